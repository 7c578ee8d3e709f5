"""The FMI 3.0 controller as a clocked task (issue 36): FullPoseController's FMI 3.0 archive
provides Scheduled Execution besides co-simulation (fmu_src/common/fmi3_scheduled.h,
docs/fmus.md, "Scheduled Execution").

Its sample is the periodic input clock ``sample`` (constant interval Ts = 0.002 s, the default
of the ``Ts`` parameter); the controller's inputs and outputs belong to that clock's model
partition, and ``fmi3ActivateModelPartition(sample, t)`` runs one control sample at t: the
model step ``fmi3DoStep(t, Ts)`` runs.  What is checked here:

- fmpy's validator and fmusim's (``fmitools``) find nothing in the archive; the clock, the
  partition and the <ScheduledExecution> element are as described; the plant and the player
  provide no Scheduled Execution;
- a master of our own (fmpy's ``FMU3ScheduledExecution`` for the controller, its
  ``FMU3Slave`` for the plant, both at 2 ms) flies 2 s of hover 0.2 m beside the start with
  plant positions and controller commands bit-identical to the same loop stepping the
  co-simulation controller by ``fmi3DoStep(t, Ts)``;
- the off-grid policy: an activation at a time other than the next instant t0 + k Ts (off the
  grid, an instant skipped, an instant activated twice) is refused with fmi3Error naming both
  times, and leaves the instance in Error;
- the call-sequence discipline: activation before initialization, after termination, with an
  unknown clock reference or a variable's, on a co-simulation instance; fmi3DoStep on a
  Scheduled Execution instance; a read between a set and the next activation; a changed Ts;
  the clock functions; each answered fmi3Error with a logged message;
- FMU states in Clock Activation Mode (get/set and serialize round trips reproduce the next
  samples to the bit; a state moves between the two interfaces); the callbacks are kept,
  never called, and may be NULL;
- fmusim cannot run Scheduled Execution (0.8: ``--interface-type`` me or cs): the check says so
  and skips (``fmitools``).
"""

from __future__ import annotations

import ctypes
import functools
import os
import re
import shutil
import subprocess
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import (
    FMU3ScheduledExecution,
    FMU3Slave,
    fmi3ClockUpdateCallback,
    fmi3LockPreemptionCallback,
    fmi3LogMessageCallback,
    fmi3UnlockPreemptionCallback,
)
from fmpy.validation import validate_fmu, validate_model_description

from plant.common.artifacts import find_artifact

MODELS = {"MultirotorPlant": "plant", "FullPoseController": "controller",
          "ScenarioSignals": "orchestrator"}
H = 0.002  # the plant's communication step and the controller's Ts
CLOCK = 5000  # the value reference of the clock `sample` (fmi3_scheduled.h)
FMI3_OK, FMI3_WARNING, FMI3_ERROR = 0, 1, 3
INTERVAL_UNCHANGED = 1  # fmi3IntervalUnchanged
POS0, POS_REF = [0.0, 0.0, -3.0], [0.2, 0.0, -3.0]


def fmu_path(model: str) -> Path:
    return find_artifact(MODELS[model], "fmus", f"fmi3/{model}.fmu")


class Log:
    """The messages an instance logged: (status, category, message)."""

    def __init__(self) -> None:
        self.lines: list[tuple[int, str, str]] = []

    def __call__(self, env, status, category, message) -> None:
        self.lines.append((status, (category or b"").decode(), (message or b"").decode()))

    def errors(self) -> list[str]:
        return [m for s, _, m in self.lines if s >= FMI3_ERROR]

    def text(self) -> str:
        return "\n".join(m for _, _, m in self.lines)


def unzipped(path: Path, tmp_path: Path) -> Path:
    folder = tmp_path / f"{path.stem}_unzip"
    if not folder.exists():
        extract(str(path), str(folder))
    return folder


class Calls:
    """The Scheduled Execution callbacks, counting their calls."""

    def __init__(self) -> None:
        self.count = {"clockUpdate": 0, "lockPreemption": 0, "unlockPreemption": 0}
        self.clock_update = fmi3ClockUpdateCallback(lambda env: self._hit("clockUpdate"))
        self.lock = fmi3LockPreemptionCallback(lambda: self._hit("lockPreemption"))
        self.unlock = fmi3UnlockPreemptionCallback(lambda: self._hit("unlockPreemption"))

    def _hit(self, name: str) -> None:
        self.count[name] += 1


