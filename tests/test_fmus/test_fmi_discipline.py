"""FMI 2.0 discipline of the glue (fmu_src/common/fmi2_glue.c), driven the way importers drive
an FMU: fmpy's FMU2Slave and raw ctypes calls on its library.

* FMU states are checked before use: another FMU's state or a buffer that is no state is
  refused by every state function (never read or written beyond its magic);
* every refused call logs why, NULL arguments included;
* fmi2Get*Status answer only in StepComplete, StepFailed and Terminated;
* a refused call (illegal in the state, bad argument) changes nothing and the instance stays
  usable; a failed step (refused step size or time, the work cap, the model's refusal) puts
  it in Error, where only diagnosis, FMU states, reset and free are allowed;
* a call on a freed instance is detected (best effort) and refused;
* one fmi2DoStep does at most 10^6 internal steps, refused before any work.
"""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys
import textwrap
import time
from ctypes import POINTER, byref, c_double, c_int, c_size_t, c_uint, c_void_p
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

from orchestrator.sim.fmu import FmuError, FmuInstance
from plant import plant_fmu

ROOT = Path(__file__).resolve().parents[2]
H = 0.002
OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3
DO_STEP_STATUS, PENDING_STATUS, LAST_SUCCESSFUL_TIME, TERMINATED = 0, 1, 2, 3


def raw(inst: FmuInstance, name: str, *argtypes):
    """fmi2 function `name` of the instance's library with our own prototype (int result)."""
    return ctypes.CFUNCTYPE(c_int, *argtypes)((name, inst.slave.dll))


def error_messages(inst: FmuInstance) -> list[str]:
    return [m for s, _, m in inst.messages if s == "ERROR"]


@pytest.fixture
def make(make_fmu):
    """Instances of either FMU (conftest's make_fmu)."""
    return make_fmu


# ---------------------------------------------------------------------------
# FMU states of another FMU, or no state at all

STATE_CHILD = textwrap.dedent(r"""
    import ctypes, json
    from ctypes import byref, c_int, c_size_t, c_void_p, POINTER
    from controller import controller_fmu
    from orchestrator.sim.fmu import FmuInstance
    from plant import plant_fmu

    plant = FmuInstance(plant_fmu(), "plant"); plant.initialize()
    ctrl = FmuInstance(controller_fmu(), "ctrl"); ctrl.initialize()

    def fn(inst, name, *types):
        return ctypes.CFUNCTYPE(c_int, *types)((name, inst.slave.dll))

    def calls(inst, state):
        comp = inst.slave.component
        blob = bytes(inst.slave.serializeFMUstate(own := inst.slave.getFMUstate()))
        inst.slave.freeFMUstate(own)
        size = c_size_t(0)
        out = ctypes.create_string_buffer(1 << 20)
        slot = lambda: c_void_p(state)
        return {
            "fmi2GetFMUstate": lambda: fn(inst, "fmi2GetFMUstate", c_void_p,
                                          POINTER(c_void_p))(comp, byref(slot())),
            "fmi2SetFMUstate": lambda: fn(inst, "fmi2SetFMUstate", c_void_p, c_void_p)(
                comp, state),
            "fmi2SerializedFMUstateSize": lambda: fn(
                inst, "fmi2SerializedFMUstateSize", c_void_p, c_void_p, POINTER(c_size_t))(
                comp, state, byref(size)),
            "fmi2SerializeFMUstate": lambda: fn(
                inst, "fmi2SerializeFMUstate", c_void_p, c_void_p, c_void_p, c_size_t)(
                comp, state, out, len(out)),
            "fmi2DeSerializeFMUstate": lambda: fn(
                inst, "fmi2DeSerializeFMUstate", c_void_p, ctypes.c_char_p, c_size_t,
                POINTER(c_void_p))(comp, blob, len(blob), byref(slot())),
            "fmi2FreeFMUstate": lambda: fn(inst, "fmi2FreeFMUstate", c_void_p,
                                           POINTER(c_void_p))(comp, byref(slot())),
        }

    result = {}
    plant_state = plant.slave.getFMUstate()
    ctrl_state = ctrl.slave.getFMUstate()
    fake = ctypes.create_string_buffer(b"\xa5" * 8, 8)  # pointer-sized, no state
    cases = [("plant state -> controller", ctrl, plant_state.value),
             ("controller state -> plant", plant, ctrl_state.value),
             ("8 random bytes -> plant", plant, ctypes.addressof(fake)),
             ("8 random bytes -> controller", ctrl, ctypes.addressof(fake))]
    for label, inst, state in cases:
        for name, call in calls(inst, state).items():
            inst.messages.clear()
            status = call()
            result[f"{label}: {name}"] = [status, [m for s, _, m in inst.messages
                                                   if s == "ERROR"]]
    assert fake.raw == b"\xa5" * 8, "the fake state was written"
    # the states handed around are intact: their own FMUs still restore them
    plant.slave.setFMUstate(plant_state); plant.slave.freeFMUstate(plant_state)
    ctrl.slave.setFMUstate(ctrl_state); ctrl.slave.freeFMUstate(ctrl_state)
    plant.step(0.002); ctrl.step(0.002)
    plant.close(); ctrl.close()
    print(json.dumps(result))
""")


