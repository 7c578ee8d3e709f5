"""What importers read first and what they build their initialization on (issue 34,
deliverable 2): the order of the ScalarVariables and the <ModelStructure>.

- The ScalarVariables are listed inputs, then outputs, then parameters, each in the table's
  order (tools/mdgen.c), then the plant's Model Exchange states and derivatives (local):
  importers that find a connector by name scan from the top.  The value references are the
  tables' (fmu_src/*/*_vars.h, read here from the C source), so nothing that goes by name or
  value reference notices the order.
- <ModelStructure> names variables by their 1-based ScalarVariable index: <Outputs> lists
  every output in that order, the controller's with ``dependencies=""`` (no direct
  feedthrough at communication points), the plant's with what its outputs are functions of
  in Model Exchange (states, some inputs: PLANT_OUTPUT_DEPENDENCIES, checked by
  test_model_exchange.py); <InitialUnknowns> lists the same outputs (and the plant's states
  and derivatives), each with the knowns (inputs, parameters: FMI 2.0 section 2.2.8) the
  table declares it a function of at initialization.
- The declarations are never short: perturbing one known at a time moves only the initial
  outputs (and states and derivatives) that list it (the shipped paper hexacopter, its
  design-time force sets given).
- The plant's initial outputs do not depend on its actuator commands, so the closed loop
  (plant outputs into controller inputs and back, by name) has no algebraic loop at
  initialization.
"""

from __future__ import annotations

import math
import re
import zipfile
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.model_description import ModelDescription, ScalarVariable

import plant
from orchestrator.export.ssp import CONTROLLER, PLANT, connection_table
from orchestrator.sim.fmu import FmuError, FmuInstance, installed_fmu
from orchestrator.sim.start_values import Pose, start_values

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "fmu_src"
MODELS = ("MultirotorPlant", "FullPoseController")
TABLES = {"MultirotorPlant": ("plant/plant_vars.h", 0),
          "FullPoseController": ("controller/controller_vars.h", 1)}
ROW = re.compile(r"\bXS?\((\w+), ([^,]+), (\w+), (\w+), (\d+), (\d+),")
Value = float | int | bool


