"""The co-simulation master: plant and controller FMUs at a fixed step.

fmpy extracts, loads, instantiates and initializes both FMUs; the stepping loop
then calls the very same FMI functions of the loaded libraries with value
references and buffers prepared once per run, reading and writing the
recording matrix in place (no per-step lists, no copies):

* the references and disturbances of the whole run are sampled up front into
  their columns;
* the plant's outputs are recorded in an order whose first part is exactly the
  controller's measured inputs, and the controller's outputs in an order whose
  first part is the plant's command inputs, so each connection is one
  ``fmi2SetReal`` reading straight from the recording.

Coupling (the order is a modelling choice, documented here and in the result):

* ``gauss-seidel`` (default): at t_k the controller samples y_k and computes
  u_k; the plant then integrates [t_k, t_k+1] with u_k (zero computational delay,
  as a sampled controller on a real vehicle with a fast processor).
* ``jacobi``: both FMUs step in parallel from t_k; the plant integrates with
  u_{k-1}, the command of the previous sample (one-sample delay).

Runs are deterministic: the same scenario gives bit-identical results (unless
the controller's self-timing outputs are switched on).
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from orchestrator.fmu import FmuInstance
from orchestrator.outcome import Lost, LostCriteria, first_lost
from orchestrator.results import RunResult
from plant import Airframe, fmu_path

if TYPE_CHECKING:
    from orchestrator.scenario import Scenario

ROTOR_SIGNALS = frozenset({"omega_cmd", "alpha_cmd", "beta_cmd", "omega", "alpha", "beta",
                           "efficiency", "rotor_health"})
"""Per-rotor vectors (8 elements): a run records and connects only the airframe's rotors."""
MAX_ROTORS = 8
REF_INPUTS = ("pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref", "rotor_health")
DIST_INPUTS = ("f_d", "tau_d", "a_d", "efficiency")
COUPLINGS = ("gauss-seidel", "jacobi")
ENGINES = ("native", "python")

_c_int, _vp, _sz, _dbl = ctypes.c_int, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_double
_ARRAY_FN = ctypes.CFUNCTYPE(_c_int, _vp, _vp, _sz, _vp)
_STEP_FN = ctypes.CFUNCTYPE(_c_int, _vp, _dbl, _dbl, _c_int)


class RunError(RuntimeError):
    """An FMU refused a call during the run; the message carries its log."""

    def __init__(self, message: str, row: int = -1) -> None:
        super().__init__(message)
        self.row = row  # the recording row whose step failed (-1: not known)


class RecordingTooLarge(ValueError):
    """The recording of a run would not fit in memory; raised before anything runs."""


def _rotor_used(name: str, n_rotors: int) -> bool:
    """False for the element of a per-rotor vector beyond the airframe's rotor count."""
    base, _, index = name.partition("[")
    return base not in ROTOR_SIGNALS or int(index.rstrip("]").split(",")[0]) <= n_rotors


@dataclass
class _Group:
    """Variables of one FMU read/written with one call, bound to a recording block."""

    names: list[str]
    refs: ctypes.Array[ctypes.c_uint]
    column: int  # first column of the block in its matrix


class _Fmu:
    """Raw FMI entry points of an fmpy-loaded FMU, typed for pointer arithmetic."""

    def __init__(self, inst: FmuInstance) -> None:
        self.inst = inst
        dll = inst.slave.dll
        self.comp = inst.slave.component
        self.get_real = _ARRAY_FN(("fmi2GetReal", dll))
        self.set_real = _ARRAY_FN(("fmi2SetReal", dll))
        self.get_int = _ARRAY_FN(("fmi2GetInteger", dll))
        self.get_bool = _ARRAY_FN(("fmi2GetBoolean", dll))
        self.do_step = _STEP_FN(("fmi2DoStep", dll))

    def outputs(self, kind: str, n_rotors: int = MAX_ROTORS) -> list[str]:
        return [v.name for v in self.inst.md.modelVariables
                if v.causality == "output" and v.type == kind and _rotor_used(v.name, n_rotors)]

    def inputs(self, n_rotors: int = MAX_ROTORS) -> list[str]:
        return [v.name for v in self.inst.md.modelVariables
                if v.causality == "input" and _rotor_used(v.name, n_rotors)]

    def refs(self, names: list[str]) -> ctypes.Array[ctypes.c_uint]:
        return (ctypes.c_uint * len(names))(*[self.inst.vr(n) for n in names])


