"""The co-simulation master of scenario runs: plant and controller FMUs at a fixed step.

fmpy extracts, loads, instantiates and initializes both FMUs with the start values of
``orchestrator.start_values``; ``orchestrator.engine`` connects them, lays out the recording
and steps them (the C kernel by default, the Python oracle with ``engine="python"``).  The
references and disturbances of the whole run are sampled up front into their columns of the
recording; the loop checks each chunk of 500 steps for a lost vehicle
(``orchestrator.outcome``) and stops there.

Runs are deterministic: the same scenario gives bit-identical results (unless the FMUs'
self-timing outputs are switched on).
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
import weakref
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from controller import controller_fmu
from orchestrator.engine import (
    COUPLINGS,
    DIST_INPUTS,
    ENGINES,
    REF_INPUTS,
    Connections,
    Engine,
    Recording,
    RunError,
    make_engine,
)
from orchestrator.fmu import FmuInstance
from orchestrator.outcome import Lost, LostCriteria, first_lost
from orchestrator.results import RunResult
from orchestrator.start_values import Pose, StartValues, start_values
from plant import plant_fmu

if TYPE_CHECKING:
    from orchestrator.scenario import Scenario

__all__ = ["COUPLINGS", "ENGINES", "CoSimulation", "RecordingTooLarge", "RunError", "run"]


class RecordingTooLarge(ValueError):
    """The recording of a run would not fit in memory; raised before anything runs."""


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation, or None when the OS does not say."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    if sys.platform == "win32":
        class _Status(ctypes.Structure):
            _fields_ = [("length", ctypes.c_ulong), ("load", ctypes.c_ulong),
                        ("total", ctypes.c_ulonglong), ("avail", ctypes.c_ulonglong),
                        ("total_page", ctypes.c_ulonglong), ("avail_page", ctypes.c_ulonglong),
                        ("total_virtual", ctypes.c_ulonglong),
                        ("avail_virtual", ctypes.c_ulonglong),
                        ("avail_extended", ctypes.c_ulonglong)]
        st = _Status()
        st.length = ctypes.sizeof(_Status)
        if ctypes.windll.kernel32.GlobalMemoryStatusEx(ctypes.byref(st)):  # type: ignore[attr-defined]
            return int(st.avail)
        return None
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def recording_bytes(rows: int, columns: int) -> int:
    """Peak memory of a run's recording: the matrix, its copy with the integer columns
    appended for the result, and the sampled references and disturbances (~48 columns)."""
    return rows * 8 * (2 * columns + 48)


def check_memory(rows: int, columns: int, step: float = 0.002) -> None:
    """Refuses, before anything runs, a recording that would not fit in memory."""
    need = recording_bytes(rows, columns)
    avail = available_memory()
    if avail is None or need <= 0.75 * avail:
        return
    fits = 0.75 * avail / recording_bytes(1, columns) * step
    raise RecordingTooLarge(
        f"a run of {(rows - 1) * step:g} s records {rows:,} rows x {columns} columns and "
        f"needs about {need / 2**30:.1f} GiB of memory; {avail / 2**30:.1f} GiB are "
        f"available, enough for about {fits:.0f} s: shorten the duration (--duration)")


def _used_columns(signals: dict[str, np.ndarray], groups: tuple[str, ...],
                  blocks: tuple[tuple[str, ...], ...]) -> np.ndarray:
    """The groups' columns side by side, each cut to the connected width (rotors in use)."""
    return np.hstack([signals[g][:, :len(b)] for g, b in zip(groups, blocks, strict=True)])


def lost_in(engine: Engine, first: int, last: int, criteria: LostCriteria) -> Lost | None:
    """The first lost row among rows first..last (inclusive) of the engine's recording."""
    rec = engine.rec
    rows = slice(first, last + 1)
    pos, ref, euler = (rec.data[rows, rec.columns_of(c)]
                       for c in ("plant.pos", "ref.pos_ref", "plant.euler"))
    finite = np.all(np.isfinite(rec.plant[rows]), axis=1)
    # the controller's commands of a row exist once the row has been stepped
    stepped = slice(first, min(last + 1, rec.rows - 1))
    cmd_ok = np.all(np.isfinite(rec.commands[stepped]), axis=1)
    finite[:cmd_ok.size] &= cmd_ok
    found = first_lost(rec.time[rows], pos, ref, euler, finite, criteria)
    if found is None:
        return None
    return replace(found, row=found.row + first)


_CONNECTIONS: weakref.WeakKeyDictionary[FmuInstance, tuple[FmuInstance, int, Connections]] = (
    weakref.WeakKeyDictionary())