@pytest.fixture(scope="module", params=MODELS)
def model(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture(scope="module")
def md(model: str) -> ModelDescription:
    return read_model_description(str(installed_fmu(model)))


def table_references(model: str) -> dict[str, int]:
    """Element name -> value reference, from the X-macro rows of the model's table (the
    airframe rows of common/airframe_vars.h with the model's shift S)."""
    path, shift = TABLES[model]
    out: dict[str, int] = {}
    for text, s in (((SRC / path).read_text(), 0),
                    ((SRC / "common/airframe_vars.h").read_text(), shift)):
        for name, vr, _, _, rows, cols in ROW.findall(text):
            m = re.fullmatch(r"(\d+)( \+ \(S\))?", vr)  # "1 + (S)": the shifted rows
            assert m, (name, vr)
            first = int(m.group(1)) + (s if m.group(2) else 0)
            r, c = int(rows), int(cols)
            for k in range(r * c):
                element = name if r * c == 1 else (f"{name}[{k + 1}]" if c == 1
                                                   else f"{name}[{k // c + 1},{k % c + 1}]")
                out[element] = first + k
    return out


def test_inputs_and_outputs_come_before_the_parameters(md):
    causality = [v.causality for v in md.modelVariables]
    n_in, n_out, n_local = (causality.count(c) for c in ("input", "output", "local"))
    assert causality == ["input"] * n_in + ["output"] * n_out + \
        ["parameter"] * (len(causality) - n_in - n_out - n_local) + ["local"] * n_local
    assert n_in > 0 and n_out > 0
    # the plant's states, their derivatives and its contact depths (the event indicators)
    assert n_local == (2 * md.numberOfContinuousStates + 8 if md.modelExchange else 0)


def test_value_references_are_the_tables(model, md):
    refs = table_references(model)
    assert {v.name: int(v.valueReference) for v in md.modelVariables} == refs
    # and within each causality the table's order
    for kind in ("input", "output", "parameter"):
        listed = [int(v.valueReference) for v in md.modelVariables if v.causality == kind]
        rows = [refs[v.name] for v in md.modelVariables if v.causality == kind]
        assert listed == rows


def test_model_structure_names_the_outputs_by_their_index(md):
    outputs = [i + 1 for i, v in enumerate(md.modelVariables) if v.causality == "output"]
    index = {id(v): i + 1 for i, v in enumerate(md.modelVariables)}
    # the continuous states and their derivatives (initial unknowns in FMI 2.0 section 2.2.8)
    local = sorted([index[id(d.variable)] for d in md.derivatives] +
                   [index[id(d.variable.derivative)] for d in md.derivatives])
    assert [index[id(u.variable)] for u in md.outputs] == outputs
    if md.modelExchange is None:
        assert all(u.dependencies == [] for u in md.outputs)
    else:  # Model Exchange: functions of the states and some inputs
        states = {id(d.variable.derivative) for d in md.derivatives}
        for u in md.outputs:
            assert all(d.causality == "input" or id(d) in states for d in u.dependencies)
    assert [index[id(u.variable)] for u in md.initialUnknowns] == outputs + local
    for u in md.initialUnknowns:
        deps = [index[id(d)] for d in u.dependencies]
        assert deps == sorted(set(deps)), u.variable.name
        assert all(d.causality in ("input", "parameter") for d in u.dependencies)


def test_every_initial_unknown_declares_its_dependencies(model):
    """The attribute is on every InitialUnknown: absent, it would mean every known."""
    with zipfile.ZipFile(installed_fmu(model)) as z:
        text = z.read("modelDescription.xml").decode()
    block = text.split("<InitialUnknowns>")[1].split("</InitialUnknowns>")[0]
    unknowns = re.findall(r"<Unknown [^>]*/>", block)
    assert unknowns and all('dependencies="' in u for u in unknowns)


def test_no_initial_output_of_the_plant_waits_for_a_command():
    """(The state derivatives do depend on the commands: no output does, so nothing connected.)"""
    md = read_model_description(str(installed_fmu("MultirotorPlant")))
    commands = {v.name for v in md.modelVariables if v.causality == "input"
                and v.name.split("[")[0] in ("omega_cmd", "alpha_cmd", "beta_cmd")}
    assert len(commands) == 24
    for u in md.initialUnknowns:
        if u.variable.causality == "output":
            assert not commands & {d.name for d in u.dependencies}, u.variable.name


def _has_cycle(edges: Mapping[str, set[str]]) -> list[str]:
    """A cycle of the directed graph (node -> successors), or []."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str]:
        state[n] = 1
        stack.append(n)
        for m in edges.get(n, ()):
            if state.get(m) == 1:
                return [*stack[stack.index(m):], m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return []

    for n in list(edges):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return []


def test_the_closed_loop_has_no_algebraic_loop_at_initialization():
    """The initialization graph an importer builds (OMSimulator does exactly this): known ->
    initial unknown within each FMU, output -> input along the connections."""
    mds = {PLANT: read_model_description(str(installed_fmu(PLANT))),
           CONTROLLER: read_model_description(str(installed_fmu(CONTROLLER)))}
    edges: dict[str, set[str]] = {}
    for comp, m in mds.items():
        for u in m.initialUnknowns:
            for d in u.dependencies:
                edges.setdefault(f"{comp}.{d.name}", set()).add(f"{comp}.{u.variable.name}")
    connections = connection_table(mds[PLANT], mds[CONTROLLER])
    assert len(connections) > 60
    for src, sv, dst, dv in connections:
        edges.setdefault(f"{src}.{sv}", set()).add(f"{dst}.{dv}")
    assert _has_cycle(edges) == []
    # and the check finds the loop an output depending on every known would make
    edges.setdefault(f"{PLANT}.omega_cmd[1]", set()).add(f"{PLANT}.omega[1]")
    assert _has_cycle(edges)


# ---------------------------------------------------------------------------
# the declarations are not short: perturbation


def _perturbed(v: ScalarVariable, x: Value, name: str) -> list[Value]:
    """Other values of a known worth trying, within its declared range."""
    kind = v.type
    lo = float(v.min) if v.min is not None else -math.inf
    hi = float(v.max) if v.max is not None else math.inf
    if kind == "Boolean":
        return [not x]
    if kind == "Integer":
        return [y for y in (int(x) - 1, int(x) + 1) if lo <= y <= hi]
    d = 0.01 * abs(float(x)) if x else 0.01
    out = [y for y in (float(x) + d, float(x) - d) if lo <= y <= hi]
    if name.startswith("rotor_health"):
        out.insert(0, 0.3)  # reported lost: the force set in use changes
    return out


OUTPUT_TYPES = ("Real", "Integer", "Boolean")


def _unknown(md: ModelDescription, v: ScalarVariable) -> bool:
    """An initial unknown: an output, or (the plant) a continuous state or its derivative."""
    return v.causality == "output" or any(v is d.variable or v is d.variable.derivative
                                          for d in md.derivatives)


def _output_names(md: ModelDescription) -> list[str]:
    """The initial unknowns in the order _outputs reads them: by type, each in listing
    order."""
    return [v.name for kind in OUTPUT_TYPES for v in md.modelVariables
            if _unknown(md, v) and v.type == kind]


def _outputs(inst: FmuInstance, md: ModelDescription) -> np.ndarray:
    values: list[float] = []
    for kind, get in zip(OUTPUT_TYPES, (inst.slave.getReal, inst.slave.getInteger,
                                        inst.slave.getBoolean), strict=True):
        refs = [v.valueReference for v in md.modelVariables
                if _unknown(md, v) and v.type == kind]
        values += [float(x) for x in get(refs)]
    return np.array(values)


def _start(v: ScalarVariable) -> Value:
    text = str(v.start)
    if v.type == "Boolean":
        return text in ("true", "1", "True")
    return int(text) if v.type == "Integer" else float(text)


@pytest.fixture(scope="module")
def paper() -> dict[str, dict[str, Value]]:
    sv = start_values(plant.load_airframe("paper_hexacopter"), Pose.of(pos=(0.5, -1.0, -3.0)))
    return {PLANT: dict(sv.plant), CONTROLLER: dict(sv.controller)}


@pytest.fixture(scope="module")
def instance(model: str) -> Iterator[FmuInstance]:
    with FmuInstance(installed_fmu(model)) as inst:
        yield inst


def test_no_initial_output_moves_with_a_known_it_does_not_list(model, md, instance, paper):
    """One known at a time (the first element of every input and parameter row), perturbed
    within its range from the shipped airframe's start values (the controller's force sets
    given, so that they count): every initial output that changes lists that known."""
    base = paper[model]
    outputs = _output_names(md)
    deps = {u.variable.name: {d.name for d in u.dependencies} for u in md.initialUnknowns}
    assert set(deps) == set(outputs)

    def initial(values: Mapping[str, Value]) -> np.ndarray | None:
        instance.reset()
        try:
            instance.initialize(parameters=values)
        except FmuError:
            return None
        return _outputs(instance, md)

    reference = initial(base)
    assert reference is not None
    seen: set[str] = set()
    short, exercised, moved = [], 0, 0
    for v in md.modelVariables:
        row = v.name.split("[")[0]
        if v.causality not in ("input", "parameter") or row in seen:
            continue
        seen.add(row)
        x: Value = base.get(v.name, _start(v))
        for y in _perturbed(v, x, v.name):
            got = initial({**base, v.name: y})
            if got is None:
                continue  # another rule refuses the combination: try the next value
            exercised += 1
            changed = [outputs[i] for i in np.flatnonzero(
                ~((got == reference) | (np.isnan(got) & np.isnan(reference))))]
            moved += bool(changed)
            short += [(v.name, y, o) for o in changed if v.name not in deps[o]]
            break
    print(f"{md.modelName}: {len(seen)} known rows, {exercised} perturbed, {moved} moved an "
          "initial output")
    assert short == []
    assert exercised >= 0.9 * len(seen) and moved >= 10