def controller_parameters(airframe: Airframe, controller: FmuInstance,
                          failures: bool = False) -> dict[str, float | int]:
    """The controller's airframe model and feasible-force polytopes for an airframe.

    Names shared with the plant come from the airframe file; the polytope is always the
    airframe's S(0), passed explicitly (never the FMU's built-in default on the strength of
    a file comparison), and with ``failures`` also S(0) after each single-rotor loss.  Both
    are computed once per airframe content (``controller.polytope_cache``).
    """
    from controller.polytope_cache import failure_set_parameters, polytope_parameters

    params = {k: v for k, v in airframe.fmu_parameters().items()
              if k in controller.variables and controller.variables[k].causality == "parameter"}
    params.update(polytope_parameters(airframe))
    if failures:
        params.update(failure_set_parameters(airframe))
    return params


def plant_parameters(scenario: Scenario, refs0: dict[str, np.ndarray]) -> dict[str, object]:
    """Airframe values, the initial pose at the reference's start, then the overrides."""
    params: dict[str, object] = dict(scenario.airframe.fmu_parameters())
    for i in range(3):
        params[f"pos0[{i + 1}]"] = float(refs0["pos_ref"][0, i])
        params[f"euler0[{i + 1}]"] = float(refs0["euler_ref"][0, i])
        params[f"vel0[{i + 1}]"] = float(refs0["vel_ref"][0, i])
    params.update(scenario.plant_parameters)
    return params


