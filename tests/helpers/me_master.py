"""The plant FMU as Model Exchange, integrated by CVode, and a small closed-loop master around
it (tests/test_fmus/test_model_exchange.py, tests/bench/bench_model_exchange.py).

``MePlant`` is one Model Exchange instance of the plant (fmpy's FMU2Model) with the CVode
solver fmpy's ``simulate_fmu`` uses (fmpy.sundials.CVodeSolver: BDF, dense Jacobian by
finite differences, absolute tolerances = nominals x rtol, the event indicators as root
functions).  The inputs are piecewise constant: ``event(t, refs, values)`` sets them in
Event Mode and restarts the solver at t (an input step is a discontinuity of the right-hand
side); ``advance(t, t_end)`` integrates to t_end, handling the state events on the way
(touchdown and lift-off of the landing gear) and calling fmi2CompletedIntegratorStep at each
stop, and counts CVode's steps and right-hand-side evaluations.

``closed_loop`` flies the co-simulation controller (FMI 2.0, stepped every 2 ms) with either
plant: ``"cs"`` the co-simulation plant (RK4, 0.5 ms) stepped 2 ms, or ``"me"`` this one
integrated between the controller's samples, the controller sampling the plant's outputs at
t_k and the plant holding the commands of t_k until t_k+1 (as tests/test_fmus/
test_closed_loop.py's master does).  It records the commands and the plant's start values:
fmusim, which has no master, replays them to its Model Exchange plant.
"""

from __future__ import annotations

import ctypes
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import (
    FMU2Model,
    calloc,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    free,
)
from fmpy.sundials import CVodeSolver
from fmpy.sundials.libraries import sundials_cvode

from controller import controller_fmu
from orchestrator.scenario.catalogue import load_scenario
from orchestrator.sim.fmu import FmuInstance, set_by_type
from orchestrator.sim.start_values import Pose, start_values
from plant import plant_fmu

H = 0.002
"""The controller's sample time and the co-simulation communication step, s."""

REFERENCES = ("pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref")

sundials_cvode.CVodeGetNumSteps.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_long)]
sundials_cvode.CVodeGetNumRhsEvals.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_long)]
DoubleP = ctypes.POINTER(ctypes.c_double)


class _HeldInputs:
    """The solver's view of the inputs: set by the master in Event Mode, held in between."""

    def apply(self, time: float, discrete: bool = True, after_event: bool = False) -> None:
        pass


class MePlant:
    """One Model Exchange instance of the plant FMU, initialized with ``parameters`` and left
    in Continuous-Time Mode with its CVode solver ready at t = 0."""

    def __init__(self, parameters: Mapping[str, Any] | None = None, *, rtol: float = 1e-8,
                 fmu: Path | None = None, max_step: float = H) -> None:
        self.path = Path(fmu) if fmu is not None else plant_fmu()
        self.md = read_model_description(str(self.path))
        self.unzip = extract(str(self.path))
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.messages: list[tuple[int, str]] = []
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(self._on_log)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._callbacks = cb  # (kept alive as long as the instance)
        m = FMU2Model(guid=self.md.guid, unzipDirectory=self.unzip,
                      modelIdentifier=self.md.modelExchange.modelIdentifier,
                      instanceName="me_plant")
        m.instantiate(callbacks=cb)
        self.model = m
        m.setupExperiment(startTime=0.0)
        set_by_type(m, self.variables, dict(parameters or {}))
        m.enterInitializationMode()
        m.exitInitializationMode()
        m.newDiscreteStates()
        m.enterContinuousTimeMode()
        self.nx = int(self.md.numberOfContinuousStates)
        self.nz = int(self.md.numberOfEventIndicators)
        self.solver = CVodeSolver(
            nx=self.nx, nz=self.nz, get_x=m.getContinuousStates, set_x=m.setContinuousStates,
            get_dx=m.getDerivatives, get_z=m.getEventIndicators,
            get_nominals=m.getNominalsOfContinuousStates, set_time=m.setTime,
            input=_HeldInputs(), startTime=0.0, maxStep=max_step, relativeTolerance=rtol,
            maxNumSteps=100000)
        self.steps = self.rhs = self.events = 0
        self.event_times: list[float] = []

    def _on_log(self, env: object, name: bytes, status: int, category: bytes,
                message: bytes) -> None:
        self.messages.append((int(status), message.decode(errors="replace")))

    def refs(self, names: Sequence[str]) -> list[int]:
        return [int(self.variables[n].valueReference) for n in names]

    def get(self, names: Sequence[str]) -> np.ndarray:
        return np.array(self.model.getReal(self.refs(names)))

    def _live(self) -> tuple[int, int]:
        """CVode's counters since its last (re-)initialization."""
        steps, rhs = ctypes.c_long(), ctypes.c_long()
        sundials_cvode.CVodeGetNumSteps(self.solver.cvode_mem, ctypes.byref(steps))
        sundials_cvode.CVodeGetNumRhsEvals(self.solver.cvode_mem, ctypes.byref(rhs))
        return steps.value, rhs.value

    def _count(self) -> None:
        """CVode's counters into ours (they restart at every re-initialization)."""
        steps, rhs = self._live()
        self.steps += steps
        self.rhs += rhs

    def event(self, t: float, refs: Sequence[int] | None = None,
              values: Sequence[float] | np.ndarray | None = None) -> None:
        """An event at t (Event Mode, the inputs set, the event iteration, Continuous-Time
        Mode) and the solver restarted there."""
        m = self.model
        m.enterEventMode()
        if refs is not None and values is not None:
            m.setReal(list(refs), [float(v) for v in values])
        m.newDiscreteStates()
        m.enterContinuousTimeMode()
        self._count()
        self.solver.reset(t)

    def advance(self, t: float, t_end: float) -> float:
        """Integrates from t to t_end; a state event on the way is handled (Event Mode) and
        the integration goes on from it."""
        while True:
            state_event, _, t = self.solver.step(t, t_end)
            self.model.setTime(t)
            self.model.completedIntegratorStep()
            if state_event:
                self.events += 1
                self.event_times.append(t)
                self.event(t)
            if t >= t_end - 1e-12 * max(1.0, abs(t_end)):
                return t

    def counts(self) -> tuple[int, int, int]:
        """CVode's steps and right-hand-side evaluations so far, and the state events."""
        steps, rhs = self._live()
        return self.steps + steps, self.rhs + rhs, self.events

    def close(self) -> None:
        self.model.terminate()
        self.model.freeInstance()


