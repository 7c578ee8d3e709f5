"""Every declared bound is a value the FMU accepts (issue 34, deliverable 2).

FMI 2.0's ``min`` and ``max`` are inclusive: an importer may offer, and set, exactly the
declared bound.  The probe sets, on a fresh instance (fmpy's FMU2Slave, one fmi2Instantiate per
trial), every declared ``min`` and ``max`` of every parameter and input element to exactly the
value the modelDescription gives (the text read back as a double), with the other values at
the shipped paper hexacopter's start values, and initializes:

- no bound may be refused by the variable's own range check: a message ``parameter NAME =
  VALUE: ...`` or ``input NAME = VALUE: ...`` naming the variable (what the FMUs log for a
  value outside its range) fails the probe.  An open range is declared at the first value
  inside it (``mass`` > 0: ``min="4.9406564584124654e-324"``, tools/mdgen.c), not at its
  boundary, which the check refuses;
- the rules that relate one parameter to others are met by partner values (the servo limits
  ordered around a limit probed at +-pi/2, the Euler bounds ordered, an initial actuator
  state within its limits, a measured servo angle within the airframe's limits), so that a
  bound is accepted as a whole wherever some airframe accepts it;
- what remains refused is refused by a plausibility or feasibility rule that no single
  variable's range can state (``parameter omega_max: ... slower than any rotor turns``; a
  thrust or thrust-to-weight ratio out of range; one rotor cannot hover), which logs
  ``parameter NAME: ...`` or ``parameters A, B: ...`` without a value: those are counted and
  listed, and each must be one of these.
"""

from __future__ import annotations

import math
import re
import shutil
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import pytest
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

import plant
from orchestrator.sim.fmu import installed_fmu, set_by_type
from orchestrator.sim.start_values import Pose, start_values
from plant.airframe import airframe_table

MODELS = ("MultirotorPlant", "FullPoseController")
ERROR = 3
Value = float | int | bool
# a refusal by another rule than the variable's own range: no "= VALUE" after the name
OTHER_RULE = re.compile(r"^parameters? [\w, /\[\]]+: ")


@dataclass(frozen=True)
class Bound:
    """One declared bound of one variable element."""

    name: str
    type: str
    causality: str
    side: str  # "min" or "max"
    value: float


class Probe:
    """Fresh instances of one FMU through fmpy: set values, initialize, keep the log."""

    def __init__(self, model: str) -> None:
        path = str(installed_fmu(model))
        self.md = read_model_description(path)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.unzip = extract(path)
        self.log: list[tuple[int, str]] = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._on_log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzip,
                               modelIdentifier=self.md.coSimulation.modelIdentifier,
                               instanceName="probe")

    def _on_log(self, env: object, name: bytes, status: int, category: bytes,
                message: bytes) -> None:
        self.log.append((status, message.decode(errors="replace").replace("%%", "%")))

    def bounds(self) -> list[Bound]:
        """Every declared min and max of the parameters and inputs, as the XML gives them: of
        every row's first element and its last in use (rotor 6 of a per-rotor row: the paper
        hexacopter's last; the elements of a row share its range and its check)."""
        size: dict[str, int] = {}
        for v in self.md.modelVariables:
            base = v.name.split("[")[0]
            size[base] = size.get(base, 0) + 1
        out = []
        for v in self.md.modelVariables:
            if v.causality not in ("parameter", "input"):
                continue
            base, _, rest = v.name.partition("[")
            index = int(rest.split(",")[0].rstrip("]") or 1)
            last = 6 if size[base] == 8 else size[base]
            if index not in (1, last) or ("," in rest and not rest.startswith(("1,1]",
                                                                              f"{last},"))):
                continue
            out += [Bound(v.name, v.type, v.causality, side, float(text))
                    for side, text in (("min", v.min), ("max", v.max)) if text is not None]
        return out

    def initializes(self, values: Mapping[str, Value]) -> bool:
        """A fresh instance with these values set before initialization: True if
        fmi2ExitInitializationMode succeeded.  The log holds what the FMU said."""
        self.log.clear()
        self.slave.instantiate(callbacks=self.callbacks)
        try:
            self.slave.setupExperiment(startTime=0.0)
            set_by_type(self.slave, self.variables, values)
            self.slave.enterInitializationMode()
            self.slave.exitInitializationMode()
            return True
        except FMICallException:
            return False
        finally:
            # not fmpy's freeInstance, which also unloads the library
            self.slave.fmi2FreeInstance(self.slave.component)

    def close(self) -> None:
        self.slave.freeLibrary()
        shutil.rmtree(self.unzip, ignore_errors=True)


@pytest.fixture(scope="module", params=MODELS)
def probe(request: pytest.FixtureRequest) -> Iterator[Probe]:
    p = Probe(request.param)
    yield p
    p.close()