@contextmanager
def scheduled(tmp_path: Path, name: str = "se", *, initialize: bool = True,
              calls: Calls | None = None, null_callbacks: bool = False,
              ts: float | None = None) -> Iterator[tuple[FMU3ScheduledExecution, Log]]:
    """A Scheduled Execution instance of the controller through fmpy (its wrapped calls raise on
    fmi3Error; ``se.dll`` has the raw entries, which return the status) and its log."""
    path = fmu_path("FullPoseController")
    md = read_model_description(str(path))
    unzip = unzipped(path, tmp_path)
    log = Log()
    se = FMU3ScheduledExecution(guid=md.guid, unzipDirectory=str(unzip),
                                modelIdentifier=md.scheduledExecution.modelIdentifier,
                                instanceName=name)
    calls = calls or Calls()
    se.logMessage = fmi3LogMessageCallback(log)  # (kept from the garbage collector)
    se.calls = calls
    cb = ((fmi3ClockUpdateCallback(), fmi3LockPreemptionCallback(),
           fmi3UnlockPreemptionCallback()) if null_callbacks  # NULL function pointers
          else (calls.clock_update, calls.lock, calls.unlock))
    se.component = se.fmi3InstantiateScheduledExecution(
        name.encode(), md.guid.encode(), (str(unzip / "resources") + os.sep).encode(), False,
        False, None, se.logMessage, *cb)
    assert se.component, log.text()
    try:
        if initialize:
            se.enterInitializationMode(startTime=0.0)
            if ts is not None:
                se.setFloat64([1], [ts])
            se.exitInitializationMode()
        yield se, log
    finally:
        se.freeInstance()


