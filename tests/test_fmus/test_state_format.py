"""The FMU state format (fmu_src/common/fmu_state.c, used by fmi2_fmustate.c): a checked,
versioned header, then the model struct.  A state survives serialization into another
process bit for bit; a state of another FMU, of another format version, damaged or
truncated is refused with a message naming what is wrong, before anything of it is used.
The header's lifecycle state must agree with the model it holds: the payload carries the
model's ``initialized`` marker (an int32 the glue keeps, 0 until fmi2ExitInitializationMode,
1 from then on), so a header relabelled across the end of initialization never passes.

Header (80 bytes, the saving machine's byte order), then ``payload_size`` bytes of model:

    offset size field
    0      4    magic b"FPST"
    4      2    format version (3; 2 had padding where the marker is)
    6      2    byte-order marker 0x0102
    8      4    header size (80)
    12     4    payload size (sizeof the model struct)
    16     40   GUID of the FMU, NUL-terminated
    56     4    lifecycle state (one bit: 1 Instantiated, 2 InitializationMode, 4 StepComplete,
                8 StepFailed, 16 Terminated, 32 Error)
    60     4    flags (1: parameters changed since the last initialize, 2: tunables changed)
    64     8    time (double)
    72     8    checksum: 64-bit FNV-1a over the header (this field zero), then the payload
"""

from __future__ import annotations

import ctypes
import json
import os
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from helpers import logged

from orchestrator.sim.fmu import FmuInstance

ROOT = Path(__file__).resolve().parents[2]
H = 0.002
HEADER = struct.Struct("<4sHHII40siIdQ")
HEADER_SIZE = 80
INSTANTIATED, INITIALIZATION_MODE, STEP_COMPLETE, TERMINATED, ERROR_STATE = 1, 2, 4, 16, 32
FMI2_ERROR = 3
NOISY = {"noise_pos": 0.01, "noise_vel": 0.02, "noise_acc": 0.1, "noise_att": 0.01,
         "noise_rate": 0.05, "noise_ang_acc": 0.5, "noise_seed": 42,
         "rate0[1]": 0.3, "rate0[2]": -0.2, "rate0[3]": 0.1}


def fnv1a64(data: bytes, h: int = 14695981039346656037) -> int:
    for b in data:
        h = ((h ^ b) * 1099511628211) & 0xFFFFFFFFFFFFFFFF
    return h


def header(blob: bytes) -> dict:
    names = ("magic", "version", "endian", "header_size", "payload_size", "guid", "state",
             "flags", "time", "checksum")
    h = dict(zip(names, HEADER.unpack_from(blob), strict=True))
    h["guid"] = h["guid"].split(b"\0")[0].decode()
    return h


def reseal(blob: bytes | bytearray) -> bytes:
    """The blob with its checksum recomputed (a forged or edited state)."""
    b = bytearray(blob)
    b[72:80] = bytes(8)
    b[72:80] = fnv1a64(bytes(b)).to_bytes(8, "little")
    return bytes(b)


@pytest.fixture
def make(make_fmu):
    """Instances of either FMU (conftest's make_fmu)."""
    return make_fmu


def serialize(inst: FmuInstance) -> bytes:
    state = inst.slave.getFMUstate()
    try:
        return bytes(inst.slave.serializeFMUstate(state))
    finally:
        inst.slave.freeFMUstate(state)


def refused(inst: FmuInstance, blob: bytes, fragment: str) -> None:
    inst.messages.clear()
    with pytest.raises(FMICallException) as e:
        state = inst.slave.deSerializeFMUstate(blob)
        inst.slave.setFMUstate(state)  # reached only if deserialization let it through
    assert e.value.status == FMI2_ERROR
    assert fragment in " | ".join(logged(inst, "ERROR")), inst.messages