@pytest.fixture(scope="module")
def shipped() -> dict[str, dict[str, Value]]:
    """Partners from the shipped airframes: the paper hexacopter's design-time force sets
    (``sets``: poly_n = 64 facets of S(0), fail_poly_n = 32 per lost rotor) and the X8
    coaxial octocopter's airframe rows for either FMU (``x8 MultirotorPlant``, ``x8
    FullPoseController``)."""
    pose = Pose.of(pos=(0.0, 0.0, -3.0))
    paper = start_values(plant.load_airframe("paper_hexacopter"), pose)
    x8 = start_values(plant.load_airframe("x8_coaxial"), pose)
    air = {n.name for n in airframe_table()}
    return {"sets": {k: v for k, v in paper.controller.items()
                     if k.startswith(("poly_", "fail_poly_"))},
            "x8 MultirotorPlant": {k: v for k, v in x8.plant.items()
                                   if k.split("[")[0] in air},
            "x8 FullPoseController": {k: v for k, v in x8.controller.items()
                                      if k.split("[")[0] in air}}


def partners(model: str, b: Bound, shipped: Mapping[str, Mapping[str, Value]]
             ) -> dict[str, Value]:
    """Values that meet the rules relating the probed variable to others (see the module
    docstring), so that the bound stands alone."""
    base, _, rest = b.name.partition("[")
    i = rest.split(",")[0].rstrip("]") or "1"
    half = math.pi / 2
    out: dict[str, Value] = {}
    if base in ("poly_n", "fail_poly_n") and b.value > 0:
        out.update(shipped["sets"])  # facets to count
    if base == "n_rotors" and b.value == 8:
        out.update(shipped[f"x8 {model}"])  # eight rotors in eight places
    if base == "n_rotors" and b.value == 1 and model == "MultirotorPlant":
        out["init_trim"] = False  # one rotor has no hover trim; it need not start at one
    if base == "mass" and b.side == "min":
        out["g"] = 0.0  # weightless: no thrust-to-weight ratio to keep plausible
    if model == "MultirotorPlant" and base in ("omega0", "alpha0", "beta0"):
        out["init_trim"] = False  # ignored (and unchecked) at hover trim
    for servo in ("alpha", "beta"):
        if base in (f"{servo}0", servo):  # an initial or measured angle: limits at +-pi/2
            out.update({f"{servo}_min[{i}]": -half, f"{servo}_max[{i}]": half})
        if base in (f"{servo}_min", f"{servo}_max") and abs(b.value) == half:
            # a rotor fixed at +-pi/2 (thrust in the body plane): the hover trim the plant
            # starts at and the controller derives its attitude limits from has no closed
            # form; start the plant at rest, give the controller its attitude limits
            if model == "MultirotorPlant":
                out.update({"init_trim": False, f"{servo}0[{i}]": b.value})
            else:  # (and the measured angle within the limits)
                out.update({f"ref_att_acc_max[{k}]": a for k, a in ((1, 20.0), (2, 20.0),
                                                                      (3, 5.0))})
                out[f"{servo}[{i}]"] = b.value
        if base == f"{servo}_min" and b.side == "max":
            out[f"{servo}_max[{i}]"] = b.value
        if base == f"{servo}_max" and b.side == "min":
            out[f"{servo}_min[{i}]"] = b.value
    if base == "euler_min" and b.side == "max":
        out[f"euler_max[{i}]"] = b.value
    if base == "euler_max" and b.side == "min":
        out[f"euler_min[{i}]"] = b.value
    return out


def own_refusals(p: Probe, b: Bound) -> list[str]:
    """Errors naming the variable with its value: its own range check refused it."""
    pat = re.compile(rf"\b(?:parameter|input) {re.escape(b.name)} = ")
    return [m for s, m in p.log if s >= ERROR and pat.search(m)]


def probe_all(p: Probe, shipped: Mapping[str, Mapping[str, Value]]) -> tuple[list, list, int]:
    """(bounds refused by their own check, bounds refused by other rules, bounds probed), each
    on a fresh instance: the defaults, the partners and the bound."""
    own, other = [], []
    bounds = p.bounds()
    for b in bounds:
        value: Value = int(b.value) if b.type == "Integer" else b.value
        ok = p.initializes({**partners(p.md.modelName, b, shipped), b.name: value})
        if own_refusals(p, b):
            own.append((b.name, b.side, b.value, own_refusals(p, b)))
        elif not ok:
            other.append((b.name, b.side, b.value,
                          [m for s, m in p.log if s >= ERROR]))
    return own, other, len(bounds)


