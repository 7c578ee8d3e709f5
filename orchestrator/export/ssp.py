"""Export the closed loop (plant FMU + controller FMU) as an SSP archive: SSP 1.0 with the FMI
2.0 FMUs (the default), or SSP 2.0 with the FMI 3.0 FMUs (``fmi=3``).

    export_ssp(Path("hover.ssp"))                     # paper hexacopter hovering at [0, 0, -3]
    export_ssp(Path("quad.ssp"), airframe="quadrotor")
    export_ssp(Path("hover3.ssp"), fmi=3)             # SSP 2.0, fmi3/*.fmu, array connectors

Archive layout (zip, entries in this order, all timestamps 1980-01-01 00:00:00)::

    SystemStructure.ssd                 system "ClosedLoop": both components, their connectors,
                                        the connections, one ParameterBinding per component
    resources/FullPoseController.fmu    the installed FMUs, byte for byte (stored, not
    resources/MultirotorPlant.fmu       recompressed)
    resources/FullPoseController.ssv    one SSV parameter set per component, bare FMU variable
    resources/MultirotorPlant.ssv       names (the binding sits on the component)

With ``fmi=3`` the layout is the same; the SSD and SSVs declare ``version="2.0"`` (SSP 2.0,
the first version with FMI 3.0 types and arrays) and name FMI 3.0 variables: a vector is one
array connector (``<ssd:Connector name="pos" kind="output"><ssc:Float64/><ssc:Dimension
size="3"/>``), a connection joins two whole arrays (no ``startIndices``/``endIndices``), and a
parameter is one value list in row-major order (``<ssv:Parameter name="poly_A"><ssv:Float64
value="..."/><ssc:Dimension size="64"/><ssc:Dimension size="3"/>``); the types are the FMI 3.0
ones (``Float64``, ``Int32``, ``Boolean``), every component says
``implementation="CoSimulation"`` (the plant's archive also has Model Exchange, the
controller's Scheduled Execution), and the controller's clock ``sample`` (Scheduled
Execution's) is neither a connector nor connected.  The numbers are the FMI 2.0 archive's,
element for element.  fmpy's and libcosim's SSP loaders read SSP 1.0 with FMI 2.0 only;
``orchestrator.export.ssp_replay`` plays either archive.

Connections are derived by name from the two modelDescriptions (:func:`connection_table`):
every controller input named like a plant output (pos, vel, acc, euler, rate, omega, alpha,
beta) and every plant input named like a controller output (omega_cmd, alpha_cmd, beta_cmd).
The SSD declares a connector for every connected input and for every output of both FMUs
(so that a runner records them), nothing else: parameters are set through the SSVs, and the
unconnected inputs (the controller's references, the plant's disturbances and efficiencies)
get start values from the SSVs (SSP 1.0 allows parameter bindings to give "start values of
other variables").  The plant starts at hover trim (``init_trim = true``) at ``pos0``; the
controller's reference is that hover point; the controller's measurement inputs and the
plant's command inputs get the plant's initial outputs / trim as start values, so the loop is
consistent at t = 0 for a runner that initialises inputs from start values.

The step size (SSP 1.0 has no element for it) is written twice in the ``DefaultExperiment``,
next to start and stop time: as the Open Simulation Platform's annotation
(``com.opensimulationplatform``: ``osp:Algorithm/osp:FixedStepAlgorithm baseStepSize``),
which libcosim's SSP loader applies, and as our own ``org.fullpose.fixedStepMaster``; and once
on the system, as OpenModelica's annotation (``org.openmodelica``:
``oms:Annotations/oms:SimulationInformation/oms:FixedStepMaster stepSize``), which
OMSimulator's C API and command line need to create the system and take the step from.
libcosim also applies the ParameterBindings (to parameters and inputs), so it plays the
archive as written: ``CosimExecution.from_ssp_file(path)`` hovers to ~1e-15 m
(tests/test_orchestrator/test_ssp.py).

What fmpy's SSP runner (``fmpy.ssp.simulation.simulate_ssp``, fmpy 0.3.x) does, read from its
source, and how this module deals with it:

* It validates the SSD (and each SSV it reads) against the bundled SSP 1.0 XML Schema 1.0
  files, namespaces ``http://ssp-standard.org/SSP1/...``: the files written here validate.
* It *reads* ParameterBindings (SSV files in the archive) but never *applies* them: only its
  ``parameter_set`` argument is applied, with hierarchical names (``MultirotorPlant.mass``),
  to every component after ``setupExperiment`` and before ``enterInitializationMode``.
  :func:`parameter_set` builds that argument from the archive itself (through fmpy's own
  ``read_ssd``/``read_ssv``), so run ``simulate_ssp(path, parameter_set=parameter_set(path))``.
  Without it the FMUs keep their modelDescription defaults (paper hexacopter hovering at the
  origin), not the exported airframe and hover point.
* It applies Boolean parameters as ``value != 0.0``: an SSV string ``"false"`` would become
  true.  :func:`parameter_set` converts values to Python bool/int/float by the SSV type, which
  avoids that (the only Boolean written is ``init_trim = true`` anyway).
* It ignores DefaultExperiment, annotations and connector types: pass ``stop_time`` and
  ``step_size`` explicitly (its default step is stop_time / 100); :func:`fmpy_options`
  reads them, and the parameter set, from the archive.
* It steps all components with the same inputs and then copies outputs to inputs (Jacobi:
  one-step delay in both directions), and it sets every declared *input* connector from its
  connection at every step, starting from 0.0 at the first step (input start values are not
  used for connected inputs).  So in the first step the plant gets zero commands (its motors
  spin down by ~10 % for 2 ms) and the controller zero measurements (the vehicle seems to be
  at the origin, at rest, rotors stopped), whose commands the plant then applies in the
  second step.  The start-up dip that follows grows with the distance of ``pos0`` from the
  origin (2 ms steps, shipped H-infinity gains, measured): 1.61 mm peak near t = 0.42 s at
  [0, 0, -3] (paper hexacopter and quadrotor alike; 0.12 mm left at t = 1.5 s, 39 um at
  t = 2 s, decaying at ~2.4/s through the blocks' slow lag states), 13 mm (hexacopter) /
  18 mm (quadrotor) at [1, -2, -5], 30 mm (hexacopter) at [0, 0, -10].  The hexacopter's
  dies out (below 0.06 mm at t = 2 s at all three points); the quadrotor at [1, -2, -5],
  which corrects the lateral jump through its attitude, still has 0.5 mm left at t = 2 s.
  (With the prototype's hand-tuned P blocks: 1.24 mm near t = 0.37 s at [0, 0, -3], 4 um
  left at t = 2 s.)  When the t = 0 inputs are the SSV start values instead (what the
  archive describes), the same archive holds the hover to ~1e-15 m
  (tests/test_orchestrator/test_ssp.py
  shows both).
* Unconnected inputs must not be declared as connectors: they would be forced to 0.0 every
  step (pos_ref = 0 would fly the vehicle to the origin), and its connection resolution fails
  for an input connector without a connection.  Left undeclared, they keep the start values
  the SSV gives them (applied through ``parameter_set``).
* Its result is a NumPy structured array: a ``time`` column (the start of each step) and one
  column per declared connector, named ``<component>.<variable>``, e.g.
  ``MultirotorPlant.pos[3]``, holding the value after that step.
"""