def test_a_foreign_or_fake_state_is_refused_by_every_state_function():
    """Run in a child process: without the checks, the plant's 3 kB state would be
    overwritten by the controller's 167 kB (a heap overflow), or an importer's buffer freed."""
    result = json.loads(run_child(STATE_CHILD))
    assert len(result) == 4 * 6
    for call, (status, messages) in result.items():
        assert status == ERROR, (call, status, messages)
        fn = call.split(": ")[1]
        expected = "belongs to another FMU" if "state ->" in call else 'no "FPST" magic'
        assert any(m.startswith(fn) and expected in m for m in messages), (call, messages)


def test_reusing_an_own_state_in_fmi2GetFMUstate_overwrites_it_in_place(make):
    a, b = make(), make()  # two instances of one FMU share the state format
    a.step(H)
    state = a.slave.getFMUstate()
    address = state.value
    b.step(H)
    b.step(H)
    raw(b, "fmi2GetFMUstate", c_void_p, POINTER(c_void_p))(b.slave.component, byref(state))
    assert state.value == address
    a.slave.setFMUstate(state)
    assert a.slave.getRealStatus(LAST_SUCCESSFUL_TIME) == pytest.approx(2 * H, abs=1e-15)
    a.slave.freeFMUstate(state)
    assert state.value is None


DOUBLE_FREE_CHILD = textwrap.dedent(r"""
    import ctypes, json
    from ctypes import byref, c_int, c_void_p, POINTER
    from orchestrator.sim.fmu import FmuInstance
    from plant import plant_fmu
    inst = FmuInstance(plant_fmu(), "plant"); inst.initialize()
    state = inst.slave.getFMUstate()
    copy = c_void_p(state.value)
    inst.slave.freeFMUstate(state)
    inst.messages.clear()
    free_state = ctypes.CFUNCTYPE(c_int, c_void_p, POINTER(c_void_p))(
        ("fmi2FreeFMUstate", inst.slave.dll))
    status = free_state(inst.slave.component, byref(copy))
    print(json.dumps([status, [m for s, _, m in inst.messages if s == "ERROR"]]))
    inst.close()
""")


def run_child(code: str) -> str:
    """Runs `code` in a fresh interpreter (a crash there fails the test, not the session);
    returns its last line of output."""
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=120)
    assert run.returncode == 0, f"child died ({run.returncode}): {run.stderr[-2000:]}"
    return run.stdout.strip().splitlines()[-1]


def test_freeing_a_state_twice_is_refused():
    """Best effort, like the instance check: fmi2FreeFMUstate wipes the header before the
    memory is freed, and nothing has reused the block yet in this short sequence."""
    status, messages = json.loads(run_child(DOUBLE_FREE_CHILD))
    assert status == ERROR
    assert any(m.startswith("fmi2FreeFMUstate") and "magic" in m for m in messages), messages


# ---------------------------------------------------------------------------
# Every refusal logs why: NULL arguments