class _Plan:
    """Everything a run's stepping needs, prepared once: FMUs, connections, the
    recording matrices and their layout, value-reference arrays, call runners."""

    def __init__(self, plant_inst: FmuInstance, ctrl_inst: FmuInstance, rows: int,
                 n_rotors: int = MAX_ROTORS, planned_rows: int | None = None) -> None:
        self.plant_inst, self.ctrl_inst = plant_inst, ctrl_inst
        plant, ctrl = _Fmu(plant_inst), _Fmu(ctrl_inst)
        self.plant, self.ctrl = plant, ctrl
        self.rows = rows
        n = n_rotors
        # connection table by matching names
        p_real_out, c_real_out = plant.outputs("Real", n), ctrl.outputs("Real", n)
        c_inputs, p_inputs = ctrl.inputs(n), plant.inputs(n)
        self.measured = [v for v in c_inputs if v in set(p_real_out)]
        self.commands = [v for v in p_inputs if v in set(c_real_out)]
        self.ref_widths = [len([v for v in ctrl_inst.expand(g) if _rotor_used(v, n)])
                           for g in REF_INPUTS]
        self.dist_widths = [len([v for v in plant_inst.expand(g) if _rotor_used(v, n)])
                            for g in DIST_INPUTS]
        self.ref_names = [v for g in REF_INPUTS for v in ctrl_inst.expand(g) if _rotor_used(v, n)]
        self.dist_names = [v for g in DIST_INPUTS for v in plant_inst.expand(g)
                           if _rotor_used(v, n)]
        unconnected = ([f"controller.{v}" for v in c_inputs
                        if v not in self.measured and v not in self.ref_names]
                       + [f"plant.{v}" for v in p_inputs
                          if v not in self.commands and v not in self.dist_names])
        if unconnected:
            raise RunError(f"inputs left unconnected: {', '.join(unconnected)}")
        # recording layout: time | ref | plant (measured first) | dist | ctrl (commands first),
        # so that [ref, measured] and [dist, commands] are contiguous: one call each
        self.plant_order = self.measured + [v for v in p_real_out if v not in self.measured]
        self.ctrl_order = self.commands + [v for v in c_real_out if v not in self.commands]
        self.columns = (["time"] + [f"ref.{v}" for v in self.ref_names]
                        + [f"plant.{v}" for v in self.plant_order]
                        + [f"dist.{v}" for v in self.dist_names]
                        + [f"ctrl.{v}" for v in self.ctrl_order])
        self.c_ref = 1
        self.c_plant = self.c_ref + len(self.ref_names)
        self.c_dist = self.c_plant + len(self.plant_order)
        self.c_ctrl = self.c_dist + len(self.dist_names)
        # first columns of plant.pos, ref.pos_ref, plant.euler: what the lost check reads
        self.pose_columns = tuple(self.columns.index(f"{g}[1]")
                                  for g in ("plant.pos", "ref.pos_ref", "plant.euler"))
        self.p_ints, self.c_ints = plant.outputs("Integer", n), ctrl.outputs("Integer", n)
        self.c_bools = ctrl.outputs("Boolean", n)
        self.int_columns = ([f"plant.{v}" for v in self.p_ints]
                            + [f"ctrl.{v}" for v in self.c_ints]
                            + [f"ctrl.{v}" for v in self.c_bools])
        check_memory(planned_rows or rows, len(self.columns) + len(self.int_columns))
        self.data = np.zeros((rows + 1, len(self.columns)))  # spare row: Jacobi's u_{-1}
        self.ints = np.zeros((rows + 1, len(self.int_columns)), dtype=np.int32)
        self.g = {
            "c_in": ctrl.refs(self.ref_names + self.measured),
            "c_out": ctrl.refs(self.ctrl_order), "c_int": ctrl.refs(self.c_ints),
            "c_bool": ctrl.refs(self.c_bools),
            "p_in": plant.refs(self.dist_names + self.commands),
            "p_cmd": plant.refs(self.commands), "p_dist": plant.refs(self.dist_names),
            "p_out": plant.refs(self.plant_order), "p_int": plant.refs(self.p_ints),
        }

    @classmethod
    def build(cls, plant_inst: FmuInstance, ctrl_inst: FmuInstance, rows: int,
              plant_params: dict[str, object], ctrl_params: dict[str, object],
              ref0: np.ndarray, n_rotors: int = MAX_ROTORS) -> _Plan:
        """Plan and initialize: the plant at its start pose, the controller from y_0, r_0."""
        return cls(plant_inst, ctrl_inst, rows, n_rotors).initialize(plant_params, ctrl_params,
                                                                     ref0)

    def initialize(self, plant_params: dict[str, object], ctrl_params: dict[str, object],
                   ref0: np.ndarray) -> _Plan:
        plant_inst, ctrl_inst = self.plant_inst, self.ctrl_inst
        plant_inst.initialize(parameters=plant_params)  # type: ignore[arg-type]
        ctrl_inst.enter_initialization(0.0, ctrl_params)  # type: ignore[arg-type]
        ctrl_inst.write(ctrl_inst.signal(self.measured),
                        plant_inst.read(plant_inst.signal(self.measured)))
        ctrl_inst.write(ctrl_inst.signal(self.ref_names), ref0)
        ctrl_inst.exit_initialization()
        self.data[0, self.c_ref:self.c_plant] = ref0
        self.record_initial(0)
        return self

    def row_address(self, k: int) -> tuple[int, int]:
        return (self.data.ctypes.data + k * self.data.strides[0],
                self.ints.ctypes.data + k * self.ints.strides[0])

    def record_initial(self, k: int) -> None:
        """Plant outputs into row k; the controller's current outputs into the spare row."""
        row, irow = self.row_address(k)
        plant, ctrl, g = self.plant, self.ctrl, self.g
        plant.get_real(plant.comp, g["p_out"], len(g["p_out"]), row + 8 * self.c_plant)
        plant.get_int(plant.comp, g["p_int"], len(g["p_int"]), irow)
        spare, _ = self.row_address(self.rows)
        ctrl.get_real(ctrl.comp, g["c_out"], len(g["c_out"]), spare + 8 * self.c_ctrl)

    def final_sample(self, k: int, t: float, h: float) -> None:
        """The controller's answer to the last row (the plant does not step again)."""
        row, irow = self.row_address(k)
        ctrl, g = self.ctrl, self.g
        n_pint, n_cint = len(self.p_ints), len(self.c_ints)
        a = ctrl.set_real(ctrl.comp, g["c_in"], len(g["c_in"]), row + 8 * self.c_ref)
        a |= ctrl.do_step(ctrl.comp, t, h, 1)
        a |= ctrl.get_real(ctrl.comp, g["c_out"], len(g["c_out"]), row + 8 * self.c_ctrl)
        a |= ctrl.get_int(ctrl.comp, g["c_int"], n_cint, irow + 4 * n_pint)
        a |= ctrl.get_bool(ctrl.comp, g["c_bool"], len(self.c_bools),
                           irow + 4 * (n_pint + n_cint))
        if a > 1:
            self.fail(t, k)

    def python_runner(self, h: float, jacobi: bool) -> Callable[[int, int, float], None]:
        """Steps [first, last) from Python: nine FMI calls per step on the prepared buffers."""
        plant, ctrl, g = self.plant, self.ctrl, self.g
        base, ibase = self.row_address(0)
        stride, istride = self.data.strides[0], self.ints.strides[0]
        spare, _ = self.row_address(self.rows)
        c_ref, c_plant, c_dist, c_ctrl = (8 * c for c in (self.c_ref, self.c_plant, self.c_dist,
                                                         self.c_ctrl))
        n_cin, n_cout, n_pin, n_pout = (len(g[k]) for k in ("c_in", "c_out", "p_in", "p_out"))
        n_cmd, n_dist = len(g["p_cmd"]), len(g["p_dist"])
        n_pint, n_cint, n_cbool = len(self.p_ints), len(self.c_ints), len(self.c_bools)
        o_cint, o_cbool = 4 * n_pint, 4 * (n_pint + n_cint)
        pc, cc = plant.comp, ctrl.comp
        p_set, p_get, p_geti, p_step = plant.set_real, plant.get_real, plant.get_int, plant.do_step
        c_set, c_get, c_geti, c_getb, c_step = (ctrl.set_real, ctrl.get_real, ctrl.get_int,
                                                ctrl.get_bool, ctrl.do_step)
        gc_in, gc_out, gc_int, gc_bool = g["c_in"], g["c_out"], g["c_int"], g["c_bool"]
        gp_in, gp_cmd, gp_dist, gp_out, gp_int = (g["p_in"], g["p_cmd"], g["p_dist"], g["p_out"],
                                                  g["p_int"])

        def steps(first: int, last: int, t0: float) -> None:
            for k in range(first, last):
                row = base + k * stride
                irow = ibase + k * istride
                t = t0 + k * h
                a = c_set(cc, gc_in, n_cin, row + c_ref)  # controller samples [r_k, y_k]
                a |= c_step(cc, t, h, 1)
                a |= c_get(cc, gc_out, n_cout, row + c_ctrl)
                a |= c_geti(cc, gc_int, n_cint, irow + o_cint)
                a |= c_getb(cc, gc_bool, n_cbool, irow + o_cbool)
                if a > 1:  # statuses: 0 ok, 1 warning; anything else stops the run
                    self.fail(t, k)
                if jacobi:  # plant integrates with u_{k-1}
                    a |= p_set(pc, gp_cmd, n_cmd, (row - stride if k else spare) + c_ctrl)
                    a |= p_set(pc, gp_dist, n_dist, row + c_dist)
                else:  # plant integrates with u_k: [dist_k, u_k] in one call
                    a |= p_set(pc, gp_in, n_pin, row + c_dist)
                a |= p_step(pc, t, h, 1)
                a |= p_get(pc, gp_out, n_pout, row + stride + c_plant)  # y_{k+1}
                a |= p_geti(pc, gp_int, n_pint, irow + istride)
                if a > 1:  # statuses: 0 ok, 1 warning; anything else stops the run
                    self.fail(t, k)

        return steps

    def native_runner(self, h: float, jacobi: bool) -> Callable[[int, int, float], None]:
        """The same call sequence run by fp_cosim_steps (libfullpose_core)."""
        from plant._native import core

        lib = core()
        vp = ctypes.c_void_p

        def fn(f: _Fmu, name: str) -> int | None:
            return ctypes.cast(getattr(f.inst.slave.dll, name), vp).value

        plant, ctrl, g = self.plant, self.ctrl, self.g
        fns = (vp * 9)(fn(ctrl, "fmi2SetReal"), fn(ctrl, "fmi2DoStep"), fn(ctrl, "fmi2GetReal"),
                       fn(ctrl, "fmi2GetInteger"), fn(ctrl, "fmi2GetBoolean"),
                       fn(plant, "fmi2SetReal"), fn(plant, "fmi2DoStep"),
                       fn(plant, "fmi2GetReal"), fn(plant, "fmi2GetInteger"))
        comps = (vp * 2)(ctrl.comp, plant.comp)
        order = ["c_in", "c_out", "c_int", "c_bool", "p_in", "p_cmd", "p_dist", "p_out", "p_int"]
        vrs = (vp * 9)(*[ctypes.addressof(g[k]) for k in order])
        counts = (ctypes.c_size_t * 9)(*[len(g[k]) for k in order])
        n_pint, n_cint = len(self.p_ints), len(self.c_ints)
        offsets = (ctypes.c_long * 7)(self.c_ref, self.c_plant, self.c_dist, self.c_ctrl,
                                      n_pint, n_pint + n_cint, 0)
        failed = ctypes.c_long(-1)
        base, ibase = self.row_address(0)
        spare, _ = self.row_address(self.rows)
        args = (fns, comps, vrs, counts, base, self.data.strides[0] // 8, ibase,
                self.ints.strides[0] // 4, spare, offsets)

        def steps(first: int, last: int, t0: float) -> None:
            if lib.fp_cosim_steps(*args, t0, h, int(jacobi), first, last, ctypes.byref(failed)):
                self.fail(t0 + failed.value * h, int(failed.value))

        return steps

    def fail(self, t: float, row: int = -1) -> None:
        msgs = [f"{f.inst.md.modelName}: {m}" for f in (self.plant, self.ctrl)
                for s, _, m in f.inst.messages if s in ("ERROR", "FATAL", "DISCARD")]
        raise RunError(f"the co-simulation failed at t = {t:.3f} s: "
                       + ("; ".join(msgs[-3:]) or "an FMU call returned an error"), row)

    def lost_in(self, first: int, last: int, criteria: LostCriteria) -> Lost | None:
        """The first lost row among rows first..last (inclusive) of the recording."""
        rows = slice(first, last + 1)
        d = self.data
        pos, ref, euler = (d[rows, c:c + 3] for c in self.pose_columns)
        finite = np.all(np.isfinite(d[rows, self.c_plant:self.c_dist]), axis=1)
        # the controller's commands of a row exist once the row has been stepped
        stepped = slice(first, min(last + 1, self.rows - 1))
        cmd_ok = np.all(np.isfinite(d[stepped, self.c_ctrl:self.c_ctrl + len(self.commands)]),
                        axis=1)
        finite[:cmd_ok.size] &= cmd_ok
        found = first_lost(d[rows, 0], pos, ref, euler, finite, criteria)
        if found is None:
            return None
        return replace(found, row=found.row + first)


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
                  widths: list[int]) -> np.ndarray:
    """The groups' columns side by side, each cut to the recorded width (rotors in use)."""
    return np.hstack([signals[g][:, :w] for g, w in zip(groups, widths, strict=True)])


