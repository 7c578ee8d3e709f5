"""The FMI 3.0 co-simulation FMUs (issue 36): the same models and the same variable tables as
the FMI 2.0 ones, behind the FMI 3.0 glue (fmu_src/common/fmi3_*.c) and a modelDescription that
mdgen --fmi3 writes from the same table.

Where they are: ``<package>/fmus/fmi3/<Model>.fmu`` installed, ``$FULLPOSE_BUILD_DIR/fmi3/`` in
a CMake build (plant.common.artifacts).  What is checked here:

- fmpy's validator and fmusim's (``fmitools``) find nothing; both modelDescriptions state the
  same table (one FMI 3.0 variable per row at the row's value reference, its elements the FMI
  2.0 variables vr, vr + 1, ...);
- the binaries export every function fmi3Functions.h declares, and nothing else; what they do
  not provide answers fmi3Error naming the function;
- fmusim flies the plant at trim and steps the controller (``fmitools``);
- the FMI 3.0 plant under fmpy's simulate_fmu equals the FMI 2.0 one to the bit, and so does a
  closed loop of both FMUs under one small master;
- the call-sequence discipline: illegal calls, wrong nValues, NULL arrays, a bad parameter at
  fmi3ExitInitializationMode, each answered fmi3Error with a message naming what is wrong;
- FMU states: get/set and serialize round trips reproduce the next step to the bit.
"""

from __future__ import annotations

import ctypes
import os
import re
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave, fmi3LogMessageCallback
from fmpy.validation import validate_fmu, validate_model_description

from plant.common.artifacts import find_artifact

MODELS = {"MultirotorPlant": "plant", "FullPoseController": "controller",
          "ScenarioSignals": "orchestrator"}
H = 0.002
FMI3_OK, FMI3_ERROR = 0, 3


def fmu_path(model: str, fmi: int = 3) -> Path:
    """The built or installed FMU of ``model``: FMI 3.0 in ``fmus/fmi3/``, or FMI 2.0."""
    name = f"fmi3/{model}.fmu" if fmi == 3 else f"{model}.fmu"
    return find_artifact(MODELS[model], "fmus", name)


def signals_fmu3(tmp_path: Path) -> Path:
    """The FMI 3.0 ScenarioSignals FMU with a small table in its resources/."""
    from orchestrator.export.signals import SignalTable, signals_fmu_with

    table = SignalTable(("pos_ref[1]", "pos_ref[3]", "f_d[2]"), np.array([0.0, 0.5, 1.0]),
                        np.array([[0.0, -1.0, 0.1], [0.5, -1.5, 0.2], [1.0, -2.0, 0.3]]))
    out = tmp_path / "ScenarioSignals3.fmu"
    out.write_bytes(signals_fmu_with(table, fmu_path("ScenarioSignals")))
    return out


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