def _null_calls(inst: FmuInstance):
    comp = inst.slave.component
    vr = (c_uint * 1)(0)
    real = (c_double * 1)()
    integer = (c_int * 1)()
    state = inst.slave.getFMUstate()
    size = c_size_t()
    vp, pvp = c_void_p, POINTER(c_void_p)
    # (function, the NULL argument, the value buffer): the array get/set functions
    arrays = [("fmi2GetReal", "vr", real), ("fmi2GetReal", "value", real),
              ("fmi2SetReal", "vr", real), ("fmi2SetReal", "value", real),
              ("fmi2GetInteger", "vr", integer), ("fmi2SetInteger", "value", integer),
              ("fmi2GetBoolean", "value", integer), ("fmi2SetBoolean", "vr", integer),
              ("fmi2GetString", "vr", real), ("fmi2SetString", "vr", real)]

    def array_call(fn: str, null: str, buf: object):
        return lambda: raw(inst, fn, vp, vp, c_size_t, vp)(
            comp, None if null == "vr" else vr, 1, None if null == "value" else buf)

    return {
        **{f"{fn} {null}": array_call(fn, null, buf) for fn, null, buf in arrays},
        "fmi2SetDebugLogging categories": lambda: raw(
            inst, "fmi2SetDebugLogging", vp, c_int, c_size_t, vp)(comp, 1, 1, None),
        "fmi2GetFMUstate FMUstate": lambda: raw(inst, "fmi2GetFMUstate", vp, pvp)(comp, None),
        "fmi2SetFMUstate FMUstate": lambda: raw(inst, "fmi2SetFMUstate", vp, vp)(comp, None),
        "fmi2FreeFMUstate FMUstate": lambda: raw(inst, "fmi2FreeFMUstate", vp, pvp)(comp, None),
        "fmi2SerializedFMUstateSize size": lambda: raw(
            inst, "fmi2SerializedFMUstateSize", vp, vp, vp)(comp, state, None),
        "fmi2SerializedFMUstateSize FMUstate": lambda: raw(
            inst, "fmi2SerializedFMUstateSize", vp, vp, vp)(comp, None, byref(size)),
        "fmi2SerializeFMUstate FMUstate": lambda: raw(
            inst, "fmi2SerializeFMUstate", vp, vp, vp, c_size_t)(comp, None, real, 8),
        "fmi2SerializeFMUstate serializedState": lambda: raw(
            inst, "fmi2SerializeFMUstate", vp, vp, vp, c_size_t)(comp, state, None, 1 << 20),
        "fmi2DeSerializeFMUstate serializedState": lambda: raw(
            inst, "fmi2DeSerializeFMUstate", vp, vp, c_size_t, pvp)(comp, None, 100,
                                                                   byref(c_void_p())),
        "fmi2DeSerializeFMUstate FMUstate": lambda: raw(
            inst, "fmi2DeSerializeFMUstate", vp, vp, c_size_t, pvp)(comp, real, 8, None),
        "fmi2GetStatus value": lambda: raw(inst, "fmi2GetStatus", vp, c_int, vp)(
            comp, DO_STEP_STATUS, None),
        "fmi2GetRealStatus value": lambda: raw(inst, "fmi2GetRealStatus", vp, c_int, vp)(
            comp, LAST_SUCCESSFUL_TIME, None),
        "fmi2GetIntegerStatus value": lambda: raw(inst, "fmi2GetIntegerStatus", vp, c_int, vp)(
            comp, DO_STEP_STATUS, None),
        "fmi2GetBooleanStatus value": lambda: raw(inst, "fmi2GetBooleanStatus", vp, c_int, vp)(
            comp, TERMINATED, None),
        "fmi2GetStringStatus value": lambda: raw(inst, "fmi2GetStringStatus", vp, c_int, vp)(
            comp, PENDING_STATUS, None),
    }, state


def test_null_arguments_are_refused_with_a_message(make):
    inst = make()
    inst.step(H)
    calls, state = _null_calls(inst)
    silent = []
    for label, call in calls.items():
        inst.messages.clear()
        status = call()
        fn, what = label.split(" ")
        if status != ERROR or not any(m.startswith(fn) and "NULL" in m and what in m
                                      for m in error_messages(inst)):
            silent.append((label, status, inst.messages[:]))
    assert not silent, silent
    # nothing of that changed the instance: it steps on
    inst.slave.freeFMUstate(state)
    inst.step(H)


# ---------------------------------------------------------------------------
# fmi2Get*Status: only where the FMI 2.0 co-simulation state table allows them


def _status_calls(inst: FmuInstance):
    comp = inst.slave.component
    out = {"real": c_double(), "int": c_int(), "status": c_int(), "str": c_void_p()}
    vp = c_void_p
    return {
        "fmi2GetStatus": lambda: raw(inst, "fmi2GetStatus", vp, c_int, vp)(
            comp, DO_STEP_STATUS, byref(out["status"])),
        "fmi2GetRealStatus": lambda: raw(inst, "fmi2GetRealStatus", vp, c_int, vp)(
            comp, LAST_SUCCESSFUL_TIME, byref(out["real"])),
        "fmi2GetIntegerStatus": lambda: raw(inst, "fmi2GetIntegerStatus", vp, c_int, vp)(
            comp, DO_STEP_STATUS, byref(out["int"])),
        "fmi2GetBooleanStatus": lambda: raw(inst, "fmi2GetBooleanStatus", vp, c_int, vp)(
            comp, TERMINATED, byref(out["int"])),
        "fmi2GetStringStatus": lambda: raw(inst, "fmi2GetStringStatus", vp, c_int, vp)(
            comp, PENDING_STATUS, byref(out["str"])),
    }, out