@contextmanager
def cosimulation(model: str, tmp_path: Path, name: str) -> Iterator[tuple[FMU3Slave, Log]]:
    """A co-simulation instance (instantiated, not initialized) and its log."""
    path = fmu_path(model)
    md = read_model_description(str(path))
    log = Log()
    s = FMU3Slave(guid=md.guid, unzipDirectory=str(unzipped(path, tmp_path)),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    s.instantiate(logMessage=log)
    try:
        yield s, log
    finally:
        s.freeInstance()


def activate(se, t: float, clock: int = CLOCK) -> int:
    """fmi3ActivateModelPartition called as it is: its status."""
    return se.dll.fmi3ActivateModelPartition(se.component, clock, t)


def do_step(s, t: float, h: float = H) -> int:
    flags = [ctypes.c_bool() for _ in range(3)]
    last = ctypes.c_double()
    return s.dll.fmi3DoStep(s.component, t, h, True, ctypes.byref(flags[0]),
                            ctypes.byref(flags[1]), ctypes.byref(flags[2]), ctypes.byref(last))


def get_float64(s, vr: int, n: int) -> tuple[int, list[float]]:
    refs = (ctypes.c_uint32 * 1)(vr)
    values = (ctypes.c_double * n)()
    status = s.dll.fmi3GetFloat64(s.component, refs, 1, values, n)
    return status, list(values)


def rows(model: str) -> dict[str, tuple[str, int, int]]:
    """Float64 variables: name -> (causality, value reference, size)."""
    md = read_model_description(str(fmu_path(model)))
    return {v.name: (v.causality, v.valueReference, int(np.prod(v.shape)) if v.shape else 1)
            for v in md.modelVariables if v.type == "Float64" and v.causality != "independent"}


@functools.cache
def tables() -> SimpleNamespace:
    """The Float64 variables of both FMUs (read once, when first needed) and what a master
    connects: the plant's outputs the controller measures, the commands it sends."""
    ctrl, plant = rows("FullPoseController"), rows("MultirotorPlant")
    return SimpleNamespace(
        CTRL=ctrl, PLANT=plant,
        MEASURED=[n for n, (c, _, _) in ctrl.items()
                  if c == "input" and plant.get(n, ("",))[0] == "output"],
        COMMANDS=[n for n, (c, _, _) in plant.items()
                  if c == "input" and ctrl.get(n, ("",))[0] == "output"])


def get(s, table: str, name: str) -> list[float]:
    _, vr, n = getattr(tables(), table)[name]
    return list(s.getFloat64([vr], n))


def put(s, table: str, name: str, values) -> None:
    s.setFloat64([getattr(tables(), table)[name][1]], list(values))


def hover_inputs(tmp_path: Path) -> dict[str, list[float]]:
    """The plant's measured outputs at rest at POS0 (its trim): constant controller inputs."""
    with cosimulation("MultirotorPlant", tmp_path, "trim") as (plant, _):
        plant.enterInitializationMode(startTime=0.0)
        put(plant, "PLANT", "pos0", POS0)
        plant.exitInitializationMode()
        return {n: get(plant, "PLANT", n) for n in tables().MEASURED}


def fly(tmp_path: Path, scheduled_controller: bool, steps: int = 1000):
    """The plant stepped by 2 ms and the controller sampled every 2 ms (activated, or stepped
    by fmi3DoStep(t, Ts)), the controller's inputs set before and its outputs read after;
    the plant's positions and the controller's rotor commands of every step."""
    with cosimulation("MultirotorPlant", tmp_path, "plant") as (plant, _):
        plant.enterInitializationMode(startTime=0.0)
        put(plant, "PLANT", "pos0", POS0)
        plant.exitInitializationMode()
        if scheduled_controller:
            ctx = scheduled(tmp_path, "ctrl_se", initialize=False)
        else:
            ctx = cosimulation("FullPoseController", tmp_path, "ctrl_cs")
        with ctx as (ctrl, log):
            ctrl.enterInitializationMode(startTime=0.0)
            for n in tables().MEASURED:
                put(ctrl, "CTRL", n, get(plant, "PLANT", n))
            put(ctrl, "CTRL", "pos_ref", POS_REF)
            ctrl.exitInitializationMode()
            pos, omega = [], []
            for k in range(steps):
                t = k * H
                for n in tables().MEASURED:
                    put(ctrl, "CTRL", n, get(plant, "PLANT", n))
                status = activate(ctrl, t) if scheduled_controller else do_step(ctrl, t)
                assert status == FMI3_OK, log.text()[-2000:]
                for n in tables().COMMANDS:
                    put(plant, "PLANT", n, get(ctrl, "CTRL", n))
                assert do_step(plant, t) == FMI3_OK
                pos.append(get(plant, "PLANT", "pos"))
                omega.append(get(ctrl, "CTRL", "omega_cmd"))
            calls = getattr(ctrl, "calls", None)
            return np.array(pos), np.array(omega), calls


# ---------------------------------------------------------------------------------------------
# The archive


def test_fmpy_validator_finds_no_problem_in_the_scheduled_archive():
    path = fmu_path("FullPoseController")
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    assert validate_model_description(md, validate_variable_names=True,
                                      validate_model_structure=True) == []


def test_the_clock_its_partition_and_both_interfaces():
    """One archive, both interfaces under one modelIdentifier; the clock `sample` is a periodic
    input clock of constant interval Ts (the parameter's start value), priority 0; every input
    and output is discrete and in its partition, no parameter is; clocked outputs are no
    initial unknowns."""
    md = read_model_description(str(fmu_path("FullPoseController")))
    assert md.coSimulation.modelIdentifier == md.scheduledExecution.modelIdentifier \
        == "FullPoseController"
    assert not md.coSimulation.hasEventMode  # co-simulation as before: no Event Mode
    se = md.scheduledExecution
    assert se.canGetAndSetFMUstate and se.canSerializeFMUstate
    clocks = [v for v in md.modelVariables if v.type == "Clock"]
    assert len(clocks) == 1
    clock = clocks[0]
    ts = next(v for v in md.modelVariables if v.name == "Ts")
    assert (clock.name, clock.valueReference, clock.causality) == ("sample", CLOCK, "input")
    # (fmpy reads neither intervalDecimal nor priority: from the XML)
    with zipfile.ZipFile(fmu_path("FullPoseController")) as z:
        xml = ElementTree.fromstring(z.read("modelDescription.xml"))
    attrs = xml.find("ModelVariables/Clock").attrib
    assert attrs["intervalVariability"] == clock.intervalVariability == "constant"
    assert float(attrs["intervalDecimal"]) == float(ts.start) == H
    assert attrs["priority"] == "0"
    assert xml.find("ScheduledExecution").attrib["modelIdentifier"] == "FullPoseController"
    partition = [v for v in md.modelVariables
                 if v.causality in ("input", "output") and v.type != "Clock"]
    assert len(partition) > 50
    for v in partition:
        assert [c.valueReference for c in v.clocks] == [CLOCK], v.name
        assert v.variability == "discrete", v.name
    assert not [v.name for v in md.modelVariables
                if v.causality == "parameter" and v.clocks]
    assert md.initialUnknowns == []
    assert len(md.outputs) == sum(v.causality == "output" for v in md.modelVariables)
    for model in ("MultirotorPlant", "ScenarioSignals"):
        other = read_model_description(str(fmu_path(model)))
        assert other.scheduledExecution is None
        assert not [v for v in other.modelVariables if v.type == "Clock"]


@pytest.mark.parametrize("model", ["MultirotorPlant", "ScenarioSignals"])
def test_plant_and_player_refuse_scheduled_execution(model, tmp_path):
    path = fmu_path(model)
    md = read_model_description(str(path))
    unzip = unzipped(path, tmp_path)
    lib = ctypes.CDLL(str(unzip / "binaries" / "x86_64-linux" / f"{model}.so"))
    log = Log()
    cb = fmi3LogMessageCallback(log)
    f = lib.fmi3InstantiateScheduledExecution
    f.restype = ctypes.c_void_p
    f.argtypes = [ctypes.c_char_p] * 3 + [ctypes.c_bool] * 2 + [
        ctypes.c_void_p, fmi3LogMessageCallback] + [ctypes.c_void_p] * 3
    assert f(b"se", md.guid.encode(), str(unzip / "resources").encode(), False, False, None,
             cb, None, None, None) is None
    assert f"fmi3InstantiateScheduledExecution: {model} provides co-simulation only" \
        in log.text()


# ---------------------------------------------------------------------------------------------
# Flying


def test_scheduled_hover_equals_cosimulation_to_the_bit(tmp_path):
    """2 s of hover 0.2 m beside the start: the controller activated every 2 ms and the
    controller stepped by fmi3DoStep(t, Ts) give the same plant positions and rotor commands,
    every one the same double; no callback was called."""
    pos_se, omega_se, calls = fly(tmp_path, scheduled_controller=True)
    pos_cs, omega_cs, _ = fly(tmp_path, scheduled_controller=False)
    assert pos_se.shape == (1000, 3)
    assert pos_se.tobytes() == pos_cs.tobytes()
    assert omega_se.tobytes() == omega_cs.tobytes()
    assert abs(pos_se[-1, 0] - 0.2) < 0.05 and np.abs(pos_se[:, 2] + 3.0).max() < 0.05
    assert calls.count == {"clockUpdate": 0, "lockPreemption": 0, "unlockPreemption": 0}


def test_time_is_the_next_instant_and_warnings_leave_the_sample_ok(tmp_path):
    """After k activations the FMU's time is t0 + k Ts, the instant of the next one (what it is
    after fmi3DoStep(t, Ts) in co-simulation); a held sample (an input beyond its plausible
    range) answers fmi3OK with its warning logged, as fmi3DoStep does."""
    with scheduled(tmp_path) as (se, log):
        assert se.getFloat64([0], 1) == [0.0]
        for k in range(5):
            assert activate(se, k * H) == FMI3_OK
            assert se.getFloat64([0], 1) == [0.0 + (k + 1) * H]
        put(se, "CTRL", "pos", [1e9, 0.0, -3.0])
        assert activate(se, 5 * H) == FMI3_OK
        assert any(s == FMI3_WARNING and "pos" in m for s, _, m in log.lines)


# ---------------------------------------------------------------------------------------------
# The off-grid policy


def test_an_activation_off_the_grid_is_refused_naming_the_time(tmp_path):
    with scheduled(tmp_path) as (se, log):
        assert activate(se, 0.0) == FMI3_OK
        assert activate(se, 0.003) == FMI3_ERROR
        assert re.search(r"fmi3ActivateModelPartition: activationTime 0\.003\d* is not the "
                         r"next instant of clock sample \(vr 5000\), t = 0\.002\d*.*off the "
                         r"clock's grid", "\n".join(log.errors())), log.errors()
        # the instance is in Error: nothing more is activated, values can still be read
        log.lines.clear()
        assert activate(se, 0.002) == FMI3_ERROR
        assert "fmi3ActivateModelPartition may not be called in state Error" in log.errors()
        assert get_float64(se, tables().CTRL["omega_cmd"][1], 8)[0] == FMI3_OK
        # fmi3Reset starts over
        se.reset()
        se.enterInitializationMode(startTime=0.0)
        se.exitInitializationMode()
        assert activate(se, 0.0) == FMI3_OK


def test_an_instant_activated_twice_or_skipped_is_refused(tmp_path):
    with scheduled(tmp_path) as (se, log):
        assert activate(se, 0.0) == FMI3_OK
        assert activate(se, H) == FMI3_OK
        assert activate(se, H) == FMI3_ERROR
        assert ("fmi3ActivateModelPartition: clock sample was activated at t = 0.002 already: "
                "each instant is activated once, in increasing time; the next one is "
                "t = 0.0040000000000000001") in log.errors()
    with scheduled(tmp_path, "skip") as (se, log):
        assert activate(se, 0.0) == FMI3_OK
        assert activate(se, 3 * H) == FMI3_ERROR
        assert any("it would skip the instants between" in m for m in log.errors())
    with scheduled(tmp_path, "early") as (se, log):
        assert activate(se, -H) == FMI3_ERROR  # before the start
        assert any("it lies before it" in m for m in log.errors())


def test_a_master_summing_its_steps_stays_on_the_grid(tmp_path):
    """Activation times summed (t += Ts, rounding a little each time) are the grid's within
    the tolerance: 5,000 activations are accepted."""
    with scheduled(tmp_path) as (se, log):
        t = 0.0
        for _ in range(5000):
            assert activate(se, t) == FMI3_OK, log.errors()
            t += H
        assert t != 5000 * H  # the sum did drift from the grid


# ---------------------------------------------------------------------------------------------
# The call-sequence discipline


def test_activation_before_initialization_and_after_termination_is_an_error(tmp_path):
    with scheduled(tmp_path, initialize=False) as (se, log):
        assert activate(se, 0.0) == FMI3_ERROR
        assert "fmi3ActivateModelPartition may not be called in state Instantiated" \
            in log.errors()
        se.enterInitializationMode(startTime=0.0)
        assert activate(se, 0.0) == FMI3_ERROR
        assert "fmi3ActivateModelPartition may not be called in state Initialization Mode" \
            in log.errors()
        se.exitInitializationMode()
        assert activate(se, 0.0) == FMI3_OK
        se.terminate()
        assert activate(se, H) == FMI3_ERROR
        assert "fmi3ActivateModelPartition may not be called in state Terminated" \
            in log.errors()


def test_an_unknown_clock_reference_is_an_error_that_changes_nothing(tmp_path):
    with scheduled(tmp_path) as (se, log):
        assert activate(se, 0.0, clock=7) == FMI3_ERROR
        assert ("fmi3ActivateModelPartition: unknown clock reference 7; the FMU's one input "
                "clock is sample (vr 5000)") in log.errors()
        assert activate(se, 0.0, clock=1000) == FMI3_ERROR
        assert ("fmi3ActivateModelPartition: clockReference 1000 is the variable pos_ref, not "
                "a clock; the FMU's one input clock is sample (vr 5000)") in log.errors()
        assert activate(se, 0.0) == FMI3_OK  # still in Clock Activation Mode


def test_each_interface_refuses_the_others_step(tmp_path):
    with scheduled(tmp_path) as (se, log):
        assert do_step(se, 0.0) == FMI3_ERROR
        assert any(m.startswith("fmi3DoStep may not be called in state Clock Activation Mode")
                   for m in log.errors())
        assert activate(se, 0.0) == FMI3_OK
    with cosimulation("FullPoseController", tmp_path, "cs") as (cs, log):
        cs.enterInitializationMode(startTime=0.0)
        cs.exitInitializationMode()
        assert activate(cs, 0.0) == FMI3_ERROR
        assert any(m.startswith("fmi3ActivateModelPartition: a Co-Simulation instance")
                   for m in log.errors())
        assert do_step(cs, 0.0) == FMI3_OK


def test_values_are_not_read_between_a_set_and_the_next_activation(tmp_path):
    """FMI 3.0, Clock Activation Mode: no fmi3Get after an fmi3Set without an activation in
    between."""
    with scheduled(tmp_path) as (se, log):
        assert get_float64(se, tables().CTRL["omega_cmd"][1], 8)[0] == FMI3_OK  # nothing set yet
        put(se, "CTRL", "pos", POS0)
        assert get_float64(se, tables().CTRL["omega_cmd"][1], 8)[0] == FMI3_ERROR
        assert any(m.startswith("fmi3GetFloat64 may not be called in Clock Activation Mode "
                                "after an fmi3Set call") for m in log.errors())
        assert activate(se, 0.0) == FMI3_OK
        assert get_float64(se, tables().CTRL["omega_cmd"][1], 8)[0] == FMI3_OK


def test_ts_is_the_clocks_constant_interval(tmp_path):
    """Ts set to another value: Scheduled Execution refuses it at fmi3ExitInitializationMode
    naming both (co-simulation takes it, as before)."""
    with pytest.raises(FMICallException):
        with scheduled(tmp_path, ts=0.004):
            pass
    with scheduled(tmp_path, "ts", initialize=False) as (se, log):
        se.enterInitializationMode(startTime=0.0)
        se.setFloat64([1], [0.004])
        assert se.dll.fmi3ExitInitializationMode(se.component) == FMI3_ERROR
        assert any("Ts = 0.0040000000000000001 s, but in Scheduled Execution the clock sample "
                   "(vr 5000) activates the samples at its constant interval "
                   "0.002 s" in m for m in log.errors())
    with cosimulation("FullPoseController", tmp_path, "cs") as (cs, _):
        cs.enterInitializationMode(startTime=0.0)
        cs.setFloat64([1], [0.004])
        cs.exitInitializationMode()


def test_the_clock_functions(tmp_path):
    with scheduled(tmp_path) as (se, log):
        vr = (ctypes.c_uint32 * 1)(CLOCK)
        interval = (ctypes.c_double * 1)()
        qualifier = (ctypes.c_int * 1)()
        assert se.dll.fmi3GetIntervalDecimal(se.component, vr, 1, interval, qualifier) == 0
        assert (interval[0], qualifier[0]) == (H, INTERVAL_UNCHANGED)
        shift = (ctypes.c_double * 1)(1.0)
        assert se.dll.fmi3GetShiftDecimal(se.component, vr, 1, shift) == FMI3_OK
        assert shift[0] == 0.0
        assert se.dll.fmi3SetIntervalDecimal(se.component, vr, 1, interval) == FMI3_ERROR
        assert ("fmi3SetIntervalDecimal: not provided: the clock sample has a constant interval "
                "and no shift (intervalVariability=\"constant\"): nothing sets them") \
            in log.errors()
        clock = (ctypes.c_bool * 1)()
        assert se.dll.fmi3GetClock(se.component, vr, 1, clock) == FMI3_ERROR
        assert se.dll.fmi3SetClock(se.component, vr, 1, clock) == FMI3_ERROR
        assert any(m.startswith("fmi3GetClock: sample (vr 5000) is the input clock of "
                                "Scheduled Execution") for m in log.errors())
        assert get_float64(se, CLOCK, 1)[0] == FMI3_ERROR
        assert "fmi3GetFloat64: variable sample (vr 5000) is of type Clock, the input clock " \
               "of Scheduled Execution (fmi3ActivateModelPartition activates it)" in log.errors()
        bad = (ctypes.c_uint32 * 1)(1000)
        assert se.dll.fmi3GetIntervalDecimal(se.component, bad, 1, interval,
                                             qualifier) == FMI3_ERROR
        assert activate(se, 0.0) == FMI3_OK  # none of these changed the state


def test_callbacks_may_be_null(tmp_path):
    with scheduled(tmp_path, null_callbacks=True) as (se, log):
        for k in range(3):
            assert activate(se, k * H) == FMI3_OK, log.errors()


# ---------------------------------------------------------------------------------------------
# FMU states


def run(se, inputs: dict[str, list[float]], k0: int, n: int, step) -> np.ndarray:
    """n samples from instant k0 with constant inputs: the rotor commands after each."""
    out = []
    for k in range(k0, k0 + n):
        for name, values in inputs.items():
            put(se, "CTRL", name, values)
        put(se, "CTRL", "pos_ref", POS_REF)
        assert step(se, k * H) == FMI3_OK
        out.append(get(se, "CTRL", "omega_cmd") + get(se, "CTRL", "alpha_cmd"))
    return np.array(out)


def test_fmu_states_in_clock_activation_mode(tmp_path):
    """A state taken after 100 samples, restored (directly and through serialization),
    reproduces the next 20 to the bit; in a co-simulation instance, stepped by fmi3DoStep(t,
    Ts), it does too, and a co-simulation state restores in Scheduled Execution."""
    inputs = hover_inputs(tmp_path)
    with scheduled(tmp_path) as (se, log):
        run(se, inputs, 0, 100, activate)
        state = se.getFMUState()
        ahead = run(se, inputs, 100, 20, activate)
        se.setFMUState(state)
        assert se.getFloat64([0], 1) == [100 * H]
        assert run(se, inputs, 100, 20, activate).tobytes() == ahead.tobytes()
        blob = se.serializeFMUState(state)
        se.setFMUState(se.deserializeFMUState(blob))
        assert run(se, inputs, 100, 20, activate).tobytes() == ahead.tobytes()
        se.freeFMUState(state)
        with cosimulation("FullPoseController", tmp_path, "cs") as (cs, _):
            cs.enterInitializationMode(startTime=0.0)
            cs.exitInitializationMode()
            cs.setFMUState(cs.deserializeFMUState(blob))
            assert run(cs, inputs, 100, 20, do_step).tobytes() == ahead.tobytes()
            run(cs, inputs, 120, 5, do_step)
            back = cs.serializeFMUState(cs.getFMUState())
        se.setFMUState(se.deserializeFMUState(back))
        assert se.getFloat64([0], 1) == [125 * H]
        assert activate(se, 125 * H) == FMI3_OK, log.errors()


# ---------------------------------------------------------------------------------------------
# fmusim


def fmusim_exe() -> Path:
    folder = os.environ.get("FULLPOSE_FMI_TOOLS")
    exe = Path(folder) / "bin" / "fmusim" if folder else None
    if exe is None or not os.access(exe, os.X_OK):
        found = shutil.which("fmusim")
        if found is None:
            pytest.skip("fmusim not found (set FULLPOSE_FMI_TOOLS to the folder holding "
                        "bin/fmusim; tests/tools/fmi_tools.sh builds it)")
        exe = Path(found)
    return exe


@pytest.mark.fmitools
def test_fmusim_validates_the_scheduled_archive():
    run_ = subprocess.run([str(fmusim_exe()), "validate", str(fmu_path("FullPoseController"))],
                          capture_output=True, text=True, timeout=300)
    text = run_.stdout + run_.stderr
    assert run_.returncode == 0, text
    assert "Validating model description" in text and "error" not in text.lower()


@pytest.mark.fmitools
def test_fmusim_runs_the_controller_alone_under_scheduled_execution(tmp_path):
    """Only if fmusim can: 0.8 offers --interface-type me and cs, no Scheduled Execution."""
    exe = str(fmusim_exe())
    help_ = subprocess.run([exe, "simulate", "--help"], capture_output=True, text=True,
                           timeout=60).stdout
    kinds = re.findall(r"^\s*- (\w+): ", help_.split("--interface-type", 1)[-1], re.M)
    if "se" not in kinds:
        pytest.skip(f"fmusim has no Scheduled Execution (--interface-type: {', '.join(kinds)})")
    out = tmp_path / "se.csv"
    run_ = subprocess.run([exe, "simulate", "--interface-type", "se", "--stop-time", "1",
                           "--output-file", str(out), str(fmu_path("FullPoseController"))],
                          capture_output=True, text=True, timeout=300)
    assert run_.returncode == 0, run_.stdout + run_.stderr
    assert out.exists()