@contextmanager
def fmu3(path: Path, tmp_path: Path, name: str = "inst", *,
         initialize: bool = True) -> Iterator[tuple[FMU3Slave, Log, object]]:
    """An FMI 3.0 instance through fmpy (its calls raise on fmi3Error), its log and its model
    description; ``slave.dll`` has the raw entries, which return the status."""
    md = read_model_description(str(path))
    unzip = tmp_path / f"{name}_unzip"
    if not unzip.exists():
        extract(str(path), str(unzip))
    log = Log()
    slave = FMU3Slave(guid=md.guid, unzipDirectory=str(unzip),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    slave.instantiate(logMessage=log)
    try:
        if initialize:
            slave.enterInitializationMode(startTime=0.0)
            slave.exitInitializationMode()
        yield slave, log, md
    finally:
        slave.freeInstance()


def vrs(md) -> dict[str, int]:
    return {v.name: v.valueReference for v in md.modelVariables}


def size(md, name: str) -> int:
    v = next(v for v in md.modelVariables if v.name == name)
    return int(np.prod(v.shape)) if v.shape else 1


def raw_get_float64(slave: FMU3Slave, refs: list[int], n_values: int):
    """fmi3GetFloat64 called as it is: (status, values)."""
    vr = (ctypes.c_uint32 * len(refs))(*refs)
    values = (ctypes.c_double * max(n_values, 1))()
    status = slave.dll.fmi3GetFloat64(slave.component, vr, len(refs), values, n_values)
    return status, list(values)[:n_values]


def raw_set_float64(slave: FMU3Slave, refs: list[int], values: list[float], n_values=None):
    vr = (ctypes.c_uint32 * len(refs))(*refs)
    arr = (ctypes.c_double * max(len(values), 1))(*values)
    return slave.dll.fmi3SetFloat64(slave.component, vr, len(refs), arr,
                                    len(values) if n_values is None else n_values)


def do_step(slave: FMU3Slave, t: float, h: float = H) -> int:
    flags = [ctypes.c_bool() for _ in range(3)]
    last = ctypes.c_double()
    return slave.dll.fmi3DoStep(slave.component, t, h, True, ctypes.byref(flags[0]),
                                ctypes.byref(flags[1]), ctypes.byref(flags[2]),
                                ctypes.byref(last))


# ---------------------------------------------------------------------------------------------
# The archives and their modelDescriptions


@pytest.mark.parametrize("model", MODELS)
def test_fmpy_validator_finds_no_problem(model):
    path = fmu_path(model)
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    assert md.fmiVersion == "3.0"
    assert validate_model_description(md, validate_variable_names=True,
                                      validate_model_structure=True) == []


@pytest.mark.parametrize("model", MODELS)
def test_both_model_descriptions_state_the_same_table(model):
    """One FMI 3.0 variable per table row, at the value reference of its first element in FMI
    2.0, with the same causality, variability, start values, range and unit; the FMI 2.0
    GUID as instantiation token; time the only addition, at vr 0.  The controller's Scheduled
    Execution (test_fmi3_scheduled.py) adds its clock, which is no table row, and clocks its
    inputs and outputs: those are discrete (FMI 3.0 clocks no continuous variable) and, as
    clocked outputs, no initial unknowns.  The plant's Model Exchange rows (states, their
    derivatives, the contact depths) are local variables in both, each derivative naming its
    state, and its outputs have the same dependencies."""
    md3 = read_model_description(str(fmu_path(model)))
    md2 = read_model_description(str(fmu_path(model, fmi=2)))
    assert md3.guid == md2.guid and re.fullmatch(r"\{[0-9a-f-]{36}\}", md3.guid)
    cs = md3.coSimulation
    assert cs.modelIdentifier == model and cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    assert not cs.hasEventMode and not cs.providesIntermediateUpdate
    by_vr2 = {v.valueReference: v for v in md2.modelVariables}
    time = [v for v in md3.modelVariables if v.causality == "independent"]
    assert [(v.name, v.valueReference, v.type) for v in time] == [("time", 0, "Float64")]
    clocks = [v for v in md3.modelVariables if v.type == "Clock"]
    assert [c.name for c in clocks] == (["sample"] if model == "FullPoseController" else [])
    n_elements = 0
    for v in md3.modelVariables:
        if v is time[0] or v in clocks:
            continue
        n = int(np.prod(v.shape)) if v.shape else 1
        n_elements += n
        elements = [by_vr2[v.valueReference + k] for k in range(n)]
        names = [e.name for e in elements]
        if not v.shape:
            assert names == [v.name]
        else:
            assert all(re.fullmatch(rf"{re.escape(v.name)}\[[\d,]+\]", x) for x in names)
            if len(v.shape) == 2:  # row-major: [1,1], [1,2], ...
                assert names[1] == f"{v.name}[1,2]"
        clocked = "discrete" if v.clocks else None  # in the clock's partition
        assert {(e.causality, clocked or e.variability) for e in elements} == \
            {(v.causality, v.variability)}
        assert {e.type for e in elements} == {
            {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean"}[v.type]}
        if v.causality not in ("output", "local"):
            starts = v.start.split() if v.shape else [v.start]
            assert starts == [e.start for e in elements], v.name
        if v.derivative is not None:  # the state array, element by element in FMI 2.0
            assert [e.derivative.valueReference for e in elements] == [
                v.derivative.valueReference + k for k in range(n)]
        assert {(e.min, e.max) for e in elements} == {(v.min, v.max)}, v.name
        if v.type == "Float64" and v.declaredType is not None:
            assert {e.declaredType.name for e in elements} == {v.declaredType.name}
            assert {e.unit for e in elements} == {v.unit}
        elif v.type == "Float64":  # a wrench: force then torque
            assert [e.declaredType.name for e in elements] == ["Force"] * 3 + ["Torque"] * 3
            assert "unit N for elements 1-3, N.m for elements 4-6" in v.description
    assert n_elements == len(md2.modelVariables)
    # the same outputs and initial dependencies, by variable instead of by element
    outputs3 = [u.variable.valueReference for u in md3.outputs]
    assert outputs3 == [v.valueReference for v in md3.modelVariables if v.causality == "output"]
    rows2 = {}
    for v in md2.modelVariables:
        rows2.setdefault(v.name.split("[")[0], v.valueReference)
    row_of = {v.valueReference: rows2[v.name.split("[")[0]] for v in md2.modelVariables}
    deps2 = {row_of[u.variable.valueReference]:
             sorted({row_of[d.valueReference] for d in u.dependencies})
             for u in md2.initialUnknowns}
    deps3 = {u.variable.valueReference: sorted(d.valueReference for d in u.dependencies)
             for u in md3.initialUnknowns}
    assert deps3 == ({} if clocks else deps2)
    out2 = {row_of[u.variable.valueReference]: sorted({row_of[d.valueReference]
                                                       for d in u.dependencies})
            for u in md2.outputs}
    out3 = {u.variable.valueReference: sorted(d.valueReference for d in u.dependencies)
            for u in md3.outputs}
    assert out3 == out2
    assert [d.variable.valueReference for d in md3.derivatives] == sorted(
        {row_of[d.variable.valueReference] for d in md2.derivatives})


@pytest.mark.parametrize("model", MODELS)
def test_sources_hold_the_fmi3_glue_and_headers(model):
    import zipfile

    with zipfile.ZipFile(fmu_path(model)) as z:
        names = set(z.namelist())
        build = z.read("sources/buildDescription.xml").decode()
        unity = z.read(f"sources/{model}_all.c").decode()
    for f in ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h", "fmi3_glue.c",
              "fmi3_values.c", "fmi3_fmustate.c", "fmi3_resources.c", "fmu_state.c"):
        assert f"sources/{f}" in names
    assert not [n for n in names if "fmi2" in n]
    assert any(n.startswith("binaries/x86_64-linux/") for n in names)
    assert '<fmiBuildDescription fmiVersion="3.0">' in build
    assert f'<SourceFile name="{model}_all.c"/>' in build
    assert "FMI3_FUNCTION_PREFIX" in unity and '#include "fmi3_glue.c"' in unity


def fmi3_functions(unzip: Path) -> list[str]:
    header = (unzip / "sources" / "fmi3Functions.h").read_text()
    return re.findall(r"^FMI3_Export\s+fmi3\w+TYPE\s+(fmi3\w+);", header, re.M)


@pytest.mark.parametrize("model", MODELS)
def test_every_fmi3_function_is_exported_and_nothing_else(model, tmp_path):
    """Importers look up every function of the header: all of them are there (75), and the
    binary exports nothing but them."""
    extract(str(fmu_path(model)), str(tmp_path))
    names = fmi3_functions(tmp_path)
    assert len(names) == 75 and "fmi3DoStep" in names and "fmi3InstantiateModelExchange" in names
    binary = tmp_path / "binaries" / "x86_64-linux" / f"{model}.so"
    lib = ctypes.CDLL(str(binary))
    assert [n for n in names if not hasattr(lib, n)] == []
    nm = shutil.which("nm")
    if nm:
        out = subprocess.run([nm, "-D", "--defined-only", str(binary)], capture_output=True,
                             text=True, check=True).stdout
        exported = sorted(line.split()[-1] for line in out.splitlines()
                          if line.split()[-2:-1] == ["T"])
        assert exported == sorted(names)


@pytest.mark.heavy
@pytest.mark.parametrize("prefix", [None, "MultirotorPlant_"])
def test_sources_build_alone_and_fly_as_the_shipped_binary(prefix, tmp_path):
    """The plant's sources/ compiled by the one-line command (all warnings on, none given),
    the binary exporting the 75 functions and flying 0.2 s as the shipped one, to the bit;
    with FMI3_FUNCTION_PREFIX, an object whose every global symbol carries the prefix."""
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    unzip = tmp_path / "u"
    extract(str(fmu_path("MultirotorPlant")), str(unzip))
    src = unzip / "sources"
    flags = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Wstrict-prototypes",
             "-I", str(src), str(src / "MultirotorPlant_all.c")]
    if prefix is not None:
        obj = tmp_path / "p.o"
        run = subprocess.run([cc, "-c", f"-DFMI3_FUNCTION_PREFIX={prefix}", *flags, "-o",
                              str(obj)], capture_output=True, text=True)
        assert run.returncode == 0 and run.stderr == "", run.stderr
        nm = shutil.which("nm")
        if nm is None:
            pytest.skip("no nm")
        out = subprocess.run([nm, "--defined-only", str(obj)], capture_output=True, text=True,
                             check=True).stdout
        globals_ = [line.split()[-1] for line in out.splitlines()
                    if line.split()[1:2] and line.split()[1] in "TDBR"]
        assert len(globals_) > 75 and [g for g in globals_ if not g.startswith(prefix)] == []
        return
    binary = unzip / "binaries" / "x86_64-linux" / "MultirotorPlant.so"
    shipped = tmp_path / "shipped"
    extract(str(fmu_path("MultirotorPlant")), str(shipped))
    run = subprocess.run([cc, "-shared", "-fPIC", *flags, "-lm", "-o", str(binary)],
                         capture_output=True, text=True)
    assert run.returncode == 0 and run.stderr == "", run.stderr
    assert fmi3_functions(unzip) == fmi3_functions(shipped)
    tracks = []
    for folder in (unzip, shipped):
        md = read_model_description(str(fmu_path("MultirotorPlant")))
        s = FMU3Slave(guid=md.guid, unzipDirectory=str(folder),
                      modelIdentifier="MultirotorPlant", instanceName=folder.name)
        s.instantiate()
        try:
            s.enterInitializationMode(startTime=0.0)
            s.setFloat64([126], [0.05, -0.03, 0.2])  # euler0: a tilted start
            s.exitInitializationMode()
            track = []
            for k in range(100):
                s.doStep(k * H, H)
                track += s.getFloat64([300, 309], 6)
            tracks.append(np.array(track))
        finally:
            s.freeInstance()
    assert tracks[0].tobytes() == tracks[1].tobytes()


# ---------------------------------------------------------------------------------------------
# What is not provided, and the call-sequence discipline


def test_unprovided_functions_answer_error_naming_themselves(tmp_path):
    with fmu3(fmu_path("MultirotorPlant"), tmp_path) as (slave, log, _md):
        c = slave.component
        dll = slave.dll
        null = None
        calls = {
            "fmi3EnterEventMode": lambda: dll.fmi3EnterEventMode(c),
            "fmi3EnterStepMode": lambda: dll.fmi3EnterStepMode(c),
            "fmi3UpdateDiscreteStates":
                lambda: dll.fmi3UpdateDiscreteStates(c, null, null, null, null, null, null),
            "fmi3EvaluateDiscreteStates": lambda: dll.fmi3EvaluateDiscreteStates(c),
            "fmi3GetDirectionalDerivative":
                lambda: dll.fmi3GetDirectionalDerivative(c, null, 0, null, 0, null, 0, null, 0),
            "fmi3GetAdjointDerivative":
                lambda: dll.fmi3GetAdjointDerivative(c, null, 0, null, 0, null, 0, null, 0),
            "fmi3EnterConfigurationMode": lambda: dll.fmi3EnterConfigurationMode(c),
            "fmi3ExitConfigurationMode": lambda: dll.fmi3ExitConfigurationMode(c),
            "fmi3GetNumberOfVariableDependencies":
                lambda: dll.fmi3GetNumberOfVariableDependencies(c, 300, null),
            "fmi3SetTime": lambda: dll.fmi3SetTime(c, 0.0),
            "fmi3GetNumberOfContinuousStates":
                lambda: dll.fmi3GetNumberOfContinuousStates(c, null),
            "fmi3ActivateModelPartition": lambda: dll.fmi3ActivateModelPartition(c, 1, 0.0),
            "fmi3GetIntervalDecimal": lambda: dll.fmi3GetIntervalDecimal(c, null, 0, null, null),
        }
        # (the plant provides Model Exchange: its functions name the interface this instance
        # has, the Event Mode ones answer as without Model Exchange: test_model_exchange.py)
        me_only = {"fmi3SetTime", "fmi3GetNumberOfContinuousStates"}
        for name, call in calls.items():
            log.lines.clear()
            assert call() == FMI3_ERROR, name
            said = (f"{name}: the instance was instantiated for co-simulation" if name in me_only
                    else f"{name}: not provided")
            assert any(m.startswith(said) for m in log.errors()), name
        # no variable of the other types; a clock call naming one is refused
        vr = (ctypes.c_uint32 * 1)(2)
        val = (ctypes.c_float * 1)()
        log.lines.clear()
        assert dll.fmi3GetFloat32(c, vr, 1, val, 1) == FMI3_ERROR
        assert "fmi3GetFloat32: variable mass (vr 2) is of type Float64; the FMU has no " \
               "Float32 variables" in log.errors()
        # the instance still steps: none of these changed its state
        assert do_step(slave, 0.0) == FMI3_OK


def test_model_exchange_in_the_plant_only_scheduled_execution_and_event_mode_refused(tmp_path):
    path = fmu_path("MultirotorPlant")
    md = read_model_description(str(path))
    extract(str(path), str(tmp_path))
    lib = ctypes.CDLL(str(tmp_path / "binaries" / "x86_64-linux" / "MultirotorPlant.so"))
    log = Log()
    cb = fmi3LogMessageCallback(log)
    res = str(tmp_path / "resources") + "/"
    lib.fmi3InstantiateModelExchange.restype = ctypes.c_void_p
    lib.fmi3InstantiateModelExchange.argtypes = [ctypes.c_char_p] * 3 + [ctypes.c_bool] * 2 + [
        ctypes.c_void_p, fmi3LogMessageCallback]
    # the plant provides Model Exchange (test_model_exchange.py), the player does not
    me = lib.fmi3InstantiateModelExchange(b"me", md.guid.encode(), res.encode(), False, False,
                                          None, cb)
    assert me
    lib.fmi3FreeInstance.argtypes = [ctypes.c_void_p]
    lib.fmi3FreeInstance(me)
    player = fmu_path("ScenarioSignals")
    extract(str(player), str(tmp_path / "player"))
    plib = ctypes.CDLL(str(tmp_path / "player" / "binaries" / "x86_64-linux" /
                           "ScenarioSignals.so"))
    plib.fmi3InstantiateModelExchange.restype = ctypes.c_void_p
    plib.fmi3InstantiateModelExchange.argtypes = lib.fmi3InstantiateModelExchange.argtypes
    assert plib.fmi3InstantiateModelExchange(b"me", md.guid.encode(), res.encode(), False, False,
                                             None, cb) is None
    assert "fmi3InstantiateModelExchange: ScenarioSignals provides co-simulation only" in \
        log.text()
    lib.fmi3InstantiateScheduledExecution.restype = ctypes.c_void_p
    lib.fmi3InstantiateScheduledExecution.argtypes = [ctypes.c_char_p] * 3 + [
        ctypes.c_bool] * 2 + [ctypes.c_void_p, fmi3LogMessageCallback] + [ctypes.c_void_p] * 3
    assert lib.fmi3InstantiateScheduledExecution(b"se", md.guid.encode(), res.encode(), False,
                                                 False, None, cb, None, None, None) is None
    assert "fmi3InstantiateScheduledExecution: MultirotorPlant provides co-simulation only" in \
        log.text()
    inst = lib.fmi3InstantiateCoSimulation
    inst.restype = ctypes.c_void_p
    inst.argtypes = [ctypes.c_char_p] * 3 + [ctypes.c_bool] * 4 + [
        ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, fmi3LogMessageCallback,
        ctypes.c_void_p]
    log.lines.clear()
    assert inst(b"cs", md.guid.encode(), res.encode(), False, False, True, False, None, 0, None,
                cb, None) is None
    assert "eventModeUsed = true, but MultirotorPlant has no Event Mode" in log.text()
    log.lines.clear()
    assert inst(b"cs", b"{00000000-0000-0000-0000-000000000000}", res.encode(), False, False,
                False, False, None, 0, None, cb, None) is None
    assert "instantiationToken {00000000-0000-0000-0000-000000000000} does not match" in \
        log.text()
    ok = inst(b"cs", md.guid.encode(), res.encode(), False, False, False, True, None, 0, None,
              cb, None)
    assert ok  # earlyReturnAllowed = true: accepted (the FMU never returns early)
    lib.fmi3FreeInstance.argtypes = [ctypes.c_void_p]
    lib.fmi3FreeInstance(ok)


def test_illegal_calls_are_errors_naming_function_and_variable(tmp_path):
    with fmu3(fmu_path("MultirotorPlant"), tmp_path, initialize=False) as (slave, log, md):
        ref = vrs(md)
        # DoStep before initialization
        assert do_step(slave, 0.0) == FMI3_ERROR
        assert "fmi3DoStep may not be called in state Instantiated" in log.errors()
        # Get before Initialization Mode
        status, _ = raw_get_float64(slave, [ref["pos"]], 3)
        assert status == FMI3_ERROR
        assert "fmi3GetFloat64 may not be called in state Instantiated" in log.errors()
        slave.enterInitializationMode(startTime=0.0)
        # an output cannot be set; nothing of the call is written
        log.lines.clear()
        mass = raw_get_float64(slave, [ref["mass"]], 1)[1]
        assert raw_set_float64(slave, [ref["mass"], ref["pos"]], [9.0, 1, 2, 3]) == FMI3_ERROR
        assert "fmi3SetFloat64: cannot set pos (vr 300): it is an output" in log.errors()
        assert raw_get_float64(slave, [ref["mass"]], 1)[1] == mass
        # nValues must be the sum of the variables' sizes
        log.lines.clear()
        status, _ = raw_get_float64(slave, [ref["pos0"], ref["mass"]], 3)
        assert status == FMI3_ERROR
        assert log.errors() == ["fmi3GetFloat64: nValues = 3, but the 2 variable(s) hold 4 "
                                "value(s) (pos0 3, mass 1)"]
        assert raw_set_float64(slave, [ref["pos0"]], [1.0, 2.0]) == FMI3_ERROR
        assert "fmi3SetFloat64: nValues = 2, but the 1 variable(s) hold 3 value(s) (pos0 3)" in \
            log.errors()
        # NULL arrays
        log.lines.clear()
        assert slave.dll.fmi3GetFloat64(slave.component, None, 1, None, 1) == FMI3_ERROR
        assert "fmi3GetFloat64: valueReferences (nValueReferences = 1) is NULL" in log.errors()
        vr = (ctypes.c_uint32 * 1)(ref["pos"])
        assert slave.dll.fmi3GetFloat64(slave.component, vr, 1, None, 3) == FMI3_ERROR
        assert "fmi3GetFloat64: values (nValues = 3) is NULL" in log.errors()
        # an element reference of the FMI 2.0 numbering, a type mismatch, time
        log.lines.clear()
        assert raw_get_float64(slave, [ref["pos"] + 1], 1)[0] == FMI3_ERROR
        assert ("fmi3GetFloat64: unknown value reference 301: it numbers element 2 of pos in "
                "the FMI 2.0 FMU; in FMI 3.0 pos is one variable of 3 values, value reference "
                "300") in log.errors()
        assert raw_get_float64(slave, [ref["n_rotors"]], 1)[0] == FMI3_ERROR
        assert "fmi3GetFloat64: variable n_rotors (vr 1) is of type Int32" in log.errors()
        assert raw_set_float64(slave, [0], [1.0]) == FMI3_ERROR
        assert "fmi3SetFloat64: cannot set time (vr 0): it is the independent variable" in \
            log.errors()
        slave.exitInitializationMode()
        # a fixed parameter after initialization
        log.lines.clear()
        assert raw_set_float64(slave, [ref["mass"]], [2.0]) == FMI3_ERROR
        assert ("fmi3SetFloat64: cannot set mass (vr 2): it is a fixed parameter and "
                "initialization has ended") in log.errors()
        # DoStep's output arguments may not be NULL; the time must match
        log.lines.clear()
        assert slave.dll.fmi3DoStep(slave.component, 0.0, H, True, None, None, None,
                                    None) == FMI3_ERROR
        assert "fmi3DoStep: eventHandlingNeeded is NULL" in log.errors()
        assert do_step(slave, 0.0) == FMI3_OK
        assert raw_get_float64(slave, [0], 1) == (FMI3_OK, [H])
        assert slave.dll.fmi3Terminate(slave.component) == FMI3_OK
        assert do_step(slave, H) == FMI3_ERROR
        assert "fmi3DoStep may not be called in state Terminated" in log.errors()


def test_boolean_and_int32_arrays(tmp_path):
    """fmi3Boolean is one byte: a Boolean array read and written as bools; Int32 arrays."""
    with fmu3(fmu_path("MultirotorPlant"), tmp_path, initialize=False) as (slave, _log, md):
        ref = vrs(md)
        slave.enterInitializationMode(startTime=0.0)
        assert slave.getBoolean([ref["init_trim"], ref["timing"]]) == [True, False]
        slave.setBoolean([ref["timing"], ref["init_trim"]], [False, True])
        # the XML's start values, element by element, then a scalar after the array
        assert slave.getInt32([ref["rotor_dir"], ref["n_rotors"]], 9) == [1, -1, 1, -1, 1, -1,
                                                                           1, 1, 6]
        slave.setInt32([ref["rotor_dir"]], [-1, 1, -1, 1, -1, 1, 1, 1])
        assert slave.getInt32([ref["rotor_dir"]], 8)[:6] == [-1, 1, -1, 1, -1, 1]
        slave.exitInitializationMode()
        assert slave.getBoolean([ref["landed"], ref["init_trim"]], 2) == [False, True]
        # a Boolean array of bytes: one byte per value, no neighbour overwritten
        buf = (ctypes.c_uint8 * 4)(0xAA, 0xAA, 0xAA, 0xAA)
        vr = (ctypes.c_uint32 * 2)(ref["landed"], ref["init_trim"])
        assert slave.dll.fmi3GetBoolean(slave.component, vr, 2,
                                        ctypes.cast(buf, ctypes.POINTER(ctypes.c_bool)),
                                        2) == FMI3_OK
        assert list(buf) == [0, 1, 0xAA, 0xAA]


def test_a_bad_parameter_is_refused_at_exit_initialization_naming_it(tmp_path):
    with fmu3(fmu_path("MultirotorPlant"), tmp_path, initialize=False) as (slave, log, md):
        ref = vrs(md)
        slave.setFloat64([ref["mass"]], [-1.0])
        slave.enterInitializationMode(startTime=0.0)
        assert slave.dll.fmi3ExitInitializationMode(slave.component) == FMI3_ERROR
        assert any("mass" in m and "-1" in m for m in log.errors()), log.errors()
        assert do_step(slave, 0.0) == FMI3_ERROR
        assert "fmi3DoStep may not be called in state Error" in log.errors()
        # reset brings it back to the defaults
        assert slave.dll.fmi3Reset(slave.component) == FMI3_OK
        slave.enterInitializationMode(startTime=0.0)
        slave.exitInitializationMode()
        assert do_step(slave, 0.0) == FMI3_OK


# ---------------------------------------------------------------------------------------------
# FMU states


def outputs(slave: FMU3Slave, md) -> np.ndarray:
    refs = [v.valueReference for v in md.modelVariables
            if v.causality == "output" and v.type == "Float64" and v.name != "t_step"]
    n = sum(size(md, v.name) for v in md.modelVariables if v.valueReference in refs)
    return np.array(slave.getFloat64(refs, n))


@pytest.mark.parametrize("model", ["MultirotorPlant", "FullPoseController"])
def test_fmu_state_round_trips_reproduce_the_next_step(model, tmp_path):
    with fmu3(fmu_path(model), tmp_path) as (slave, _log, md):
        t = 0.0
        for _ in range(50):
            assert do_step(slave, t) == FMI3_OK
            t += H
        state = slave.getFMUState()
        blob = slave.serializeFMUState(state)
        assert do_step(slave, t) == FMI3_OK
        after = outputs(slave, md)
        slave.setFMUState(state)
        assert raw_get_float64(slave, [0], 1)[1] == [t]
        assert do_step(slave, t) == FMI3_OK
        assert outputs(slave, md).tobytes() == after.tobytes()
        slave.freeFMUState(state)
        # a deserialized state, in another instance
        with fmu3(fmu_path(model), tmp_path, name="other") as (other, _, _):
            restored = other.deserializeFMUState(blob)
            other.setFMUState(restored)
            assert do_step(other, t) == FMI3_OK
            assert outputs(other, md).tobytes() == after.tobytes()
            other.freeFMUState(restored)


def test_an_fmi2_state_restores_in_the_fmi3_fmu(tmp_path):
    """The instantiation token is the FMI 2.0 GUID and the state format is shared: a state
    serialized by the FMI 2.0 plant continues in the FMI 3.0 one, to the bit."""
    md2 = read_model_description(str(fmu_path("MultirotorPlant", fmi=2)))
    unzip2 = tmp_path / "fmi2"
    extract(str(fmu_path("MultirotorPlant", fmi=2)), str(unzip2))
    s2 = FMU2Slave(guid=md2.guid, unzipDirectory=str(unzip2),
                   modelIdentifier="MultirotorPlant", instanceName="p2")
    s2.instantiate()
    try:
        s2.setupExperiment(startTime=0.0)
        s2.enterInitializationMode()
        s2.exitInitializationMode()
        for k in range(20):
            s2.doStep(k * H, H)
        blob = s2.serializeFMUstate(s2.getFMUstate())
        s2.doStep(20 * H, H)
        pos2 = s2.getReal([300, 301, 302])
    finally:
        s2.terminate()
        s2.freeInstance()
    with fmu3(fmu_path("MultirotorPlant"), tmp_path) as (slave, _log, _md):
        slave.setFMUState(slave.deserializeFMUState(blob))
        assert do_step(slave, 20 * H) == FMI3_OK
        assert slave.getFloat64([300], 3) == pos2


# ---------------------------------------------------------------------------------------------
# Simulation: FMI 3.0 equals FMI 2.0 to the bit


def test_simulate_fmu_plant_fmi3_equals_fmi2():
    """fmpy's simulate_fmu on both plants, from a tilted, pushed start: every recorded value
    is the same double."""
    pos0, euler0, f_d = [0.1, -0.2, -1.0], [0.05, -0.03, 0.2], [0.3, -0.1, 0.2]
    common = dict(stop_time=1.0, step_size=H, output_interval=H)
    r3 = simulate_fmu(str(fmu_path("MultirotorPlant")), **common,
                      start_values={"pos0": pos0, "euler0": euler0, "f_d": f_d},
                      output=["pos", "euler", "omega", "acc"])
    start2 = {f"{n}[{i + 1}]": v for n, vals in (("pos0", pos0), ("euler0", euler0),
                                                 ("f_d", f_d)) for i, v in enumerate(vals)}
    names = {"pos": 3, "euler": 3, "omega": 8, "acc": 3}
    r2 = simulate_fmu(str(fmu_path("MultirotorPlant", fmi=2)), **common, start_values=start2,
                      output=[f"{n}[{i + 1}]" for n, k in names.items() for i in range(k)])
    assert len(r3) == len(r2) == 501
    assert r3["time"].tobytes() == r2["time"].tobytes()
    for n, k in names.items():
        a3 = np.asarray(r3[n], dtype=float).reshape(len(r3), k)
        a2 = np.column_stack([r2[f"{n}[{i + 1}]"] for i in range(k)])
        assert a3.tobytes() == a2.tobytes(), n
    # it moved: the push and the tilt act
    assert np.abs(np.asarray(r3["pos"])[-1] - pos0).max() > 0.01


class Pair:
    """The plant and the controller under one small master: Gauss-Seidel at H, the controller
    reading the plant's outputs of its inputs' names, the plant its commands; the same logic
    for both FMI versions, FMI 2.0 by element references, FMI 3.0 by whole variables."""

    def __init__(self, fmi: int, tmp_path: Path, pos0, pos_ref):
        self.fmi = fmi
        self.slaves = {}
        self.mds = {}
        for role, model in (("plant", "MultirotorPlant"), ("ctrl", "FullPoseController")):
            path = fmu_path(model, fmi=fmi)
            md = read_model_description(str(path))
            unzip = tmp_path / f"{role}{fmi}"
            extract(str(path), str(unzip))
            cls = FMU3Slave if fmi == 3 else FMU2Slave
            s = cls(guid=md.guid, unzipDirectory=str(unzip), modelIdentifier=model,
                    instanceName=role)
            s.instantiate()
            self.slaves[role], self.mds[role] = s, md
        self.rows = {role: self._rows(md) for role, md in self.mds.items()}
        p_out = {n for n, (c, _) in self.rows["plant"].items() if c == "output"}
        c_out = {n for n, (c, _) in self.rows["ctrl"].items() if c == "output"}
        self.measured = [n for n, (c, _) in self.rows["ctrl"].items()
                         if c == "input" and n in p_out]
        self.commands = [n for n, (c, _) in self.rows["plant"].items()
                         if c == "input" and n in c_out]
        plant, ctrl = self.slaves["plant"], self.slaves["ctrl"]
        self._start(plant)
        self.set("plant", "pos0", pos0)
        self._end_init(plant)
        self._start(ctrl)
        for n in self.measured:
            self.set("ctrl", n, self.get("plant", n))
        self.set("ctrl", "pos_ref", pos_ref)
        self._end_init(ctrl)
        self.t = 0.0

    @staticmethod
    def _rows(md) -> dict[str, tuple[str, list[int]]]:
        """Real rows: name -> (causality, value references to read or write them)."""
        rows: dict[str, tuple[str, list[int]]] = {}
        for v in md.modelVariables:
            if v.type not in ("Real", "Float64") or v.causality == "independent":
                continue
            base = v.name.split("[")[0]
            rows.setdefault(base, (v.causality, []))[1].append(v.valueReference)
        return rows

    def _start(self, s) -> None:
        if self.fmi == 2:
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
        else:
            s.enterInitializationMode(startTime=0.0)

    @staticmethod
    def _end_init(s) -> None:
        s.exitInitializationMode()

    def get(self, role: str, name: str) -> list[float]:
        s, md = self.slaves[role], self.mds[role]
        refs = self.rows[role][name][1]
        if self.fmi == 2:
            return s.getReal(refs)
        return s.getFloat64(refs, size(md, name))

    def set(self, role: str, name: str, values) -> None:
        s = self.slaves[role]
        refs = self.rows[role][name][1]
        if self.fmi == 2:
            s.setReal(refs, list(values))
        else:
            s.setFloat64(refs, list(values))

    def step(self) -> None:
        for n in self.measured:
            self.set("ctrl", n, self.get("plant", n))
        self.slaves["ctrl"].doStep(self.t, H)
        for n in self.commands:
            self.set("plant", n, self.get("ctrl", n))
        self.slaves["plant"].doStep(self.t, H)
        self.t += H

    def close(self) -> None:
        for s in self.slaves.values():
            s.terminate()
            s.freeInstance()


def test_closed_loop_fmi3_pair_equals_fmi2_pair(tmp_path):
    """2 s of hover 0.2 m beside the start, both FMI versions under the same master: the
    position is bit-identical at every step."""
    pos0, pos_ref = [0.0, 0.0, -3.0], [0.2, 0.0, -3.0]
    tracks = {}
    for fmi in (2, 3):
        pair = Pair(fmi, tmp_path, pos0, pos_ref)
        try:
            assert len(pair.measured) >= 5 and {"omega_cmd", "alpha_cmd"} <= set(pair.commands)
            track = []
            for _ in range(1000):
                pair.step()
                track.append(pair.get("plant", "pos"))
            tracks[fmi] = np.array(track)
        finally:
            pair.close()
    assert tracks[3].tobytes() == tracks[2].tobytes()
    assert abs(tracks[3][-1, 0] - 0.2) < 0.05  # it flew to the reference


def test_signals_fmu3_plays_its_table(tmp_path):
    """The ScenarioSignals FMU reads its table from the native resourcePath."""
    with fmu3(signals_fmu3(tmp_path), tmp_path) as (slave, _log, md):
        ref = vrs(md)
        assert slave.getFloat64([ref["pos_ref"]], 3) == [0.0, 0.0, -1.0]
        t = 0.0
        for _ in range(250):
            assert do_step(slave, t) == FMI3_OK
            t += H
        assert slave.getFloat64([ref["pos_ref"], ref["f_d"]], 6) == [0.5, 0.0, -1.5,
                                                                     0.0, 0.2, 0.0]
        assert slave.getInt32([ref["row"]]) == [2]


def test_signals_fmu3_without_table_refuses_to_instantiate(tmp_path):
    path = fmu_path("ScenarioSignals")
    md = read_model_description(str(path))
    extract(str(path), str(tmp_path / "u"))
    log = Log()
    s = FMU3Slave(guid=md.guid, unzipDirectory=str(tmp_path / "u"),
                  modelIdentifier="ScenarioSignals", instanceName="sig")
    with pytest.raises(Exception, match="Failed to instantiate"):
        s.instantiate(logMessage=log)
    assert "ScenarioSignals cannot open its table" in log.text()
    assert "resources/signals.fptable is missing" in log.text()


# ---------------------------------------------------------------------------------------------
# fmusim (FMI 3.0 capable), as tests/test_fmus/test_fmi_tools.py runs it on the FMI 2.0 FMUs


# the paper airframe's documented warning (docs/airframes.md), as test_fmi_tools.py allows it
KNOWN_WARNING = re.compile(r"parameter inertia: principal moment .* which no rigid body has")


def fmusim(*args: str) -> str:
    """fmusim from FULLPOSE_FMI_TOOLS (tests/tools/fmi_tools.sh), else skip."""
    folder = os.environ.get("FULLPOSE_FMI_TOOLS")
    exe = Path(folder) / "bin" / "fmusim" if folder else None
    if exe is None or not os.access(exe, os.X_OK):
        found = shutil.which("fmusim")
        if found is None:
            pytest.skip("fmusim not found (set FULLPOSE_FMI_TOOLS to the folder holding "
                        "bin/fmusim; tests/tools/fmi_tools.sh builds it)")
        exe = Path(found)
    run = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=300)
    text = run.stdout + run.stderr
    print(text[-1500:])
    assert run.returncode == 0, text[-2000:]
    return text