def _assert_status_refused(inst: FmuInstance, state_name: str) -> None:
    calls, _ = _status_calls(inst)
    for fn, call in calls.items():
        inst.messages.clear()
        assert call() == ERROR, (fn, state_name)
        assert f"{fn} may not be called in state {state_name}" in error_messages(inst), \
            inst.messages


def test_status_functions_are_refused_in_instantiated_initialization_and_error(make):
    inst = make(initialize=False)
    _assert_status_refused(inst, "Instantiated")
    inst.slave.setupExperiment(startTime=0.0)
    inst.slave.enterInitializationMode()
    _assert_status_refused(inst, "InitializationMode")
    inst.slave.exitInitializationMode()
    with pytest.raises(FMICallException):
        inst.slave.doStep(1.0, H)  # a communication point that is not the FMU's time
    _assert_status_refused(inst, "Error")


def test_status_functions_answer_after_steps_and_termination(make):
    inst = make()
    inst.step(H)
    calls, out = _status_calls(inst)
    for state_name in ("StepComplete", "Terminated"):
        if state_name == "Terminated":
            inst.slave.terminate()
        inst.messages.clear()
        assert calls["fmi2GetRealStatus"]() == OK and out["real"].value == pytest.approx(H)
        assert calls["fmi2GetBooleanStatus"]() == OK and out["int"].value == 0
        for fn in ("fmi2GetStatus", "fmi2GetIntegerStatus", "fmi2GetStringStatus"):
            assert calls[fn]() == DISCARD  # no asynchronous step: nothing to report
        warned = [m for s, _, m in inst.messages if s == "WARNING"]
        assert len(warned) == 3 and all("not provided" in m for m in warned), inst.messages


# ---------------------------------------------------------------------------
# Error state: refused calls change nothing; failed steps leave the instance in Error


def test_a_refused_set_changes_nothing_and_the_instance_stays_usable(make):
    inst = make()
    inst.step(H)
    before = inst.get("omega_cmd[1]")
    good, bad = inst.vr("omega_cmd[1]"), 99999
    with pytest.raises(FMICallException) as e:
        inst.slave.setReal([good, bad], [before + 10.0, 1.0])
    assert e.value.status == ERROR
    assert inst.get("omega_cmd[1]") == before  # all or nothing: the good element too
    with pytest.raises(FmuError, match="cannot set mass"):
        inst.set("mass", 2.0)  # a fixed parameter after initialization
    inst.step(H)  # refusals are not failures: still StepComplete
    assert inst.slave.getRealStatus(LAST_SUCCESSFUL_TIME) == pytest.approx(2 * H)


def test_the_live_session_survives_a_refused_controller_parameter():
    """The MAVLink bridge applies ground-station parameters through
    LiveSession.set_controller_parameter and keeps flying when one is refused."""
    from orchestrator.sim.live import LiveSession

    with LiveSession(chunk=2) as live:
        live.advance()
        with pytest.raises(FmuError):
            live.ctrl_inst.set("Ts", 0.004)  # fixed: refused by the FMU
        live.advance()
        assert live.time == pytest.approx(4 * H)
        assert np.all(np.isfinite(live.state()["plant"]["pos"]))


@pytest.mark.parametrize("why", ["step_size", "communication_point", "work_cap"])
def test_a_failed_step_puts_the_instance_in_error(make, why):
    inst = make("controller")
    inst.step(H)
    saved = inst.slave.getFMUstate()
    inst.step(H)
    outputs = inst.signal(["omega_cmd", "alpha_cmd", "mu_c"])
    before = inst.read(outputs).copy()
    t, h = {"step_size": (inst.time, -H), "communication_point": (inst.time + H, H),
            "work_cap": (inst.time, 2000.002)}[why]
    with pytest.raises(FMICallException) as e:
        inst.slave.doStep(t, h)
    assert e.value.status == ERROR
    # in Error: no stepping, setting or terminating ...
    for call, fn in [(lambda: inst.slave.doStep(inst.time, H), "fmi2DoStep"),
                     (lambda: inst.set("pos_ref[1]", 1.0), "fmi2SetReal"),
                     (lambda: inst.slave.terminate(), "fmi2Terminate"),
                     (lambda: inst.slave.getRealStatus(LAST_SUCCESSFUL_TIME),
                      "fmi2GetRealStatus")]:
        inst.messages.clear()
        with pytest.raises(FMICallException):
            call()
        assert f"{fn} may not be called in state Error" in error_messages(inst)
    # ... but diagnosis (the values are as before the failed call) and FMU states
    np.testing.assert_array_equal(inst.read(outputs), before)
    snapshot = inst.slave.getFMUstate()
    inst.slave.freeFMUstate(snapshot)
    inst.slave.setFMUstate(saved)  # back to StepComplete at t = H
    inst.slave.freeFMUstate(saved)
    inst.time = H
    inst.step(H)
    np.testing.assert_array_equal(inst.read(outputs), before)  # deterministic replay
    inst.slave.reset()