from __future__ import annotations

import io
import logging
import math
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from fmpy import read_model_description
from fmpy.model_description import ModelDescription
from fmpy.ssp.ssd import Parameter, ParameterSet, System, read_ssd
from lxml import etree

from controller import CONTROLLER_FMU, controller_fmu
from orchestrator.export.archive import add_entry
from orchestrator.export.signals import SIGNALS_FMU, signals_fmu
from orchestrator.sim.fmu import FmuInstance
from orchestrator.sim.fmu3 import Element, Fmu3Instance
from orchestrator.sim.fmu3 import elements as fmi3_elements
from orchestrator.sim.start_values import Pose, controller_start_values, plant_start_values
from plant import PLANT_FMU, load_airframe, plant_fmu

log = logging.getLogger(__name__)

PLANT = PLANT_FMU
CONTROLLER = CONTROLLER_FMU
SYSTEM = "ClosedLoop"
SSD_NAME = "SystemStructure.ssd"

NS_SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
NS_SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
NS_SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
NS_FP = "urn:fullpose:ssp:annotations"
STEP_ANNOTATION = "org.fullpose.fixedStepMaster"
# The Open Simulation Platform's annotation, which libcosim's SSP loader applies as the base
# step of its fixed-step algorithm.  libcosim reads the XML with prefixes taken literally
# (boost property_tree), so the prefix must be "osp" and the elements exactly these.
NS_OSP = "http://opensimulationplatform.com/SSP/OSPAnnotations"
OSP_ANNOTATION = "com.opensimulationplatform"
# OpenModelica's annotation on the system, which OMSimulator's C API and command line need to
# create the system at all (without it: "[NewSystem] internal error") and from which they
# take the fixed step of their master; its reader (pugixml) takes the prefixes literally, so
# the prefix must be "oms".  OMSimulator's Python API reads the same element.
NS_OMS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
OMS_ANNOTATION = "org.openmodelica"