@pytest.mark.parametrize("which", ["plant", "controller"])
def test_the_header_is_the_documented_format(make, which):
    inst = make(which)
    for _ in range(3):
        inst.step(H)
    blob = serialize(inst)
    h = header(blob)
    assert h["magic"] == b"FPST" and h["version"] == 3 and h["endian"] == 0x0102
    assert h["header_size"] == HEADER_SIZE == HEADER.size
    assert h["payload_size"] == len(blob) - HEADER_SIZE
    assert h["guid"] == inst.md.guid
    assert h["state"] == STEP_COMPLETE and h["flags"] == 0
    assert h["time"] == pytest.approx(3 * H, abs=1e-15)
    zeroed = blob[:72] + bytes(8) + blob[80:]
    assert h["checksum"] == fnv1a64(zeroed)


CHILD = textwrap.dedent("""
    import json, sys
    import numpy as np
    from controller import controller_fmu
    from orchestrator.sim.fmu import FmuInstance
    from plant import plant_fmu
    which, blob_path, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    inst = FmuInstance(plant_fmu() if which == "plant" else controller_fmu(), "restored")
    # a fresh instance, never initialized: the state brings everything
    state = inst.slave.deSerializeFMUstate(open(blob_path, "rb").read())
    inst.slave.setFMUstate(state)
    inst.slave.freeFMUstate(state)
    inst.time = inst.slave.getRealStatus(2)  # fmi2LastSuccessfulTime
    out = [v.name for v in inst.md.modelVariables if v.causality == "output" and v.type == "Real"
           and not v.name.startswith("t_")]
    sig = inst.signal(out)
    rows = []
    for k in range(n):
        if which == "plant":
            t = inst.time
            inst.write(inst.signal("omega_cmd"), 97.7 + 3 * np.sin(5 * t + np.arange(8)))
        inst.step(0.002)
        rows.append(inst.read(sig).tobytes().hex())
    print(json.dumps({"time": inst.time, "rows": rows}))
    inst.close()
""")