# ---------------------------------------------------------------------------
# A call after fmi2FreeInstance


def test_a_call_after_fmi2FreeInstance_is_refused(tmp_path):
    """The importer's allocator here keeps freed blocks (so the test is deterministic);
    with a real free the check holds only while the allocator has not reused the block."""
    if os.name == "nt":
        pytest.skip("uses the C library's calloc/free through ctypes.CDLL(None)")
    libc = ctypes.CDLL(None)
    libc.calloc.restype, libc.calloc.argtypes = c_void_p, [c_size_t, c_size_t]
    libc.free.restype, libc.free.argtypes = None, [c_void_p]
    quarantine: list[int] = []
    messages: list[tuple[int, str]] = []

    def log(env, name, status, category, message):
        messages.append((status, message.decode()))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(lambda n, size: libc.calloc(n, size))
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(lambda p: quarantine.append(p))
    path = str(plant_fmu())
    md = read_model_description(path)
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(path, str(tmp_path)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="freed")
    try:
        slave.instantiate(callbacks=callbacks)
        comp = slave.component
        vp = c_void_p

        def fn(name, *types):
            return ctypes.CFUNCTYPE(c_int, *types)((name, slave.dll))

        ctypes.CFUNCTYPE(None, vp)(("fmi2FreeInstance", slave.dll))(comp)
        assert quarantine, "fmi2FreeInstance released nothing"
        value = (c_double * 1)()
        after = {
            "fmi2SetupExperiment": lambda: fn("fmi2SetupExperiment", vp, c_int, c_double,
                                              c_double, c_int, c_double)(comp, 0, 0.0, 0.0, 0,
                                                                         0.0),
            "fmi2EnterInitializationMode": lambda: fn("fmi2EnterInitializationMode", vp)(comp),
            "fmi2SetReal": lambda: fn("fmi2SetReal", vp, vp, c_size_t, vp)(
                comp, (c_uint * 1)(int(md.modelVariables[0].valueReference)), 1, value),
            "fmi2DoStep": lambda: fn("fmi2DoStep", vp, c_double, c_double, c_int)(
                comp, 0.0, H, 1),
            "fmi2Reset": lambda: fn("fmi2Reset", vp)(comp),
            "fmi2GetFMUstate": lambda: fn("fmi2GetFMUstate", vp, vp)(comp, byref(c_void_p())),
        }
        for name, call in after.items():
            messages.clear()
            assert call() == ERROR, name
            assert any(s == ERROR and m.startswith(name) and "freed" in m
                       for s, m in messages), (name, messages)
        n = len(quarantine)
        messages.clear()
        ctypes.CFUNCTYPE(None, vp)(("fmi2FreeInstance", slave.dll))(comp)  # a second free
        assert len(quarantine) == n, "freed twice"
        assert any("fmi2FreeInstance" in m and "freed" in m for _, m in messages), messages
    finally:
        slave.freeLibrary()
        for p in quarantine:
            libc.free(p)


# ---------------------------------------------------------------------------
# The work of one fmi2DoStep


@pytest.mark.parametrize("which, internal, h_ok", [("plant", "h_internal", 0.5),
                                                   ("controller", "Ts", 2.0)])
def test_one_doStep_is_capped_at_a_million_internal_steps(make, which, internal, h_ok):
    inst = make(which)
    step = inst.get(internal)
    h = 1_000_001 * step  # one internal step over the cap
    t0 = time.perf_counter()
    with pytest.raises(FMICallException) as e:
        inst.slave.doStep(inst.time, h)
    assert time.perf_counter() - t0 < 0.5  # refused before any work
    assert e.value.status == ERROR
    text = " | ".join(error_messages(inst))
    assert f"h = {h:.12g} s" in text and "1000001 internal steps" in text, text
    assert f"the cap is 1000000 internal steps per fmi2DoStep ({1e6 * step:.12g} s)" in text
    inst.slave.reset()
    inst.initialize()
    inst.step(h_ok)  # long steps within the cap still run