_REFERENCES = ("pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref")

Connection = tuple[str, str, str, str]
Value = float | int | bool

FMI_VERSIONS = (2, 3)
SSP_VERSION = {2: "1.0", 3: "2.0"}
"""The SSP version an archive of FMI 2.0 / FMI 3.0 FMUs declares (SSP 1.0 knows neither the FMI
3.0 types nor arrays)."""
_SSV3_TYPE = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}


def check_fmi(fmi: object) -> int:
    """``fmi`` if it is 2 or 3, else a ValueError saying what each means."""
    if isinstance(fmi, int) and not isinstance(fmi, bool) and fmi in FMI_VERSIONS:
        return fmi
    raise ValueError(f"fmi must be 2 (the FMI 2.0 FMUs in an SSP 1.0 archive) or 3 (the FMI 3.0 "
                     f"FMUs in an SSP 2.0 archive), got {fmi!r}")


def fmi_of_md(md: ModelDescription) -> int:
    """2 or 3: the FMI version of a modelDescription."""
    return 3 if str(md.fmiVersion).startswith("3") else 2


def _shape(v: object) -> tuple[int, ...]:
    """An FMI 3.0 variable's array shape (() for a scalar and for every FMI 2.0 variable)."""
    return tuple(int(x) for x in (getattr(v, "shape", None) or ()))


def _variables(md: ModelDescription, causality: str) -> list[tuple[str, str]]:
    """(name, type) of the variables of ``causality``, the type with the array shape for FMI
    3.0 (``Float64[3]``); clocks are left out (the controller's ``sample`` belongs to Scheduled
    Execution; the archives use co-simulation)."""
    return [(v.name, v.type + (str(list(_shape(v))) if _shape(v) else ""))
            for v in md.modelVariables if v.causality == causality and v.type != "Clock"]


def connect_by_name(src: str, src_md: ModelDescription, dst: str,
                    dst_md: ModelDescription) -> tuple[list[Connection], list[str]]:
    """(connections from ``src``'s outputs to ``dst``'s inputs of the same names, in
    ``dst``'s order; ``dst``'s inputs no output of ``src`` is named like); a ValueError when
    two same-named variables differ in type."""
    outputs = dict(_variables(src_md, "output"))
    made: list[Connection] = []
    loose: list[str] = []
    for name, typ in _variables(dst_md, "input"):
        if name not in outputs:
            loose.append(name)
        elif outputs[name] != typ:
            raise ValueError(f"{src}.{name} is {outputs[name]} but {dst}.{name} is {typ}")
        else:
            made.append((src, name, dst, name))
    return made, loose


def connection_table(plant_md: ModelDescription,
                     controller_md: ModelDescription) -> list[Connection]:
    """(from component, from variable, to component, to variable), matched by name.

    Plant outputs to controller inputs first, then controller outputs to plant inputs, each
    in the order of the receiving FMU's modelDescription.  Inputs without a same-named output
    on the other side are logged (INFO); :func:`unconnected_inputs` returns them.
    """
    to_ctrl, loose_c = connect_by_name(PLANT, plant_md, CONTROLLER, controller_md)
    to_plant, loose_p = connect_by_name(CONTROLLER, controller_md, PLANT, plant_md)
    if loose_c:
        log.info("unconnected %s inputs: %s", CONTROLLER, ", ".join(loose_c))
    if loose_p:
        log.info("unconnected %s inputs: %s", PLANT, ", ".join(loose_p))
    return to_ctrl + to_plant


def element_connections(connections: Iterable[Connection],
                        mds: Mapping[str, ModelDescription]) -> list[Connection]:
    """The connections element by element, by FMI 2.0 names: an FMI 3.0 connection of two
    arrays (``pos`` -> ``pos``) becomes one per element (``pos[1]`` -> ``pos[1]``, ...,
    row-major); FMI 2.0 connections are that already.  The start values are computed on
    these (:func:`consistent_start`), so that they are one computation for both versions."""
    names: dict[str, dict[str, list[str]]] = {}
    for comp, md in mds.items():
        if fmi_of_md(md) == 3:
            by_var: dict[str, list[str]] = {}
            for e in fmi3_elements(md):
                by_var.setdefault(e.variable, []).append(e.name)
            names[comp] = by_var
    out: list[Connection] = []
    for fc, fv, tc, tv in connections:
        src = names[fc].get(fv, [fv]) if fc in names else [fv]
        dst = names[tc].get(tv, [tv]) if tc in names else [tv]
        out += [(fc, a, tc, b) for a, b in zip(src, dst, strict=True)]
    return out