# Bounds that only a plausibility or feasibility rule refuses, whatever the partners: no
# rotor's thrust k_t omega_max^2 reaches 1 mN with k_t = 4.9e-324 (omega_max is at most
# 500000 rpm), no rotor turns slower than 1 rpm, and one rotor cannot hold a vehicle (its
# drag torque is not balanced; the plant flies it, the controller finds no force set).
REFUSED_BY_OTHER_RULES = {
    "MultirotorPlant": {("k_t", "min"), ("omega_max", "min")},
    "FullPoseController": {("k_t", "min"), ("omega_max", "min"), ("n_rotors", "min")},
}


def test_every_declared_bound_is_accepted_by_the_variables_own_check(probe, shipped):
    own, other, n = probe_all(probe, shipped)
    print(f"{probe.md.modelName}: {n} declared bounds, {len(own)} refused by their own "
          f"check, {len(other)} by other rules: "
          + "; ".join(f"{name} {side}={value:.17g}" for name, side, value, _ in other))
    assert n > (40 if probe.md.modelName == "MultirotorPlant" else 80)
    assert own == []
    # what other rules refuse is a plausibility or feasibility rule, stated without a value
    for name, side, _, messages in other:
        assert messages and all(OTHER_RULE.match(m) for m in messages), (name, side, messages)
    assert {(name, side) for name, side, _, _ in other} == \
        REFUSED_BY_OTHER_RULES[probe.md.modelName]


def test_open_ranges_are_declared_at_their_first_accepted_value():
    """mdgen writes an open bound as the adjacent double inside it; the description keeps the
    interval as the check states it."""
    mds = {m: {v.name: v for v in read_model_description(str(installed_fmu(m))).modelVariables}
           for m in MODELS}
    plant_vars, ctrl = mds["MultirotorPlant"], mds["FullPoseController"]
    tiny = math.nextafter(0.0, 1.0)
    assert float(plant_vars["mass"].min) == tiny
    assert "range (0, inf)" in plant_vars["mass"].description
    assert float(ctrl["Ts"].min) == tiny and ctrl["Ts"].max is None
    assert float(ctrl["K_pos_A[1]"].min) == math.nextafter(-1.0, 0.0)
    assert float(ctrl["K_pos_A[1]"].max) == math.nextafter(1.0, 0.0)
    assert float(ctrl["euler_max[2]"].max) == math.nextafter(math.pi / 2, 0.0)
    assert float(ctrl["poly_margin"].min) == tiny and float(ctrl["poly_margin"].max) == 1.0
    assert float(plant_vars["k_d"].min) == 0.0  # closed: at the bound itself


def test_the_controller_accepts_the_open_bounds_exactly(shipped):
    """The first accepted values of the open ranges (mdgen's min/max) initialize, the bound
    itself (the value just beyond them) is refused naming the variable."""
    p = Probe("FullPoseController")
    try:
        for name in ("Ts", "filt_zeta", "K_vel_A[2]", "W_u[3]", "euler_min[1]", "poly_margin",
                     "fault_loss_min", "ref_tilt_max"):
            v = p.variables[name]
            for text, toward in ((v.min, -math.inf), (v.max, math.inf)):
                if text is None:
                    continue
                b = Bound(name, v.type, v.causality, "min" if toward < 0 else "max",
                          float(text))
                assert p.initializes({**partners(p.md.modelName, b, shipped), name: b.value}), \
                    (name, b.value, p.log[-3:])
                beyond = math.nextafter(b.value, toward)
                assert not p.initializes({**partners(p.md.modelName, b, shipped), name: beyond})
                assert own_refusals(p, b), (name, beyond)
    finally:
        p.close()


def test_the_bridge_reads_the_open_ranges_the_fmu_checks():
    """mavlink_bridge.params.fmu_range turns the declared first-accepted value back into the
    open bound the FMU refuses: (0, inf) for the weights, (-1, 1) for the poles."""
    from mavlink_bridge.params import fmu_range

    ctrl = {v.name: v for v in read_model_description(
        str(installed_fmu("FullPoseController"))).modelVariables}
    w = fmu_range(ctrl["W_u[1]"])
    assert (w.lo, w.hi, w.lo_open, w.text()) == (0.0, None, True, "(0, inf)")
    assert not w.contains(0.0) and w.contains(math.nextafter(0.0, 1.0))
    a = fmu_range(ctrl["K_att_A[3]"])
    assert (a.lo, a.hi, a.text()) == (-1.0, 1.0, "(-1, 1)")
    assert not a.contains(1.0) and a.contains(math.nextafter(1.0, 0.0))
    q = fmu_range(ctrl["qp_max_iter"])
    assert (q.lo, q.hi, q.integer, q.text()) == (1.0, 1000.0, True, "1..1000")