class CoSimulation:
    """One run of a scenario: ``CoSimulation(scenario).run() -> RunResult``."""

    def __init__(self, scenario: Scenario, *, timing: bool = False,
                 progress: bool | None = None, engine: str = "native") -> None:
        if scenario.coupling not in COUPLINGS:
            raise ValueError(f"coupling must be one of {COUPLINGS}, got {scenario.coupling!r}")
        if engine not in ENGINES:
            raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
        self.scenario = scenario
        self.engine = engine
        self.timing = timing
        self.progress = progress

    def run(self, on_chunk: Callable[[int, int], None] | None = None) -> RunResult:
        """The whole run; stops early, with ``meta["outcome"]`` saying so, when the vehicle
        is lost (``orchestrator.outcome``)."""
        plant_inst = FmuInstance(fmu_path("MultirotorPlant"), "plant")
        try:
            ctrl_inst = FmuInstance(fmu_path("FullPoseController"), "controller")
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
        with FmuInstance(fmu_path("MultirotorPlant"), "plant") as plant_inst, \
                FmuInstance(fmu_path("FullPoseController"), "controller") as ctrl_inst:
            self._setup(plant_inst, ctrl_inst, 1, self.scenario.n_steps + 1)

    # -- setup ---------------------------------------------------------------

    def _setup(self, plant_inst: FmuInstance, ctrl_inst: FmuInstance, rows: int,
               planned_rows: int | None = None) -> _Plan:
        sc = self.scenario
        refs0 = sc.references(np.zeros(1))
        refs0["rotor_health"] = sc.health(np.zeros(1))
        p_params = plant_parameters(sc, refs0)
        p_params["timing"] = self.timing
        c_params: dict[str, object] = dict(controller_parameters(sc.airframe, ctrl_inst,
                                                                 failures=bool(sc.faults)))
        c_params["timing"] = self.timing
        c_params.update(sc.controller_parameters)
        n = sc.airframe.n_rotors
        plan = _Plan(plant_inst, ctrl_inst, rows, n, planned_rows)  # refuses too large first
        return plan.initialize(p_params, c_params, _used_columns(refs0, REF_INPUTS,
                                                                 plan.ref_widths)[0])

    def _run(self, plant_inst: FmuInstance, ctrl_inst: FmuInstance,
             on_chunk: Callable[[int, int], None] | None) -> RunResult:
        sc = self.scenario
        h = sc.step
        rows = sc.n_steps + 1
        plan = self._setup(plant_inst, ctrl_inst, rows)
        times = np.arange(rows, dtype=float) * h
        refs = sc.references(times)
        refs["rotor_health"] = sc.health(times)
        dists = sc.disturbances(times)
        data = plan.data
        data[:rows, 0] = times
        data[:rows, plan.c_ref:plan.c_plant] = _used_columns(refs, REF_INPUTS, plan.ref_widths)
        data[:rows, plan.c_dist:plan.c_ctrl] = _used_columns(dists, DIST_INPUTS,
                                                             plan.dist_widths)
        del refs, dists
        wall, (lost, answered) = self._loop(plan, 0, rows - 1, 0.0, on_chunk)
        if lost is None:
            plan.final_sample(rows - 1, (rows - 1) * h, h)
        else:
            if lost.nonfinite and lost.row > 0:  # keep the finite rows only
                rows, answered = lost.row, True
            else:
                rows = lost.row + 1
            if not answered:  # the controller's answer to the row that lost the vehicle
                try:
                    plan.final_sample(lost.row, lost.row * h, h)
                except RunError:  # the FMU refused the diverged input
                    data[lost.row, plan.c_ctrl:] = np.nan

        columns = plan.columns
        fmu_time = None  # the FMUs' own compute time, measured inside them (timing on)
        if self.timing:
            fmu_time = {"plant": float(data[1:rows, columns.index("plant.t_step")].sum()),
                        "controller": float(data[:rows, columns.index("ctrl.t_step")].sum())}
        warnings = [m for s, _, m in plant_inst.messages + ctrl_inst.messages if s == "WARNING"]
        full = np.hstack([data[:rows], plan.ints[:rows].astype(float)])
        del plan.data, plan.ints
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
        return RunResult(columns=columns + plan.int_columns, data=full, meta=meta)

    # -- the loop ------------------------------------------------------------

    def _loop(self, plan: _Plan, first: int, last: int, t0: float,
              on_chunk: Callable[[int, int], None] | None
              ) -> tuple[float, tuple[Lost | None, bool]]:
        """Steps first .. last-1 (rows of plan.data), checking each chunk of rows for a lost
        vehicle; returns the wall time and the first lost row (None: completed)."""
        criteria = self.scenario.lost
        h = self.scenario.step
        jacobi = self.scenario.coupling == "jacobi"
        runner = plan.native_runner(h, jacobi) if self.engine == "native" else None
        if runner is None:
            runner = plan.python_runner(h, jacobi)
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
                    runner(k, stop, t0)
                except RunError as e:  # a diverged loop may end in an FMU error: say lost
                    failed = e.row if e.row >= 0 else k
                    lost = plan.lost_in(k, failed, criteria)
                    if lost is None:
                        raise
                    answered = lost.row < failed
                    break
                # rows k..stop have plant outputs, rows k..stop-1 the controller's answers
                lost = plan.lost_in(k, stop, criteria)
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