def unconnected_inputs(plant_md: ModelDescription,
                       controller_md: ModelDescription) -> dict[str, list[str]]:
    """Inputs of each component that :func:`connection_table` leaves unconnected."""
    return {
        PLANT: connect_by_name(CONTROLLER, controller_md, PLANT, plant_md)[1],
        CONTROLLER: connect_by_name(PLANT, plant_md, CONTROLLER, controller_md)[1],
    }


# -- parameter values -------------------------------------------------------------------------


def _typed(md: ModelDescription, values: Mapping[str, Value]) -> list[tuple[str, str, Value]]:
    """(name, FMI type, value) in modelDescription order; unknown names are an error."""
    types = {v.name: v.type for v in md.modelVariables}
    unknown = sorted(set(values) - set(types))
    if unknown:
        raise ValueError(f"{md.modelName} has no variables {unknown}")
    out: list[tuple[str, str, Value]] = []
    for v in md.modelVariables:
        if v.name not in values:
            continue
        value = values[v.name]
        if v.type == "Real":
            x = float(value)
            if not math.isfinite(x):
                raise ValueError(f"{md.modelName}.{v.name} = {x} is not finite")
            out.append((v.name, "Real", x))
        elif v.type == "Integer":
            out.append((v.name, "Integer", int(value)))
        elif v.type == "Boolean":
            out.append((v.name, "Boolean", bool(value)))
        else:
            raise ValueError(f"{md.modelName}.{v.name}: type {v.type} is not exported")
    return out


def _start(e: Element) -> Value:
    """An FMI 3.0 element's start value from its modelDescription (0 when none is given)."""
    text = e.start if e.start is not None else "0"
    if e.type == "Real":
        return float(text)
    if e.type == "Integer":
        return int(text)
    return text in ("true", "1")


Array = tuple[str, str, list[Value], tuple[int, ...]]
"""An FMI 3.0 parameter value of an SSV 2.0: (variable, SSP type, values row-major, shape)."""


def _typed3(md: ModelDescription, values: Mapping[str, Value]) -> list[Array]:
    """``values`` (by FMI 2.0 element names, ``poly_A[2,3]``) as whole FMI 3.0 variables, in
    modelDescription order: every variable with an element in ``values``, its other elements
    at the FMU's start values; unknown names are an error."""
    els = fmi3_elements(md)
    known = {e.name for e in els}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"{md.modelName} has no variables {unknown}")
    shapes = {v.name: _shape(v) for v in md.modelVariables}
    groups: dict[str, list[Element]] = {}
    for e in els:
        groups.setdefault(e.variable, []).append(e)
    out: list[Array] = []
    for var, group in groups.items():
        if not any(e.name in values for e in group):
            continue
        vals: list[Value] = []
        for e in group:
            value = values[e.name] if e.name in values else _start(e)
            if e.type == "Real":
                x = float(value)
                if not math.isfinite(x):
                    raise ValueError(f"{md.modelName}.{e.name} = {x} is not finite")
                vals.append(x)
            elif e.type == "Integer":
                vals.append(int(value))
            else:
                vals.append(bool(value))
        out.append((var, _SSV3_TYPE[group[0].type], vals, shapes[var]))
    return out


def _initial_outputs(params: Mapping[str, Value], names: Iterable[str],
                     fmi: int = 2) -> dict[str, float]:
    """The plant's outputs after initialization with ``params`` (its trim at pos0), from the
    installed plant of FMI version ``fmi`` (names: FMI 2.0 element names)."""
    inst = Fmu3Instance(plant_fmu(3), PLANT) if fmi == 3 else FmuInstance(plant_fmu(), PLANT)
    with inst as fmu:
        fmu.initialize(parameters=params)
        return {n: float(fmu.get(n)) for n in names}