@dataclass
class LoopResult:
    """One closed-loop run: positions and Euler angles at every sample (t_0 .. t_n), the
    controller's commands (``command_names``, one row per sample t_0 .. t_n-1, held by the
    plant until the next one), the plant's start values, the wall time, and for the Model
    Exchange plant CVode's counts and the messages it logged."""

    pos: np.ndarray
    euler: np.ndarray
    wall: float
    command_names: list[str] = field(default_factory=list)
    commands: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    plant_parameters: dict[str, Any] = field(default_factory=dict)
    steps: int = 0
    rhs: int = 0
    events: int = 0
    messages: list[tuple[int, str]] = field(default_factory=list)


def closed_loop(kind: str, scenario: str, seconds: float, *, pose: Pose | None = None,
                rtol: float = 1e-8) -> LoopResult:
    """The controller (co-simulation) flying the plant ``kind`` ("cs" or "me") through
    ``seconds`` of ``scenario``'s references, from ``pose`` (default: the references' start
    pose, as the orchestrator starts a scenario) at hover trim."""
    sc = load_scenario(scenario)
    n = round(seconds / H)
    refs = sc.references(np.arange(n + 1) * H)
    if pose is None:
        pose = Pose.of(refs["pos_ref"][0], refs["euler_ref"][0], refs["vel_ref"][0])
    sv = start_values(sc.airframe, pose)
    ctrl = FmuInstance(controller_fmu(), "controller")
    c_in = [v.name for v in ctrl.md.modelVariables if v.causality == "input"]
    c_out = {v.name for v in ctrl.md.modelVariables if v.causality == "output"}
    me: MePlant | None = None
    cs: FmuInstance | None = None
    if kind == "me":
        me = MePlant(sv.plant, rtol=rtol)
        p_vars = me.md.modelVariables
    else:
        cs = FmuInstance(plant_fmu(), "plant")
        cs.initialize(parameters=sv.plant)
        p_vars = cs.md.modelVariables
    p_out = {v.name for v in p_vars if v.causality == "output"}
    measured = [x for x in c_in if x in p_out]
    commands = [v.name for v in p_vars if v.causality == "input" and v.name in c_out]
    watched = [f"pos[{i}]" for i in (1, 2, 3)] + [f"euler[{i}]" for i in (1, 2, 3)]
    read: Callable[[Sequence[str]], np.ndarray]
    if me is not None:
        read = me.get
        command_refs = me.refs(commands)
    else:
        assert cs is not None
        plant = cs
        signals = {id(x): plant.signal(x) for x in (measured, watched)}
        read = lambda names: plant.read(signals[id(names)])  # noqa: E731
        command_signal = plant.signal(commands)
    y_ctrl, u_ctrl = ctrl.signal(measured), ctrl.signal(commands)
    reference = ctrl.signal(list(REFERENCES))
    ctrl.slave.setupExperiment(startTime=0.0)
    ctrl.set_many(sv.controller)
    ctrl.slave.enterInitializationMode()
    ctrl.write(y_ctrl, read(measured))
    ctrl.write(reference, np.concatenate([refs[r][0] for r in REFERENCES]))
    ctrl.slave.exitInitializationMode()
    out = np.empty((n + 1, 6))
    out[0] = read(watched)
    held = np.empty((n, len(commands)))
    t0 = time.perf_counter()
    for k in range(n):
        ctrl.write(reference, np.concatenate([refs[r][k] for r in REFERENCES]))
        ctrl.write(y_ctrl, read(measured))
        ctrl.step(H)
        u = ctrl.read(u_ctrl)
        held[k] = u
        if me is not None:
            me.event(k * H, command_refs, u)
            me.advance(k * H, (k + 1) * H)
        else:
            assert cs is not None
            cs.write(command_signal, u)
            cs.step(H)
        out[k + 1] = read(watched)
    wall = time.perf_counter() - t0
    result = LoopResult(out[:, :3], out[:, 3:], wall, commands, held, dict(sv.plant))
    if me is not None:
        result.steps, result.rhs, result.events = me.counts()
        result.messages = list(me.messages)
        me.close()
    elif cs is not None:
        cs.close()
    ctrl.close()
    return result