@pytest.mark.fmitools
@pytest.mark.parametrize("model", MODELS)
def test_fmusim_validates_the_fmi3_archive(model, tmp_path):
    path = signals_fmu3(tmp_path) if model == "ScenarioSignals" else fmu_path(model)
    text = fmusim("validate", str(path))
    assert "Validating model description" in text
    assert "Validating build description" in text


def fmusim_array(col: dict[str, int], values: list[list[str]], name: str) -> np.ndarray:
    """An array column of fmusim's CSV ("x y z" per row) as rows of floats."""
    return np.array([[float(x) for x in row[col[name]].split()] for row in values])


def fmusim_simulate(path: Path, stop: float, out: Path) -> tuple[dict[str, int], list]:
    import csv

    text = fmusim("simulate", "--interface-type", "cs", "--stop-time", str(stop),
                        "--output-interval", str(H), "--output-file", str(out),
                        "--logging-on", str(path))
    warnings = [line for line in text.splitlines()
                if line.startswith(("[WARNING]", "[ERROR]", "[FATAL]"))]
    assert [w for w in warnings if not KNOWN_WARNING.search(w)] == []
    with out.open() as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = list(reader)
    assert len(rows) == round(stop / H) + 1
    return {name.strip('"'): i for i, name in enumerate(header)}, rows


@pytest.mark.fmitools
def test_fmusim_flies_the_fmi3_plant_at_hover(tmp_path):
    col, rows = fmusim_simulate(fmu_path("MultirotorPlant"), 10.0, tmp_path / "plant.csv")
    pos = fmusim_array(col, rows, "pos")
    assert pos.shape == (5001, 3) and np.isfinite(pos).all()
    assert float(rows[-1][col["time"]]) == pytest.approx(10.0)
    assert np.abs(pos - pos[0]).max() < 1e-6


@pytest.mark.fmitools
def test_fmusim_steps_the_fmi3_controller_alone(tmp_path):
    col, rows = fmusim_simulate(fmu_path("FullPoseController"), 2.0, tmp_path / "ctrl.csv")
    omega = fmusim_array(col, rows, "omega_cmd")[:, :6]
    assert np.isfinite(omega).all()
    assert np.ptp(omega, axis=0).max() < 1e-6 * omega.max()