def component_parameters(airframe: str | Path = "paper_hexacopter",
                         pos0: Sequence[float] = (0.0, 0.0, -3.0),
                         connections: Iterable[Connection] = (),
                         euler0: Sequence[float] = (0.0, 0.0, 0.0), fmi: int = 2,
                         ) -> dict[str, dict[str, Value]]:
    """Start values per component (by FMI 2.0 variable name; ``connections`` element by
    element, :func:`element_connections`) for a hover at ``pos0``, ``euler0``; ``fmi``: the
    plant whose initialization gives the trim (FMI 2.0 or 3.0, the same numbers).

    One pose, written to both FMUs: the plant starts there (``pos0``, ``euler0``,
    ``init_trim = true``, and for its connected command inputs the trim it initialises to)
    and the controller holds it (``pos_ref = pos0``, ``euler_ref = euler0``, rates and
    accelerations 0), with the shared airframe numbers and S(0) and, for its connected
    measurement inputs, the plant's initial outputs.  An attitude the airframe cannot hold is
    refused by the plant's initialization (no hover trim), with its message.
    """
    pose = Pose.of(pos0, euler0)
    for what, v in (("pos0", pose.pos), ("euler0", pose.euler)):
        if not all(math.isfinite(x) for x in v):
            raise ValueError(f"{what} must be 3 finite numbers, got {v!r}")
    af = load_airframe(airframe)
    plant: dict[str, Value] = plant_start_values(af, pose, overrides={"init_trim": True})
    ctrl: dict[str, Value] = controller_start_values(af)
    held = {"pos_ref": pose.pos, "euler_ref": pose.euler}
    for ref in _REFERENCES:
        for i in range(3):
            ctrl[f"{ref}[{i + 1}]"] = held[ref][i] if ref in held else 0.0
    return consistent_start(plant, ctrl, connections, fmi)


def consistent_start(plant: Mapping[str, Value], ctrl: Mapping[str, Value],
                     connections: Iterable[Connection],
                     fmi: int = 2) -> dict[str, dict[str, Value]]:
    """Both FMUs' start values made consistent at t = 0 for a runner that initialises
    connected inputs from start values: the controller's connected measurement inputs get the
    plant's initial outputs (with ``plant`` set), the plant's connected command inputs the
    actuator state it initialises to (its trim).  ``connections`` element by element
    (:func:`element_connections`); ``fmi``: the plant initialised to find them."""
    conns = list(connections)
    measured = [fv for fc, fv, _, _ in conns if fc == PLANT]
    commanded = [tv for fc, _, tc, tv in conns if tc == PLANT and fc == CONTROLLER]
    # the plant's trim: its measured actuator states are what the commands must be
    trim_of = {n: n.replace("_cmd[", "[") for n in commanded}
    y0 = _initial_outputs(plant, sorted(set(measured) | set(trim_of.values())), fmi)
    plant_out, ctrl_out = dict(plant), dict(ctrl)
    ctrl_out.update({n: y0[n] for n in measured})
    plant_out.update({n: y0[trim_of[n]] for n in commanded})
    return {PLANT: plant_out, CONTROLLER: ctrl_out}


# -- XML ---------------------------------------------------------------------------------------


def _q(ns: str, tag: str) -> str:
    return f"{{{ns}}}{tag}"


def _num(x: float) -> str:
    return repr(float(x))


def _xml(root: etree._Element) -> bytes:
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def ssv_document(name: str, values: Sequence[tuple[str, str, Value]]) -> bytes:
    """An SSV 1.0 ParameterSet with the given (name, type, value) entries, in that order."""
    root = etree.Element(_q(NS_SSV, "ParameterSet"), nsmap={"ssv": NS_SSV},
                         version="1.0", name=name)
    params = etree.SubElement(root, _q(NS_SSV, "Parameters"))
    for var, typ, value in values:
        p = etree.SubElement(params, _q(NS_SSV, "Parameter"), name=var)
        if typ == "Real":
            text = _num(float(value))
        elif typ == "Integer":
            text = str(int(value))
        else:
            text = "true" if value else "false"
        etree.SubElement(p, _q(NS_SSV, typ), value=text)
    return _xml(root)


def _text(typ: str, value: Value) -> str:
    if typ in ("Real", "Float64"):
        return _num(float(value))
    if typ in ("Integer", "Int32"):
        return str(int(value))
    return "true" if value else "false"


def _dimensions(parent: etree._Element, shape: Sequence[int]) -> None:
    """SSP 2.0's ``ssc:Dimension size`` elements of an array connector or parameter."""
    for n in shape:
        etree.SubElement(parent, _q(NS_SSC, "Dimension"), size=str(n))


def ssv_document_v2(name: str, values: Sequence[Array]) -> bytes:
    """An SSV 2.0 ParameterSet of FMI 3.0 variables: one Parameter per (variable, type, values,
    shape), an array's values as one row-major list with its ``ssc:Dimension``s."""
    root = etree.Element(_q(NS_SSV, "ParameterSet"), nsmap={"ssv": NS_SSV, "ssc": NS_SSC},
                         version="2.0", name=name)
    params = etree.SubElement(root, _q(NS_SSV, "Parameters"))
    for var, typ, vals, shape in values:
        p = etree.SubElement(params, _q(NS_SSV, "Parameter"), name=var)
        etree.SubElement(p, _q(NS_SSV, typ), value=" ".join(_text(typ, x) for x in vals))
        _dimensions(p, shape)
    return _xml(root)