@pytest.mark.parametrize("which", ["plant", "controller"])
def test_a_state_continues_bit_identically_in_another_process(make, which, tmp_path):
    if which == "plant":
        inst = make("plant", parameters=NOISY)  # the noise generator's state travels too
    else:
        inst = make("controller", initialize=False)
        inst.slave.setupExperiment(startTime=0.0)
        inst.write(inst.signal("pos_ref"), [0.4, -0.3, 0.2])  # both QPs non-trivial
        inst.slave.enterInitializationMode()
        inst.slave.exitInitializationMode()
    cmd = inst.signal("omega_cmd") if which == "plant" else None

    def drive() -> None:
        if cmd is not None:
            inst.write(cmd, 97.7 + 3 * np.sin(5 * inst.time + np.arange(8)))

    for _ in range(25):
        drive()
        inst.step(H)
    blob_path = tmp_path / "state.bin"
    blob_path.write_bytes(serialize(inst))
    out = [v.name for v in inst.md.modelVariables if v.causality == "output" and v.type == "Real"
           and not v.name.startswith("t_")]  # the opt-in self-timing outputs differ anyway
    sig = inst.signal(out)
    n = 40
    here = []
    for _ in range(n):
        drive()
        inst.step(H)
        here.append(inst.read(sig).tobytes().hex())
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH",
                                                                                  "")])}
    run = subprocess.run([sys.executable, "-c", CHILD, which, str(blob_path), str(n)],
                         capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert run.returncode == 0, run.stderr
    there = json.loads(run.stdout.strip().splitlines()[-1])
    assert there["time"] == inst.time
    assert there["rows"] == here  # every output bit at every step


def test_a_state_of_another_fmu_is_refused(make):
    plant, ctrl = make("plant"), make("controller")
    refused(ctrl, serialize(plant), "belongs to another FMU")
    said = " | ".join(logged(ctrl, "ERROR"))
    assert plant.md.guid in said and ctrl.md.guid in said
    refused(plant, serialize(ctrl), "belongs to another FMU")


def test_a_state_of_another_format_version_is_refused(make):
    inst = make("plant")
    blob = bytearray(serialize(inst))
    blob[4:6] = (2).to_bytes(2, "little")  # format 2: the same header, no initialized marker
    refused(inst, reseal(blob), "state format version 2; this FMU reads version 3 only")
    old = b"FPS1" + bytes(serialize(inst)[4:])  # the unchecked layout before format 2
    refused(inst, old, "state format 1")


def test_a_state_of_the_other_byte_order_is_refused(make):
    inst = make("plant")
    blob = bytearray(serialize(inst))
    blob[6:8] = (0x0201).to_bytes(2, "little")
    refused(inst, reseal(blob), "other byte order")


@pytest.mark.parametrize("where", ["payload", "header time", "last byte"])
def test_a_flipped_byte_is_caught_by_the_checksum(make, where):
    inst = make("plant")
    for _ in range(5):
        inst.step(H)
    blob = bytearray(serialize(inst))
    at = {"payload": HEADER_SIZE + 100, "header time": 64 + 3, "last byte": len(blob) - 1}[where]
    blob[at] ^= 0x10
    refused(inst, bytes(blob), "damaged: checksum mismatch")


def test_a_truncated_or_padded_state_is_refused(make):
    inst = make("controller")
    blob = serialize(inst)
    refused(inst, blob[:-1], f"truncated: {len(blob) - 1} bytes, its header says {len(blob)}")
    refused(inst, blob[:40], "shorter than the 80-byte header")
    refused(inst, blob[:3], f"truncated: 3 bytes, a state of FullPoseController has {len(blob)}")
    refused(inst, blob + b"\0", "too long")


def test_a_relabelled_lifecycle_state_is_refused(make):
    """A state saved before initialization, relabelled as StepComplete: the checksum catches
    the edit; resealed, the flags; cleared, the payload's initialized marker (every FMU:
    test_a_state_relabelled_across_the_end_of_initialization_is_refused)."""
    fresh = make("plant", initialize=False)
    blob = bytearray(serialize(fresh))
    assert header(bytes(blob))["state"] == INSTANTIATED
    blob[56:60] = STEP_COMPLETE.to_bytes(4, "little")
    refused(fresh, bytes(blob), "checksum mismatch")
    refused(fresh, reseal(blob), "flags 0x1 do not fit its lifecycle state StepComplete")
    blob[60:64] = bytes(4)  # and the parameters-changed flag cleared as well
    refused(fresh, reseal(blob), "its model was saved before the end of initialization")
    blob[56:60] = (STEP_COMPLETE | 8).to_bytes(4, "little")  # two states at once
    refused(fresh, reseal(blob), "is not one FMI state")


def state_in(make, which: str, lifecycle: int) -> tuple[FmuInstance, bytes]:
    """An instance of ``which`` and its serialized state in ``lifecycle`` with flags 0:
    Instantiated (the parameters-changed flag cleared by a reseal: an importer's edit),
    InitializationMode after a read has brought the model up to date, or StepComplete after
    one step."""
    if lifecycle == STEP_COMPLETE:
        inst = make(which)
        inst.step(H)
        return inst, serialize(inst)
    inst = make(which, initialize=False)
    if lifecycle == INITIALIZATION_MODE:
        inst.slave.setupExperiment(startTime=0.0)
        inst.slave.enterInitializationMode()
        inst.read(inst.signal("omega" if which == "plant" else "omega_cmd"))  # initialize()
    blob = bytearray(serialize(inst))
    assert header(bytes(blob))["state"] == lifecycle
    blob[60:64] = bytes(4)
    return inst, reseal(blob)


LIFECYCLE = {INSTANTIATED: "Instantiated", INITIALIZATION_MODE: "InitializationMode",
             STEP_COMPLETE: "StepComplete", TERMINATED: "Terminated"}


@pytest.mark.parametrize("saved_in, relabelled", [
    (INSTANTIATED, STEP_COMPLETE),         # issue 32, item 5: the controller stepped it
    (INSTANTIATED, TERMINATED),
    (INITIALIZATION_MODE, STEP_COMPLETE),  # initialize() ran, the initialization never ended
    (STEP_COMPLETE, INSTANTIATED),
    (STEP_COMPLETE, INITIALIZATION_MODE),
], ids=lambda v: LIFECYCLE[v])
@pytest.mark.parametrize("which", ["plant", "controller"])
def test_a_state_relabelled_across_the_end_of_initialization_is_refused(make, which, saved_in,
                                                                       relabelled):
    """The header's lifecycle must agree with the payload: a model saved before the end of
    initialization (Instantiated, InitializationMode) cannot pass as one after it
    (StepComplete, StepFailed, Terminated), nor the reverse, with the checksum resealed and
    the flags cleared.  Refused by fmi2DeSerializeFMUstate, by every FMU, naming what is
    wrong; the instance that refused it is as it was, and no step runs on it."""
    inst, blob = state_in(make, which, saved_in)
    forged = bytearray(blob)
    forged[56:60] = relabelled.to_bytes(4, "little")
    forged = reseal(forged)
    when = "before" if saved_in in (INSTANTIATED, INITIALIZATION_MODE) else "after"
    said = (f"its model was saved {when} the end of initialization, its lifecycle state "
            f"{LIFECYCLE[relabelled]} is not")
    for target in (inst, make(which)):  # the saving instance, and one that has stepped
        before = serialize(target)
        refused(target, forged, said)
        assert any(m.startswith("fmi2DeSerializeFMUstate") for m in logged(target, "ERROR"))
        assert serialize(target) == before  # nothing of it reached the live model
    # the saving instance is still in its own lifecycle state: a step is refused there, or
    # (StepComplete) runs on its own model
    if saved_in == STEP_COMPLETE:
        inst.step(H)
    else:
        inst.messages.clear()
        with pytest.raises(FMICallException):
            inst.slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)
        assert "fmi2DoStep may not be called in state" in " | ".join(logged(inst, "ERROR"))
    # the state as saved is restored, and fmi2SetFMUstate refuses the forged one as well
    restored = inst.slave.deSerializeFMUstate(blob)
    try:
        inst.slave.setFMUstate(restored)
        memory = bytearray(ctypes.string_at(restored, len(blob)))
        assert bytes(memory) == blob
        ctypes.memmove(restored, bytes(forged), len(forged))  # relabelled in memory
        for call in (lambda: inst.slave.setFMUstate(restored),
                     lambda: inst.slave.serializeFMUstate(restored)):
            inst.messages.clear()
            with pytest.raises(FMICallException):
                call()
            assert said in " | ".join(logged(inst, "ERROR"))
    finally:
        ctypes.memmove(restored, blob, len(blob))
        inst.slave.freeFMUstate(restored)


