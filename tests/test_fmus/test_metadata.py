"""The metadata importers show (issue 14, item 5), checked against oracles nobody here wrote
and against the FMUs' own behaviour.

- fmpy's validator (the FMI 2.0 XML schema it bundles, and its model checks) accepts both
  modelDescriptions;
- every Real has a unit and a quantity (directly or through its declaredType), every unit
  and type it names is defined, nominals sit at the scale of the values they describe;
- the header names author, version (pyproject's), copyright, license (pyproject's),
  generationTool and a generationDateAndTime that no clock enters (the shipped XML equals a
  fresh mdgen run at another time; SOURCE_DATE_EPOCH is honoured);
- every declared min/max is the FMU's own check: a value just outside it, set through
  fmi2SetReal/fmi2SetInteger, is refused (or, for the controller's inputs while stepping,
  warned about and held) with a message naming the variable; a value just inside it is
  accepted without a word about that variable; the bound itself is accepted, also where the
  description says the range is open (an open bound is declared at the first value inside
  it: tests/test_fmus/test_declared_bounds.py);
- start values lie within [min, max];
- logCalls messages carry the arguments; a warning of the parameter checks is logged once
  per initialization.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from orchestrator.sim.fmu import FmuError, FmuInstance, installed_fmu

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "fmu_src"
MODELS = ("MultirotorPlant", "FullPoseController")
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
H = 0.002


def xml_of(model: str) -> bytes:
    with zipfile.ZipFile(installed_fmu(model)) as z:
        return z.read("modelDescription.xml")


@pytest.fixture(scope="module", params=MODELS)
def model(request) -> str:
    return request.param


@pytest.fixture(scope="module")
def root(model) -> ET.Element:
    return ET.fromstring(xml_of(model))


# ---------------------------------------------------------------------------
# the XML


@pytest.mark.heavy  # (fmpy's schema validation: 2.3 s for the controller's ~1,500 variables)
def test_fmpy_validates_the_fmu_against_the_fmi2_schema(model):
    assert validate_fmu(str(installed_fmu(model))) == []


def test_every_real_has_a_defined_unit_and_a_quantity(root):
    units = {u.get("name") for u in root.iter("Unit")}
    types = {t.get("name"): t.find("Real") for t in root.iter("SimpleType")}
    reals = 0
    for sv in root.iter("ScalarVariable"):
        real = sv.find("Real")
        if real is None:
            assert sv.find("Integer") is not None or sv.find("Boolean") is not None
            continue
        reals += 1
        declared = types.get(real.get("declaredType", ""))
        if real.get("declaredType") is not None:
            assert declared is not None, (sv.get("name"), real.get("declaredType"))
        unit = real.get("unit") or (declared.get("unit") if declared is not None else None)
        quantity = real.get("quantity") or (
            declared.get("quantity") if declared is not None else None)
        assert unit in units, (sv.get("name"), unit)
        assert quantity, sv.get("name")
        if declared is not None and real.get("unit") is not None:
            assert real.get("unit") == declared.get("unit"), sv.get("name")
    assert reals > 0


def test_the_recurring_kinds_are_type_definitions(root):
    kinds = {t.get("name") for t in root.iter("SimpleType")}
    assert {"Angle", "AngularVelocity", "Force", "Torque", "RotorSpeed", "Length", "Velocity",
            "Acceleration", "Mass", "Time"} <= kinds


def test_nominals_sit_at_the_scale_of_the_defaults(root):
    """The scaled kinds (inertia ~1e-2, k_t ~1e-4, k_d ~1e-6, rotor speeds ~1e2 on the shipped
    airframes) declare a nominal within a decade of every non-zero default of that kind."""
    nominal = {t.get("name"): float(t.find("Real").get("nominal"))
               for t in root.iter("SimpleType") if t.find("Real").get("nominal")}
    assert {"MomentOfInertia", "ThrustCoefficient", "DragTorqueCoefficient",
            "RotorSpeed"} <= set(nominal)
    checked = 0
    for sv in root.iter("ScalarVariable"):
        real = sv.find("Real")
        if real is None or real.get("declaredType") not in nominal or not real.get("start"):
            continue
        start = abs(float(real.get("start")))
        if start > 0.0 and sv.get("causality") == "parameter" and \
                not sv.get("name").startswith(("omega_min", "pref_omega")):
            assert abs(math.log10(start / nominal[real.get("declaredType")])) <= 1.0, \
                sv.get("name")
            checked += 1
    assert checked >= 3


def test_header_names_authorship_version_license_and_a_reproducible_date(root):
    assert root.get("author")
    assert root.get("version") == PYPROJECT["version"]
    assert root.get("license") == PYPROJECT["license"]["text"] == "MIT"
    assert root.get("copyright", "").startswith("Copyright (c) ")
    assert root.get("generationTool") == "fullpose mdgen"
    date = datetime.strptime(root.get("generationDateAndTime"), "%Y-%m-%dT%H:%M:%SZ")
    assert root.get("copyright").split()[2] == str(date.year)


def test_start_values_lie_within_min_and_max(root):
    bounded = 0
    for sv in root.iter("ScalarVariable"):
        el = sv.find("Real") if sv.find("Real") is not None else sv.find("Integer")
        if el is None or el.get("start") is None:
            continue
        start = float(el.get("start"))
        if el.get("min") is not None:
            assert start >= float(el.get("min")), sv.get("name")
            bounded += 1
        if el.get("max") is not None:
            assert start <= float(el.get("max")), sv.get("name")
    assert bounded > 20


def test_the_airframe_parameters_of_both_fmus_declare_the_same_metadata():
    """Both FMUs check their shared airframe parameters by one rule set (fp_check_airframe):
    they declare the same types and ranges too."""
    mds = {m: {v.name: v for v in read_model_description(str(installed_fmu(m))).modelVariables}
           for m in MODELS}
    plant, ctrl = mds["MultirotorPlant"], mds["FullPoseController"]
    shared = [n for n in plant if n in ctrl and plant[n].causality == "parameter"]
    assert len(shared) > 60  # n_rotors, mass, inertia, ..., omega_max
    for n in shared:
        a, b = plant[n], ctrl[n]
        assert (a.type, a.unit, a.min, a.max) == (b.type, b.unit, b.min, b.max), n
        assert (a.declaredType and a.declaredType.name) == (b.declaredType and b.declaredType.name)


# ---------------------------------------------------------------------------
# generationDateAndTime: no clock enters the build


def _build_mdgen(tmp: Path) -> Path:
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip("no C compiler to build mdgen")
    exe = tmp / "plant_mdgen"
    sources = ["tools/mdgen.c", "plant/plant_fmu.c", "plant/plant.c", "plant/contact.c",
               "common/fp_model.c",
               "common/fp_clock.c", "common/fp_params.c", "common/multirotor.c"]
    subprocess.run([cc, "-std=c99", "-O2", "-I", str(SRC / "common"), "-I", str(SRC / "plant"),
                    *[str(SRC / s) for s in sources], "-o", str(exe), "-lm"],
                   check=True, capture_output=True)
    return exe


def _run_mdgen(exe: Path, out: Path, env_epoch: str | None) -> subprocess.CompletedProcess:
    import os

    env = {k: v for k, v in os.environ.items() if k != "SOURCE_DATE_EPOCH"}
    if env_epoch is not None:
        env["SOURCE_DATE_EPOCH"] = env_epoch
    # as the build runs it: with the C files of the FMU's sources/ (its <SourceFiles>)
    # (listed in <CoSimulation>, and again in the plant's <ModelExchange>)
    cs = ET.fromstring(xml_of("MultirotorPlant")).find("CoSimulation")
    files = [f.get("name") for f in cs.iter("File")]
    return subprocess.run([str(exe), str(out), PYPROJECT["version"], "--sources",
                           str(out.parent), *files], env=env, capture_output=True, text=True)


@pytest.mark.heavy  # (mdgen compiled twice: 2.2 s)
def test_generation_date_is_deterministic(tmp_path):
    """mdgen run now, twice a second apart, writes byte for byte the XML the installed FMU
    was built with (at another time): the date is the release's, not the clock's."""
    import time

    exe = _build_mdgen(tmp_path)
    first, second = tmp_path / "a.xml", tmp_path / "b.xml"
    assert _run_mdgen(exe, first, None).returncode == 0
    time.sleep(1.1)
    assert _run_mdgen(exe, second, None).returncode == 0
    assert first.read_bytes() == second.read_bytes()
    shipped = xml_of("MultirotorPlant")
    if b'generationDateAndTime="' + _release_date(first).encode() not in shipped:
        pytest.skip("the installed FMU was built with SOURCE_DATE_EPOCH set")
    assert first.read_bytes() == shipped


def _release_date(xml: Path) -> str:
    return re.search(r'generationDateAndTime="([^"]+)"', xml.read_text()).group(1)


def test_source_date_epoch_sets_the_date_and_a_bad_one_fails_the_build(tmp_path):
    exe = _build_mdgen(tmp_path)
    out = tmp_path / "md.xml"
    assert _run_mdgen(exe, out, "86400").returncode == 0
    root = ET.fromstring(out.read_bytes())
    assert root.get("generationDateAndTime") == "1970-01-02T00:00:00Z"
    assert root.get("copyright").startswith("Copyright (c) 1970 ")
    bad = _run_mdgen(exe, tmp_path / "bad.xml", "yesterday")
    assert bad.returncode != 0 and "SOURCE_DATE_EPOCH" in bad.stderr


# ---------------------------------------------------------------------------
# declared min/max == the FMU's own checks


@dataclass
class Bound:
    name: str          # element name, e.g. "alpha_min[6]"
    type: str          # Real or Integer
    causality: str     # parameter or input
    side: str          # "min" or "max"
    value: float
    open_here: bool    # the description says the range is open at this bound


def _open_sides(description: str) -> tuple[bool, bool]:
    m = re.search(r"; range ([\[(]).*([\])])$", description or "")
    return (m is not None and m.group(1) == "(", m is not None and m.group(2) == ")")


def bounds_of(model: str) -> list[Bound]:
    """Every declared bound of the parameters and inputs the FMU checks: per-rotor vectors
    for rotors 1 and 6 (the default hexacopter's; entries beyond n_rotors are ignored),
    other vectors for their first and last element."""
    md = read_model_description(str(installed_fmu(model)))
    out = []
    for v in md.modelVariables:
        if v.causality not in ("parameter", "input") or (v.min is None and v.max is None):
            continue
        m = re.fullmatch(r"(\w+)(?:\[(\d+)(?:,(\d+))?\])?", v.name)
        index = int(m.group(2) or 1)
        size = sum(1 for w in md.modelVariables if w.name.startswith(m.group(1) + "["))
        keep = index == 1 or (index == 6 if size == 8 else index == size) or size == 0
        if not keep:
            continue
        lo_open, hi_open = _open_sides(v.description)
        for side, text, is_open in (("min", v.min, lo_open), ("max", v.max, hi_open)):
            if text is not None:
                out.append(Bound(v.name, v.type, v.causality, side, float(text), is_open))
    return out


def partners(model: str, b: Bound, x: float) -> dict[str, float | bool]:
    """Values that make the rules beside the declared range (bounds that depend on other
    parameters: servo limits ordered, initial actuators within the airframe's limits, measured
    servo angles near them) as wide as the declared range, so that "just inside the declared
    range" is inside every bound that applies to the variable."""
    base, _, rest = b.name.partition("[")
    i = rest.split(",")[0].rstrip("]") or "1"
    half = math.pi / 2
    out: dict[str, float | bool] = {}
    if model == "MultirotorPlant" and base in ("omega0", "alpha0", "beta0"):
        out["init_trim"] = False  # they are ignored (and unchecked) with init_trim
    for servo in ("alpha", "beta"):
        if base in (f"{servo}0", servo):  # initial or measured angle: limits at +-pi/2
            out.update({f"{servo}_min[{i}]": -half, f"{servo}_max[{i}]": half})
        if base == f"{servo}_min" and b.side == "max":
            out[f"{servo}_max[{i}]"] = half
        if base == f"{servo}_max" and b.side == "min":
            out[f"{servo}_min[{i}]"] = -half
    if base == "euler_min" and b.side == "max":
        out[f"euler_max[{i}]"] = x
    if base == "euler_max" and b.side == "min":
        out[f"euler_min[{i}]"] = x
    return out


class Run:
    """One FMU instance, reset and re-initialized for each trial; records what it logs."""

    def __init__(self, model: str) -> None:
        self.model = model
        self.log: list[tuple[int, str, str]] = []
        self.inst = FmuInstance(installed_fmu(model), log=lambda s, c, m: self.log.append(
            (s, c, m)))

    def initialize(self, values: dict[str, float | int | bool]) -> bool:
        """Reset, set the values before initialization, initialize: True if it succeeded."""
        self.inst.slave.reset()
        self.inst.time = 0.0
        self.log.clear()
        try:
            self.inst.initialize(parameters=values)
        except FmuError:
            return False
        return True

    def step_with(self, values: dict[str, float | bool]) -> bool:
        """Set inputs after a clean initialization and step: False if the step was refused
        (fmi2Error) or held (a warning naming an input)."""
        assert self.initialize({})
        self.log.clear()
        self.inst.set_many(values)
        try:
            self.inst.step(H)
        except FmuError:
            return False
        return not any(s >= 1 and re.search(r"\binput \w+(?:\[\d+\])? = ", m)
                       for s, _, m in self.log)

    def names(self, name: str) -> list[tuple[int, str]]:
        """The warnings and errors that name the variable element (status, message)."""
        pat = re.compile(rf"\b(?:parameter|input) {re.escape(name)} = ")
        return [(s, m) for s, _, m in self.log if s >= 1 and pat.search(m)]

    def close(self) -> None:
        self.inst.close()


@pytest.fixture(scope="module")
def run(model) -> Iterator[Run]:
    r = Run(model)
    yield r
    r.close()


def _outward(b: Bound) -> float:
    if b.type == "Integer":
        return b.value - 1 if b.side == "min" else b.value + 1
    return math.nextafter(b.value, -math.inf if b.side == "min" else math.inf)


def _inward(b: Bound) -> float:
    if b.type == "Integer":
        return b.value
    return math.nextafter(b.value, math.inf if b.side == "min" else -math.inf)


def _typed(b: Bound, x: float) -> float | int:
    return int(x) if b.type == "Integer" else x


def test_a_value_just_outside_a_declared_bound_is_refused_naming_the_variable(model, run):
    failures = []
    bounds = bounds_of(model)
    assert len({b.name.split("[")[0] for b in bounds}) >= (20 if model == "MultirotorPlant"
                                                            else 30)
    for b in bounds:
        values = {**partners(model, b, _outward(b)), b.name: _typed(b, _outward(b))}
        ok = run.initialize(values)
        named = run.names(b.name)
        if ok or not any(s >= 3 for s, _ in named):
            failures.append((b.name, b.side, values[b.name], ok, run.log[-3:]))
    assert failures == []


def test_a_value_just_inside_a_declared_bound_is_accepted(model, run):
    failures = []
    for b in bounds_of(model):
        values = {**partners(model, b, _inward(b)), b.name: _typed(b, _inward(b))}
        run.initialize(values)  # other rules may refuse the airframe: not this variable's
        if run.names(b.name):
            failures.append((b.name, b.side, values[b.name], run.names(b.name)))
    assert failures == []


def test_the_bound_itself_is_accepted_also_where_the_range_is_open(model, run):
    """FMI's min/max are inclusive: an open bound is declared at the first value inside it,
    which the FMU accepts (the interval in the description keeps the open end)."""
    failures = []
    opened = 0
    for b in bounds_of(model):
        if b.type == "Integer":
            continue
        run.initialize({**partners(model, b, b.value), b.name: b.value})
        opened += b.open_here
        if run.names(b.name):
            failures.append((b.name, b.side, b.value, b.open_here, run.names(b.name)))
    assert failures == []
    assert opened > 0  # mass, k_t, Ts, ...: open at 0, declared at 4.9e-324


def test_inputs_outside_their_range_while_stepping_are_caught_naming_them(model, run):
    """The plant refuses the step (fmi2Error), the controller holds its command
    (fmi2Warning), both naming the input; just inside steps without a word."""
    failures = []
    for b in bounds_of(model):
        if b.causality != "input":
            continue
        if partners(model, b, 0.0):
            continue  # the servo angles: their airframe limits are parameters, fixed by now
        if run.step_with({b.name: _outward(b)}) or not run.names(b.name):
            failures.append(("outside", b.name, b.side, run.log[-2:]))
        if not run.step_with({b.name: _inward(b)}) or run.names(b.name):
            failures.append(("inside", b.name, b.side, run.log[-2:]))
    assert failures == []


# ---------------------------------------------------------------------------
# logging


def test_log_calls_carries_the_arguments(model):
    log: list[tuple[int, str, str]] = []
    with FmuInstance(installed_fmu(model), log=lambda s, c, m: log.append((s, c, m)),
                     logging_on=True) as inst:
        inst.slave.setDebugLogging(True, ["logCalls"])
        inst.initialize()
        mass = inst.vr("mass")
        with pytest.raises(FMICallException):  # a fixed parameter after initialization
            inst.slave.setReal([mass], [0.0])
        first = inst.vr("pos[1]" if model == "FullPoseController" else "omega_cmd[1]")
        refs = list(range(first, first + 3))
        inst.slave.setReal(refs, [0.25, -1.5, 3e-7])
        inst.step(H)
        many = [inst.vr(n) for n in inst.expand("omega_cmd" if model == "MultirotorPlant"
                                                 else "omega")] * 3
        inst.slave.getReal(many)
    calls = [m for s, c, m in log if c == "logCalls"]
    name = "pos" if model == "FullPoseController" else "omega_cmd"
    assert any(m.startswith("fmi2SetReal(nvr = 3:") and f"{name}[1] (vr {first}) = 0.25" in m
               and f"{name}[3] (vr {first + 2}) = 3e-07" in m for m in calls), calls
    assert any(m.startswith("fmi2DoStep(") and "currentCommunicationPoint = 0," in m
               and "communicationStepSize = 0.002" in m for m in calls), calls
    assert any(m.startswith("fmi2SetupExperiment(") and "startTime = 0" in m for m in calls)
    gets = [m for m in calls if m.startswith("fmi2GetReal(nvr = 24:")]
    assert gets and "... 16 more" in gets[0] and len(gets[0]) < 700, gets
    assert gets[0].count(") = ") == 8  # eight values shown, each with its value
    # a set refused for its value references still shows what it was given, then why
    assert any(m.startswith(f"fmi2SetReal(nvr = 1: mass (vr {mass}) = 0)") for m in calls)
    assert any(s == 3 and "cannot set mass" in m for s, _, m in log)


def _inertia_warnings(log: list[tuple[int, str, str]]) -> int:
    return sum(1 for s, _, m in log if s == 1 and "principal moment" in m)


def test_an_initialization_warning_is_logged_once(model):
    """The paper airframe's inertia warning (Iz > Ix + Iy) comes from the parameter checks,
    which run at every read in initialization mode, at its end and on a restored state:
    it is logged once per initialization, and again after a reset."""
    log: list[tuple[int, str, str]] = []
    with FmuInstance(installed_fmu(model), log=lambda s, c, m: log.append((s, c, m))) as inst:
        inst.enter_initialization()
        for _ in range(3):
            inst.set("mass", inst.get("mass"))  # each read re-validates the changed set
        inst.exit_initialization()
        state = inst.slave.getFMUstate()
        inst.step(H)
        inst.slave.setFMUstate(state)
        inst.slave.freeFMUstate(state)
        assert _inertia_warnings(log) == 1, log
        inst.slave.reset()
        inst.initialize()
        assert _inertia_warnings(log) == 2, log


def test_distinct_initialization_warnings_each_appear_once():
    """A second, different warning (a coarse h_internal) is news: both appear, once each."""
    log: list[tuple[int, str, str]] = []
    with FmuInstance(installed_fmu("MultirotorPlant"),
                     log=lambda s, c, m: log.append((s, c, m))) as inst:
        inst.enter_initialization(parameters={"h_internal": 0.01})
        inst.get("mass")
        inst.set("h_internal", 0.02)  # another value: another warning
        inst.get("mass")
        inst.exit_initialization()
    coarse = [m for s, _, m in log if s == 1 and "is coarse" in m]
    assert _inertia_warnings(log) == 1
    assert len(coarse) == 2 and "0.01 s" in coarse[0] and "0.02 s" in coarse[1], coarse


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__, "-q"]))