def ssd_document(name: str, mds: Mapping[str, ModelDescription],
                 connections: Sequence[Connection], ssv: Mapping[str, str],
                 step: float, stop_time: float) -> bytes:
    """The SystemStructure.ssd of the components ``mds`` (name -> modelDescription): SSP 1.0
    for FMI 2.0 FMUs, SSP 2.0 (array connectors, FMI 3.0 types) for FMI 3.0 ones."""
    fmi = _one_version(mds)
    root = etree.Element(_q(NS_SSD, "SystemStructureDescription"),
                         nsmap={"ssd": NS_SSD, "ssc": NS_SSC, "osp": NS_OSP, "oms": NS_OMS},
                         version=SSP_VERSION[fmi],
                         name=name,
                         generationTool="fullpose orchestrator.export.ssp")
    system = etree.SubElement(root, _q(NS_SSD, "System"), name=SYSTEM,
                              description="Multirotor plant flown by the full-pose controller")
    elements = etree.SubElement(system, _q(NS_SSD, "Elements"))
    connected_inputs = {(tc, tv) for _, _, tc, tv in connections}
    for comp, md in mds.items():
        el = etree.SubElement(elements, _q(NS_SSD, "Component"), name=comp,
                              type="application/x-fmu-sharedlibrary",
                              source=f"resources/{comp}.fmu")
        if fmi == 3:  # the plant's archive also has Model Exchange, the controller's SE
            el.set("implementation", "CoSimulation")
        conns = etree.SubElement(el, _q(NS_SSD, "Connectors"))
        for v in md.modelVariables:
            if v.type == "Clock":
                continue
            if v.causality == "output" or (
                    v.causality == "input" and (comp, v.name) in connected_inputs):
                c = etree.SubElement(conns, _q(NS_SSD, "Connector"), name=v.name,
                                     kind=v.causality)
                if fmi == 3:
                    etree.SubElement(c, _q(NS_SSC, v.type))  # Float64, Int32, Boolean
                    _dimensions(c, _shape(v))
                elif v.type in ("Real", "Integer", "Boolean", "String"):
                    etree.SubElement(c, _q(NS_SSC, v.type))  # optional: for readers
        if comp in ssv:
            bindings = etree.SubElement(el, _q(NS_SSD, "ParameterBindings"))
            etree.SubElement(bindings, _q(NS_SSD, "ParameterBinding"),
                             type="application/x-ssp-parameter-set", source=ssv[comp])
    links = etree.SubElement(system, _q(NS_SSD, "Connections"))
    for fc, fv, tc, tv in connections:
        etree.SubElement(links, _q(NS_SSD, "Connection"), startElement=fc, startConnector=fv,
                         endElement=tc, endConnector=tv)
    oms = etree.SubElement(etree.SubElement(system, _q(NS_SSD, "Annotations")),
                           _q(NS_SSC, "Annotation"), type=OMS_ANNOTATION)
    info = etree.SubElement(etree.SubElement(oms, _q(NS_OMS, "Annotations")),
                            _q(NS_OMS, "SimulationInformation"))
    # a weakly coupled system whose master steps every component at `step`
    etree.SubElement(info, _q(NS_OMS, "FixedStepMaster"), description="oms-ma",
                     stepSize=_num(step), relativeTolerance=_num(1e-4))
    exp = etree.SubElement(root, _q(NS_SSD, "DefaultExperiment"), startTime=_num(0.0),
                           stopTime=_num(stop_time))
    notes = etree.SubElement(exp, _q(NS_SSD, "Annotations"))
    osp = etree.SubElement(notes, _q(NS_SSC, "Annotation"), type=OSP_ANNOTATION)
    # declared on the root: libcosim takes an xmlns attribute on osp:Algorithm for an algorithm
    algorithm = etree.SubElement(osp, _q(NS_OSP, "Algorithm"))
    etree.SubElement(algorithm, _q(NS_OSP, "FixedStepAlgorithm"), baseStepSize=_num(step))
    note = etree.SubElement(notes, _q(NS_SSC, "Annotation"), type=STEP_ANNOTATION)
    etree.SubElement(note, _q(NS_FP, "FixedStepMaster"), nsmap={"fp": NS_FP},
                     stepSize=_num(step))
    return _xml(root)


# -- archive -----------------------------------------------------------------------------------