def test_a_relabelled_state_never_steps_the_controller_to_garbage(make):
    """Issue 32, item 5, as reported: the controller's state saved in Instantiated, relabelled
    StepComplete with flags 0 and the checksum resealed, was accepted by
    fmi2DeSerializeFMUstate and fmi2SetFMUstate and stepped to omega_cmd = 0 (and a division
    by zero in the fault detector, detect.c).  Now refused, and a fresh instance cannot step."""
    fresh, blob = state_in(make, "controller", INSTANTIATED)
    forged = bytearray(blob)
    forged[56:60] = STEP_COMPLETE.to_bytes(4, "little")
    forged = reseal(forged)
    accepted = False
    try:
        state = fresh.slave.deSerializeFMUstate(forged)
        fresh.slave.setFMUstate(state)
        accepted = True
    except FMICallException as e:
        assert e.status == FMI2_ERROR
        assert "lifecycle state StepComplete" in " | ".join(logged(fresh, "ERROR"))
    if accepted:  # what happened before the fix: it steps, on a model never initialized
        fresh.slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)
        omega = fresh.read(fresh.signal("omega_cmd"))
        pytest.fail(f"the relabelled state was accepted and stepped: omega_cmd = {omega}")
    with pytest.raises(FMICallException):
        fresh.slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)