def connections(plant: FmuInstance, ctrl: FmuInstance, n_rotors: int) -> Connections:
    """``Connections.closed_loop``, found once per pair of instances and rotor count (a
    reused pair, as in sweep workers, finds them at its first run only)."""
    found = _CONNECTIONS.get(plant)
    if found is not None and found[0] is ctrl and found[1] == n_rotors:
        return found[2]
    conn = Connections.closed_loop(plant, ctrl, n_rotors)
    _CONNECTIONS[plant] = (ctrl, n_rotors, conn)
    return conn


class CoSimulation:
    """One run of a scenario: ``CoSimulation(scenario).run() -> RunResult``."""

    def __init__(self, scenario: Scenario, *, timing: bool = False,
                 progress: bool | None = None, engine: str = "native",
                 fmus: tuple[FmuInstance, FmuInstance] | None = None) -> None:
        if scenario.coupling not in COUPLINGS:
            raise ValueError(f"coupling must be one of {COUPLINGS}, got {scenario.coupling!r}")
        if engine not in ENGINES:
            raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
        self.scenario = scenario
        self.engine = engine
        self.timing = timing
        self.progress = progress
        # (plant, controller) instantiated by the caller, freshly or after
        # FmuInstance.reset(): the run uses them and leaves them open (sweep workers)
        self.fmus = fmus

    def run(self, on_chunk: Callable[[int, int], None] | None = None) -> RunResult:
        """The whole run; stops early, with ``meta["outcome"]`` saying so, when the vehicle
        is lost (``orchestrator.outcome``)."""
        if self.fmus is not None:
            return self._run(*self.fmus, on_chunk)
        plant_inst = FmuInstance(plant_fmu(), "plant")
        try:
            ctrl_inst = FmuInstance(controller_fmu(), "controller")
        except BaseException:
            plant_inst.close()
            raise
        try:
            return self._run(plant_inst, ctrl_inst, on_chunk)
        finally:
            plant_inst.close()
            ctrl_inst.close()

    def initialize_only(self) -> None:
        """Instantiate and initialize both FMUs exactly as a run would, then stop: whatever
        the FMUs refuse (a parameter out of range, an infeasible hover, unstable gains) is
        an :class:`~orchestrator.fmu.FmuError`; a recording too large for memory a
        :class:`RecordingTooLarge`."""
        with FmuInstance(plant_fmu(), "plant") as plant_inst, \
                FmuInstance(controller_fmu(), "controller") as ctrl_inst:
            self._setup(plant_inst, ctrl_inst, 1, self.scenario.n_steps + 1)

    # -- setup ---------------------------------------------------------------

    def start_values(self, refs0: dict[str, np.ndarray] | None = None) -> StartValues:
        """Both FMUs' start values: the airframe, the pose at the reference's start (``refs0``,
        the references sampled at t = 0), S(0) (and the failure sets when the scenario has
        rotor faults), the overrides."""
        sc = self.scenario
        if refs0 is None:
            refs0 = sc.references(np.zeros(1))
        pose = Pose.of(refs0["pos_ref"][0], refs0["euler_ref"][0], refs0["vel_ref"][0])
        return start_values(sc.airframe, pose, failures=bool(sc.faults), timing=self.timing,
                            plant_overrides=sc.plant_parameters,
                            controller_overrides=sc.controller_parameters)

    def _setup(self, plant_inst: FmuInstance, ctrl_inst: FmuInstance, rows: int,
               planned_rows: int | None = None) -> Engine:
        sc = self.scenario
        refs0 = sc.references(np.zeros(1))
        refs0["rotor_health"] = sc.health(np.zeros(1))
        start = self.start_values(refs0)
        conn = connections(plant_inst, ctrl_inst, sc.airframe.n_rotors)
        check_memory(planned_rows or rows, sum(conn.widths()))  # refuses too large first
        engine = make_engine(self.engine, plant_inst, ctrl_inst, conn, Recording(conn, rows),
                             sc.step, sc.coupling)
        engine.initialize(start.plant, start.controller,
                          _used_columns(refs0, REF_INPUTS, conn.ref)[0])
        return engine

    def _run(self, plant_inst: FmuInstance, ctrl_inst: FmuInstance,
             on_chunk: Callable[[int, int], None] | None) -> RunResult:
        sc = self.scenario
        h = sc.step
        rows = sc.n_steps + 1
        engine = self._setup(plant_inst, ctrl_inst, rows)
        rec = engine.rec
        times = np.arange(rows, dtype=float) * h
        refs = sc.references(times)
        refs["rotor_health"] = sc.health(times)
        dists = sc.disturbances(times)
        rec.time[:rows] = times
        rec.ref[:rows] = _used_columns(refs, REF_INPUTS, engine.conn.ref)
        rec.dist[:rows] = _used_columns(dists, DIST_INPUTS, engine.conn.dist)
        del refs, dists
        wall, (lost, answered) = self._loop(engine, 0, rows - 1, 0.0, on_chunk)
        if lost is None:
            engine.controller_answer(rows - 1, (rows - 1) * h)
        else:
            if lost.nonfinite and lost.row > 0:  # keep the finite rows only
                rows, answered = lost.row, True
            else:
                rows = lost.row + 1
            if not answered:  # the controller's answer to the row that lost the vehicle
                try:
                    engine.controller_answer(lost.row, lost.row * h)
                except RunError:  # the FMU refused the diverged input
                    rec.ctrl[lost.row] = np.nan

        columns = rec.columns
        data = rec.data
        fmu_time = None  # the FMUs' own compute time, measured inside them (timing on)
        if self.timing:
            fmu_time = {"plant": float(data[1:rows, columns.index("plant.t_step")].sum()),
                        "controller": float(data[:rows, columns.index("ctrl.t_step")].sum())}
        warnings = [m for s, _, m in plant_inst.messages + ctrl_inst.messages if s == "WARNING"]
        full = rec.result_data(rows)
        del rec.data, rec.ints, data
        meta = {
            "scenario": sc.name,
            "scenario_source": str(sc.source),
            "airframe": sc.airframe.name,
            "airframe_source": str(sc.airframe.source),
            "n_rotors": sc.airframe.n_rotors,
            "alpha_limits": [float(x) for x in sc.airframe.alpha_limits[0]],
            "beta_limits": [float(x) for x in sc.airframe.beta_limits[0]],
            "omega_max": sc.airframe.omega_max,
            "step": sc.step,
            "duration": float(full[-1, 0]),
            "planned_duration": float(times[-1]),
            "outcome": ({"outcome": "completed"} if lost is None else lost.summary()),
            "lost_criteria": sc.lost.summary(),
            "coupling": sc.coupling,
            "engine": self.engine,
            "wall_time": wall,
            "fmu_time": fmu_time,
            "timing": self.timing,
            "warnings": len(warnings),
            "first_warnings": warnings[:5],
            "plant_parameters": dict(sc.plant_parameters),
            "controller_parameters": dict(sc.controller_parameters),
        }
        return RunResult(columns=columns + rec.int_columns, data=full, meta=meta,
                         integer=frozenset(rec.int_columns))

    # -- the loop ------------------------------------------------------------

    def _loop(self, engine: Engine, first: int, last: int, t0: float,
              on_chunk: Callable[[int, int], None] | None
              ) -> tuple[float, tuple[Lost | None, bool]]:
        """Steps first .. last-1 (rows of the recording), checking each chunk of rows for a
        lost vehicle; returns the wall time and the first lost row (None: completed)."""
        criteria = self.scenario.lost
        h = self.scenario.step
        show = self.progress if self.progress is not None else sys.stderr.isatty()
        bar = None
        if show and (last - first) * h > 5.0:
            from tqdm import tqdm

            bar = tqdm(total=last - first, unit="step", desc=self.scenario.name, leave=False)
        start = time.perf_counter()
        lost: Lost | None = None
        answered = True  # whether the controller has answered the lost row
        try:
            for k in range(first, last, 500):
                stop = min(k + 500, last)
                try:
                    engine.steps(k, stop, t0)
                except RunError as e:  # a diverged loop may end in an FMU error: say lost
                    failed = e.row if e.row >= 0 else k
                    lost = lost_in(engine, k, failed, criteria)
                    if lost is None:
                        raise
                    answered = lost.row < failed
                    break
                # rows k..stop have plant outputs, rows k..stop-1 the controller's answers
                lost = lost_in(engine, k, stop, criteria)
                if lost is not None:
                    answered = lost.row < stop
                    break
                if bar is not None:
                    bar.update(stop - k)
                if on_chunk is not None:
                    on_chunk(stop, last)
        finally:
            if bar is not None:
                bar.close()
        return time.perf_counter() - start, (lost, answered)


def run(scenario: Scenario, *, timing: bool = False, progress: bool | None = None,
        engine: str = "native") -> RunResult:
    """Run a scenario and return every exchanged signal at every step."""
    return CoSimulation(scenario, timing=timing, progress=progress, engine=engine).run()