def export_ssp(path: Path, airframe: str | Path = "paper_hexacopter",
               pos0: Sequence[float] = (0.0, 0.0, -3.0), step: float = 0.002,
               stop_time: float = 10.0, euler0: Sequence[float] = (0.0, 0.0, 0.0),
               fmus: Path | None = None, fmi: int = 2) -> Path:
    """Write the closed loop hovering at ``pos0``, ``euler0`` as an SSP archive: SSP 1.0 with
    the FMI 2.0 FMUs, or with ``fmi=3`` SSP 2.0 with the FMI 3.0 ones.

    Returns its path; ``path`` gets the ``.ssp`` suffix if it has another one.  ``step`` and
    ``stop_time`` are recorded in the SSD's DefaultExperiment (libcosim applies both; for
    fmpy's runner pass :func:`fmpy_options`).  ``fmus``: a folder to take the FMUs from
    (:func:`fmu_file`), e.g. with binaries for every platform.  The output is deterministic:
    the same inputs (and FMUs) give identical bytes.
    """
    fmi = check_fmi(fmi)
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be positive, got {step}")
    if not (math.isfinite(stop_time) and stop_time > 0):
        raise ValueError(f"stop_time must be positive, got {stop_time}")
    data = {PLANT: fmu_file(PLANT, fmus, fmi).read_bytes(),
            CONTROLLER: fmu_file(CONTROLLER, fmus, fmi).read_bytes()}
    mds = {comp: read_model_description(io.BytesIO(b)) for comp, b in data.items()}
    connections = connection_table(mds[PLANT], mds[CONTROLLER])
    values = component_parameters(airframe, pos0, element_connections(connections, mds), euler0,
                                  fmi)
    af_name = load_airframe(airframe).name
    return write_archive(path, f"fullpose_{af_name}_hover", data, mds, connections, values,
                         step, stop_time, af_name)


def fmu_file(model: str, folder: Path | None = None, fmi: int = 2) -> Path:
    """The FMU ``model`` (``MultirotorPlant``, ``FullPoseController``, ``ScenarioSignals``) of
    FMI version ``fmi`` from ``folder`` (e.g. ``fullpose build-fmus [--fmi 3] --out`` with
    binaries for every platform), else the installed one; a missing file is a
    FileNotFoundError naming it, an FMU of the other FMI version a ValueError."""
    fmi = check_fmi(fmi)
    if folder is None:
        found = {PLANT: plant_fmu, CONTROLLER: controller_fmu, SIGNALS_FMU: signals_fmu}
        return Path(found[model](fmi))
    path = Path(folder) / f"{model}.fmu"
    flag = " --fmi 3" if fmi == 3 else ""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such FMU (--fmus {folder} must hold "
                                f"{PLANT}.fmu, {CONTROLLER}.fmu and, for a scenario, "
                                f"ScenarioSignals.fmu, as `fullpose build-fmus{flag} --out` "
                                "writes)")
    found_fmi = fmi_of_md(read_model_description(str(path), validate=False))
    if found_fmi != fmi:
        raise ValueError(f"{path} is an FMI {found_fmi}.0 FMU, but the archive is of FMI {fmi}.0 "
                         f"FMUs: export with --fmi {found_fmi}, or take FMUs built with "
                         f"`fullpose build-fmus{flag} --out DIR`")
    return path


def _one_version(mds: Mapping[str, ModelDescription]) -> int:
    """The FMI version all components share (an archive mixes none)."""
    found = {comp: fmi_of_md(md) for comp, md in mds.items()}
    if len(set(found.values())) != 1:
        raise ValueError("the components are of different FMI versions: "
                         + ", ".join(f"{c} FMI {v}.0" for c, v in found.items()))
    return next(iter(found.values()))


def write_archive(path: Path, name: str, fmus: Mapping[str, bytes],
                  mds: Mapping[str, ModelDescription], connections: Sequence[Connection],
                  values: Mapping[str, Mapping[str, Value]], step: float, stop_time: float,
                  label: str) -> Path:
    """Write an SSP archive of the components ``fmus`` (name -> FMU bytes, in SSD order)
    connected by ``connections``, one SSV per component of ``values`` (by FMI 2.0 element
    names, named ``"<component> (<label>)"``), the step and stop time in the
    DefaultExperiment; returns its path (``.ssp`` suffix added when missing).  SSP 1.0 for
    FMI 2.0 FMUs, SSP 2.0 for FMI 3.0 ones (``values`` grouped into whole variables).
    Deterministic; written whole or not at all (a temporary file renamed into place)."""
    path = Path(path)
    if path.suffix != ".ssp":
        path = path.with_suffix(".ssp")
    fmi = _one_version(mds)
    ssv_files = {comp: f"resources/{comp}.ssv" for comp in fmus if comp in values}
    entries: dict[str, tuple[bytes, int]] = {}
    for comp, data in fmus.items():
        if comp in values:
            title = f"{comp} ({label})"
            doc = (ssv_document_v2(title, _typed3(mds[comp], values[comp])) if fmi == 3
                   else ssv_document(title, _typed(mds[comp], values[comp])))
            entries[ssv_files[comp]] = (doc, zipfile.ZIP_DEFLATED)
        entries[f"resources/{comp}.fmu"] = (data, zipfile.ZIP_STORED)
    ssd = ssd_document(name, mds, connections, ssv_files, step, stop_time)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        add_entry(zf, SSD_NAME, ssd, zipfile.ZIP_DEFLATED)
        for entry in sorted(entries):
            data, compress = entries[entry]
            add_entry(zf, entry, data, compress)
    path.parent.mkdir(parents=True, exist_ok=True)
    part = path.with_name(path.name + ".part")
    part.write_bytes(buf.getvalue())
    part.replace(path)
    return path