@pytest.mark.parametrize("which", ["plant", "controller"])
def test_an_error_state_takes_a_model_from_either_side_of_initialization(make, which):
    """Error follows a failed initialization or a failed step, so its payload may be either;
    nothing steps in Error, and a reset leaves it."""
    stepped = make(which)
    stepped.step(H)
    with pytest.raises(FMICallException):
        stepped.slave.doStep(stepped.time, -H)  # a refused step: Error, the model initialized
    after = serialize(stepped)
    assert header(after)["state"] == ERROR_STATE
    _, before = state_in(make, which, INSTANTIATED)
    relabelled = bytearray(before)
    relabelled[56:60] = ERROR_STATE.to_bytes(4, "little")
    for blob in (after, reseal(relabelled)):
        inst = make(which)
        state = inst.slave.deSerializeFMUstate(blob)
        inst.slave.setFMUstate(state)
        inst.slave.freeFMUstate(state)
        assert serialize(inst) == blob
        with pytest.raises(FMICallException):
            inst.slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)
        inst.slave.reset()


def marker_at(make, which: str) -> int:
    """Where the initialized marker is in a state: the one word that ending initialization
    changes (InitializationMode, brought up to date, against StepComplete)."""
    inst, during = state_in(make, which, INITIALIZATION_MODE)
    inst.slave.exitInitializationMode()
    after = serialize(inst)
    changed = [i for i in range(HEADER_SIZE, len(after)) if during[i] != after[i]]
    assert len(changed) == 1, changed  # 0 -> 1: one byte of a little-endian int32
    return changed[0]


@pytest.mark.parametrize("which", ["plant", "controller"])
def test_the_initialized_marker_edited_too_is_refused_by_the_model(make, which):
    """A model never initialized with its marker set as well (payload and header forged
    together): the model's own check_restored refuses it, before anything steps."""
    at = marker_at(make, which)
    inst, blob = state_in(make, which, INSTANTIATED)
    forged = bytearray(blob)
    assert forged[at:at + 4] == bytes(4)
    forged[at:at + 4] = (1).to_bytes(4, "little")
    forged[56:60] = STEP_COMPLETE.to_bytes(4, "little")
    refused(inst, reseal(forged), "the state is refused")
    said = " | ".join(logged(inst, "ERROR"))
    assert ("rotor count 6 (rotor set 0)" if which == "plant" else
            "rotor set of 0 rotors, the airframe has 6") in said
    with pytest.raises(FMICallException):
        inst.slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=H)


@pytest.mark.parametrize("edit", ["arm", "persist"])
def test_the_fault_detector_constants_of_a_restored_controller_are_checked(make, edit):
    """The detector (detect.c) divides by the rotors' mean arm squared and counts to
    `persist` before it indexes the rotor found: a state the controller accepts has the
    constants its parameters give.  Zeroed (as in a model never initialized) they are
    refused; before, arm 0 divided by zero and persist 0 wrote est[-1]."""
    inst = make("controller")
    inst.step(H)
    good = serialize(inst)
    pos = inst.read(inst.signal("rotor_pos")).reshape(-1, 3)[:int(inst.get("n_rotors"))]
    arm = float(np.mean(np.linalg.norm(pos, axis=1)))
    # detect_p: mass, inertia, g, Ts, arm, arm I^-1 (9), loss_min, fit_max, wrench_min, onset,
    # floor2, base_gain, probe_omega, persist, window
    tail = struct.pack("<dd", 0.1, 0.3)  # fault_loss_min, fault_fit_max (the defaults)
    found = [i for i in range(HEADER_SIZE, len(good) - 96)
             if good[i + 80:i + 96] == tail
             and struct.unpack_from("<d", good, i)[0] == pytest.approx(arm, rel=1e-12)]
    assert len(found) == 1, found
    at = found[0] if edit == "arm" else found[0] + 80 + 7 * 8  # arm, or persist
    assert struct.unpack_from("<d" if edit == "arm" else "<i", good, at)[0] > 0
    bad = bytearray(good)
    bad[at:at + (8 if edit == "arm" else 4)] = bytes(8 if edit == "arm" else 4)
    refused(inst, reseal(bad), "the fault detector's constants")
    assert serialize(inst) == good
    inst.step(H)


