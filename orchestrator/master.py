"""The co-simulation master of scenario runs: plant and controller FMUs at a fixed step.

fmpy extracts, loads, instantiates and initializes both FMUs with the start values of
``orchestrator.sim.start_values``; ``orchestrator.sim.engine`` connects them, lays out the recording
and steps them (the C kernel by default, the Python oracle with ``engine="python"``).  The
references and disturbances are sampled into their columns of the recording before the loop,
a chunk of rows at a time; the loop checks each chunk of 500 steps for a lost vehicle
(``orchestrator.sim.outcome``) and stops there.

Memory: a recording up to :data:`SPILL_BYTES` is held in memory; a larger one goes to the
file the caller offers (``spill``; the results runner puts it beside the results folder),
mapped into memory, so that a run of hours is limited by the disk, not by the memory
(nothing else of the run grows with its length beyond a few columns).  Without such a file,
a recording that would not fit in memory is refused before anything runs.

Runs are deterministic: the same scenario gives bit-identical results (unless the FMUs'
self-timing outputs are switched on).
"""

from __future__ import annotations

import ctypes
import os
import shutil
import sys
import time
import weakref
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from controller import controller_fmu
from orchestrator.mission_feed import PERIOD_ROWS, MissionFeed
from orchestrator.output.run_result import RunResult
from orchestrator.sim.engine import (
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
from orchestrator.sim.fmu import FmuInstance
from orchestrator.sim.fmu3 import fmi_of, open_fmu
from orchestrator.sim.outcome import Lost, LostCriteria, first_lost
from orchestrator.sim.start_values import Pose, StartValues, resting_on_ground, start_values
from plant import plant_fmu

if TYPE_CHECKING:
    from orchestrator.scenario.model import Scenario

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


SPILL_BYTES = 256 * 2**20
"""Recordings larger than this (about 7 minutes of the paper hexacopter at 500 Hz) go to the
``spill`` file when the caller offers one."""
FILL_ROWS = 65536
"""Rows of references and disturbances sampled at a time before the loop."""


def recording_bytes(rows: int, columns: int) -> int:
    """Peak memory of a run's recording held in memory: the matrix and a few columns per row
    of working space (the metrics' errors, the references of one fill)."""
    return rows * 8 * (columns + 16)


def check_memory(rows: int, columns: int, step: float = 0.002,
                 file: Path | None = None) -> None:
    """Refuses, before anything runs, a recording that would not fit in memory, or (with
    ``file``, where it is to be written) on the disk."""
    if file is not None:
        try:
            free: int | None = shutil.disk_usage(file.parent).free
        except OSError:
            free = None
        need = rows * 8 * columns
        if free is not None and need > 0.9 * free:
            raise RecordingTooLarge(
                f"a run of {(rows - 1) * step:g} s records {rows:,} rows x {columns} columns "
                f"into {file.parent} and needs about {need / 2**30:.1f} GiB of disk; "
                f"{free / 2**30:.1f} GiB are free, enough for about "
                f"{0.9 * free / (8 * columns) * step:.0f} s: shorten the duration "
                "(--duration) or write the results elsewhere (--out)")
    # in memory: the whole recording, or with a file a few columns of working space
    need = recording_bytes(rows, columns) if file is None else recording_bytes(rows, 0)
    avail = available_memory()
    if avail is None or need <= 0.75 * avail:
        return
    fits = 0.75 * avail / (need / rows) * step
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
    if "ctrl.pos_ref_s[1]" in rec.columns and last > 0:
        # the vehicle is judged against the reference it is flying: the controller's shaped
        # one (a 10 m step is not a 10 m error).  Rows first..last-1 have it; the row last,
        # not answered yet, the one before's (it moves by millimetres per row)
        shaped = rec.data[max(first - 1, 0):last, rec.columns_of("ctrl.pos_ref_s")]
        ref = ref.copy()
        ref[:last - first] = shaped[-(last - first):] if last > first else ref[:0]
        ref[last - first] = shaped[-1]
    found = first_lost(rec.time[rows], pos, ref, euler, finite, criteria)
    if found is None:
        return None
    return replace(found, row=found.row + first)


_Found = tuple[FmuInstance, tuple[int, bool, int], Connections]  # (controller, counts, ...)
_CONNECTIONS: weakref.WeakKeyDictionary[FmuInstance, _Found] = weakref.WeakKeyDictionary()


def connections(plant: FmuInstance, ctrl: FmuInstance, n_rotors: int,
                truth: bool = False, n_contacts: int = 0) -> Connections:
    """``Connections.closed_loop``, found once per pair of instances, rotor count, ``truth``
    and contact-point count (a reused pair, as in sweep workers, finds them at its first run
    only)."""
    found = _CONNECTIONS.get(plant)
    if found is not None and found[0] is ctrl and found[1] == (n_rotors, truth, n_contacts):
        return found[2]
    conn = Connections.closed_loop(plant, ctrl, n_rotors, truth, n_contacts)
    _CONNECTIONS[plant] = (ctrl, (n_rotors, truth, n_contacts), conn)
    return conn


SENSOR_PARAMETERS = ("noise_pos", "noise_vel", "noise_acc", "noise_att", "noise_rate",
                     "noise_ang_acc", "mocap_period", "mocap_delay", "imu_period")
"""Plant parameters that make a measurement differ from the true state (all 0 by default)."""


def sensors_differ(scenario: Scenario) -> bool:
    """Whether the scenario's plant measures with noise, sampling or latency (then the true
    state is recorded beside the measured one, and metrics and figures judge the truth)."""
    return any(float(scenario.plant_parameters.get(k, 0.0)) != 0.0 for k in SENSOR_PARAMETERS)


class CoSimulation:
    """One run of a scenario: ``CoSimulation(scenario).run() -> RunResult``."""

    def __init__(self, scenario: Scenario, *, timing: bool = False,
                 progress: bool | None = None, engine: str = "native",
                 fmus: tuple[FmuInstance, FmuInstance] | None = None,
                 spill: Path | None = None, spill_above: int = SPILL_BYTES,
                 pil: Path | None = None) -> None:
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
        # a .npy file the recording is written to when larger than spill_above bytes; the
        # caller removes it (it holds the returned result's data)
        self.spill = None if spill is None else Path(spill)
        self.spill_above = spill_above
        # the controller image (fullpose build-embedded) flown on the emulated Cortex-M7
        # instead of the controller FMU: processor in the loop (orchestrator.pil)
        self.pil = None if pil is None else Path(pil)

    def run(self, on_chunk: Callable[[int, int], None] | None = None) -> RunResult:
        """The whole run; stops early, with ``meta["outcome"]`` saying so, when the vehicle
        is lost (``orchestrator.sim.outcome``)."""
        if self.fmus is not None:
            return self._run(*self.fmus, on_chunk)
        fmi = self.scenario.fmi
        plant_inst = open_fmu(plant_fmu(fmi), "plant")
        try:
            ctrl_inst = self._controller(fmi)
        except BaseException:
            plant_inst.close()
            raise
        try:
            return self._run(plant_inst, ctrl_inst, on_chunk)
        finally:
            plant_inst.close()
            ctrl_inst.close()

    def _controller(self, fmi: int) -> FmuInstance:
        if self.pil is None:
            return open_fmu(controller_fmu(fmi), "controller")
        from orchestrator.pil.instance import PilController

        return PilController(self.pil, controller_fmu(2))

    def initialize_only(self) -> None:
        """Instantiate and initialize both FMUs exactly as a run would, then stop: whatever
        the FMUs refuse (a parameter out of range, an infeasible hover, unstable gains) is
        an :class:`~orchestrator.sim.fmu.FmuError`; a recording too large for memory a
        :class:`RecordingTooLarge`."""
        fmi = self.scenario.fmi
        with open_fmu(plant_fmu(fmi), "plant") as plant_inst, \
                open_fmu(controller_fmu(fmi), "controller") as ctrl_inst:
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
        plant_overrides = dict(sc.plant_parameters)
        if sc.start == "ground":  # at rest on the gear, rotors stopped (the overrides last)
            pos, euler = sc.initial_pose()
            _, stopped = resting_on_ground(sc.true_airframe, pos.tolist(), float(euler[2]))
            pose = Pose.of(pos.tolist(), euler.tolist())
            plant_overrides = {**stopped, **plant_overrides}
        return start_values(sc.airframe, pose, timing=self.timing,
                            plant_overrides=plant_overrides,
                            controller_overrides=sc.controller_parameters,
                            plant_airframe=sc.plant_airframe)

    def _setup(self, plant_inst: FmuInstance, ctrl_inst: FmuInstance, rows: int,
               planned_rows: int | None = None) -> Engine:
        sc = self.scenario
        refs0 = sc.references(np.zeros(1))
        refs0["rotor_health"] = sc.health(np.zeros(1))
        start = self.start_values(refs0)
        conn = connections(plant_inst, ctrl_inst, sc.airframe.n_rotors, sensors_differ(sc),
                           int(start.plant.get("n_contacts", 0)))
        planned, columns = planned_rows or rows, sum(conn.widths())
        file = (self.spill if self.spill is not None
                and planned * 8 * columns > self.spill_above else None)
        check_memory(planned, columns, sc.step, file)  # refuses too large first
        engine = make_engine(self.engine, plant_inst, ctrl_inst, conn,
                             Recording(conn, rows, file), sc.step, sc.coupling)
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
        for a in range(0, rows, FILL_ROWS):  # (signals of time alone: any chunking is exact)
            b = min(a + FILL_ROWS, rows)
            times = np.arange(a, b, dtype=float) * h
            refs = sc.references(times)
            refs["rotor_health"] = sc.health(times)
            rec.time[a:b] = times
            rec.ref[a:b] = _used_columns(refs, REF_INPUTS, engine.conn.ref)
            rec.dist[a:b] = _used_columns(sc.disturbances(times), DIST_INPUTS, engine.conn.dist)
        feed = None
        if sc.mission is not None:
            pos0, euler0 = sc.initial_pose()
            feed = MissionFeed(engine, sc.mission, pos0, euler0)
        wall, (lost, answered) = self._loop(engine, 0, rows - 1, 0.0, on_chunk, feed)
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
        on_target = _on_target(ctrl_inst)
        if self.timing and on_target is None:  # (on the target: instructions, not seconds)
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
            # the airframe flown, whole: figures and the 3-D view read it from here, never
            # from a file that may have changed since
            "airframe_record": sc.airframe.record(),
            "airframe_digest": sc.airframe.digest(),
            "n_rotors": sc.airframe.n_rotors,
            "alpha_limits": [float(x) for x in sc.airframe.alpha_limits[0]],
            "beta_limits": [float(x) for x in sc.airframe.beta_limits[0]],
            "omega_max": sc.airframe.omega_max,
            "step": sc.step,
            "duration": float(full[-1, 0]),
            "planned_duration": float(sc.n_steps * h),
            "outcome": ({"outcome": "completed"} if lost is None else lost.summary()),
            "lost_criteria": sc.lost.summary(),
            "coupling": sc.coupling,
            "engine": self.engine,
            "fmi": fmi_of(plant_inst),  # the version flown (a sweep's workers: FMI 2.0)
            "wall_time": wall,
            "fmu_time": fmu_time,
            "timing": self.timing,
            "warnings": len(warnings),
            "first_warnings": warnings[:5],
            "plant_parameters": dict(sc.plant_parameters),
            "controller_parameters": dict(sc.controller_parameters),
        }
        if feed is not None:
            meta["mission"] = feed.record()
        if on_target is not None:
            meta["controller_on"] = on_target
        return RunResult(columns=columns + rec.int_columns, data=full, meta=meta,
                         integer=frozenset(rec.int_columns))

    # -- the loop ------------------------------------------------------------

    def _loop(self, engine: Engine, first: int, last: int, t0: float,
              on_chunk: Callable[[int, int], None] | None, feed: MissionFeed | None = None
              ) -> tuple[float, tuple[Lost | None, bool]]:
        """Steps first .. last-1 (rows of the recording), checking each chunk of rows for a
        lost vehicle; returns the wall time and the first lost row (None: completed).  With
        a mission ``feed`` the chunks are its periods, each one's references written first."""
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
            chunk = 500 if feed is None else PERIOD_ROWS
            for k in range(first, last, chunk):
                stop = min(k + chunk, last)
                if feed is not None:
                    feed.fill(k, stop, h)
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


def _on_target(ctrl: FmuInstance) -> dict[str, object] | None:
    """What the controller image measured on the emulated Cortex-M7, or None for an FMU."""
    from orchestrator.pil.instance import PilController

    return ctrl.summary() if isinstance(ctrl, PilController) else None


def run(scenario: Scenario, *, timing: bool = False, progress: bool | None = None,
        engine: str = "native", spill: Path | None = None,
        spill_above: int = SPILL_BYTES, pil: Path | None = None) -> RunResult:
    """Run a scenario and return every exchanged signal at every step (a recording larger
    than ``spill_above`` bytes in the ``spill`` file, when given: :class:`CoSimulation`;
    ``pil``: the controller image flown on the emulated Cortex-M7)."""
    return CoSimulation(scenario, timing=timing, progress=progress, engine=engine,
                        spill=spill, spill_above=spill_above, pil=pil).run()