def parameter_set(ssp_path: str | Path) -> ParameterSet:
    """fmpy's ``parameter_set`` for ``simulate_ssp`` from the archive's own ParameterBindings.

    Read with fmpy's ``read_ssd`` (which validates the SSD and each SSV); names are made
    hierarchical (``<component>.<variable>``, after the binding's prefix, SSP 1.0 semantics)
    and values typed (bool/int/float), since fmpy applies Booleans as ``value != 0.0``.
    Later bindings override earlier ones, as the standard says.
    """
    ssd = read_ssd(str(ssp_path))
    merged: dict[str, Parameter] = {}

    def walk(element: object, here: str) -> None:
        for binding in getattr(element, "parameterBindings", []):
            prefix = binding.prefix or ""
            for pset in binding.parameterValues:
                for p in pset.parameters:
                    full = here + prefix + p.name
                    merged[full] = Parameter(name=full, type=p.type, value=_parse(p),
                                             unit=p.unit)
        if isinstance(element, System):
            for child in element.elements:
                walk(child, f"{here}{child.name}.")

    walk(ssd.system, "")
    return ParameterSet(name=ssd.name, parameters=list(merged.values()))


def experiment(ssp_path: str | Path) -> tuple[float, float, float]:
    """(start time, stop time, step size) the archive's DefaultExperiment records.

    The step is read from the OSP annotation (what libcosim applies), else from ours.
    """
    with zipfile.ZipFile(ssp_path) as zf:
        root = etree.fromstring(zf.read(SSD_NAME))
    ns = {"ssd": NS_SSD, "ssc": NS_SSC, "osp": NS_OSP, "fp": NS_FP}
    exp = root.find("ssd:DefaultExperiment", ns)
    if exp is None:
        raise ValueError(f"{ssp_path}: {SSD_NAME} has no DefaultExperiment")
    steps = exp.xpath("ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm"
                      "/@baseStepSize | ssd:Annotations/ssc:Annotation/fp:FixedStepMaster"
                      "/@stepSize", namespaces=ns)
    if not steps:
        raise ValueError(f"{ssp_path}: {SSD_NAME} records no step size")
    return (float(exp.get("startTime", 0.0)), float(exp.get("stopTime")), float(steps[0]))


def ssp_version(ssp_path: str | Path) -> str:
    """The ``version`` its SSD declares: "1.0" (FMI 2.0 FMUs) or "2.0" (FMI 3.0 ones)."""
    with zipfile.ZipFile(ssp_path) as zf:
        return str(etree.fromstring(zf.read(SSD_NAME)).get("version"))


def fmpy_options(ssp_path: str | Path) -> dict[str, object]:
    """Keyword arguments that make fmpy's runner play the archive as recorded.

    fmpy 0.3.x's ``simulate_ssp`` reads neither the DefaultExperiment nor the parameter
    bindings from an archive (its step defaults to stop_time / 100, 0.1 s for a 10 s
    experiment, far beyond the controller's 2 ms sample time): ``simulate_ssp(path,
    **fmpy_options(path))`` passes the recorded start, stop and step and the bindings.
    """
    version = ssp_version(ssp_path)
    if version != "1.0":
        raise ValueError(f"{ssp_path} is an SSP {version} archive (FMI 3.0 FMUs): fmpy's SSP "
                         "runner reads SSP 1.0 with FMI 2.0 FMUs only; play it with "
                         "orchestrator.export.ssp_replay.replay_ssp")
    start, stop, step = experiment(ssp_path)
    return {"start_time": start, "stop_time": stop, "step_size": step,
            "parameter_set": parameter_set(ssp_path)}


def _parse(p: object) -> Value | str:
    typ, text = getattr(p, "type", None), str(getattr(p, "value", ""))
    if typ == "Real":
        return float(text)
    if typ == "Integer":
        return int(text)
    if typ == "Boolean":
        return text.strip() in ("true", "1")
    return text