def test_a_resealed_corrupt_model_is_refused_by_the_model_on_an_aligned_copy(make):
    """The checksum is no proof of sense: the model's check_restored still runs, on the
    glue's aligned scratch copy, and the live model stays as it was."""
    inst = make("plant")
    inst.step(H)
    good = serialize(inst)
    assert int.from_bytes(good[HEADER_SIZE:HEADER_SIZE + 4], "little") == 6  # n_rotors
    bad = bytearray(good)
    bad[HEADER_SIZE:HEADER_SIZE + 4] = (40).to_bytes(4, "little")
    refused(inst, reseal(bad), "rotor count 40")
    assert serialize(inst) == good  # nothing of it reached the live model
    inst.step(H)  # and the instance is still usable


def history_indices_at(make) -> int:
    """Where the plant's measurement-delay ring indices (int32 hist_head, then hist_count)
    are in its state: after n steps they are n and n + 1 (one point per communication point,
    the initial one included); the one place where that holds for two n."""
    found = None
    for n in (3, 7):
        inst = make("plant")
        for _ in range(n):
            inst.step(H)
        blob = serialize(inst)
        here = {i for i in range(HEADER_SIZE, len(blob) - 8, 4)
                if struct.unpack_from("<ii", blob, i) == (n, n + 1)}
        found = here if found is None else found & here
    assert len(found) == 1, found
    return found.pop()


PLANT_HISTORY = 512  # fmu_src/plant/plant.h: communication points kept for mocap_delay


@pytest.mark.parametrize("field, value", [
    ("hist_head", -100000),  # issue 32: accepted, and the next step wrote hist[-159]
    ("hist_head", -1),
    ("hist_head", PLANT_HISTORY),
    ("hist_count", -1),
    ("hist_count", PLANT_HISTORY + 1),
    ("hist_count", 2**31 - 1),
])
def test_a_restored_plant_history_index_out_of_range_is_refused(make, field, value):
    """The plant's ring of past true poses (for mocap_delay) is addressed by hist_head and
    walked hist_count points back: a resealed state with either outside its array passes
    fmi2DeSerializeFMUstate (the header is sound) and is refused by fmi2SetFMUstate, whose
    model check (check_restored, on the glue's aligned copy) names the field; the instance
    that refuses it is as it was and still steps.  Before, hist_head = -100000 was taken and
    the next step wrote hist[-159] (UBSan, then a segfault)."""
    at = history_indices_at(make) + (0 if field == "hist_head" else 4)
    inst = make("plant", parameters={"mocap_delay": 0.004})  # the ring is read, too
    for _ in range(5):
        inst.step(H)
    good = serialize(inst)
    bad = bytearray(good)
    bad[at:at + 4] = struct.pack("<i", value)
    said = f"restored state: {field} = {value} is outside"
    refused(inst, reseal(bad), said)
    assert "fmi2SetFMUstate: the state is refused" in logged(inst, "ERROR")
    assert serialize(inst) == good  # nothing of it reached the live model
    for _ in range(3):
        inst.step(H)  # still usable


@pytest.mark.parametrize("head, count", [(0, 0), (PLANT_HISTORY - 1, PLANT_HISTORY)])
def test_a_restored_plant_history_at_its_bounds_is_accepted(make, head, count):
    """The bounds are the array's, no tighter: the first and last index, an empty and a
    full ring restore and step."""
    at = history_indices_at(make)
    inst = make("plant")
    inst.step(H)
    blob = bytearray(serialize(inst))
    blob[at:at + 8] = struct.pack("<ii", head, count)
    state = inst.slave.deSerializeFMUstate(reseal(blob))
    try:
        inst.slave.setFMUstate(state)
    finally:
        inst.slave.freeFMUstate(state)
    inst.step(H)
