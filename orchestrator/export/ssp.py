"""Export the closed loop (plant FMU + controller FMU) as an SSP 1.0 archive.

    export_ssp(Path("hover.ssp"))                     # paper hexacopter hovering at [0, 0, -3]
    export_ssp(Path("quad.ssp"), airframe="quadrotor")

Archive layout (zip, entries in this order, all timestamps 1980-01-01 00:00:00)::

    SystemStructure.ssd                 system "ClosedLoop": both components, their connectors,
                                        the connections, one ParameterBinding per component
    resources/FullPoseController.fmu    the installed FMUs, byte for byte (stored, not
    resources/MultirotorPlant.fmu       recompressed)
    resources/FullPoseController.ssv    one SSV parameter set per component, bare FMU variable
    resources/MultirotorPlant.ssv       names (the binding sits on the component)

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


def _variables(md: ModelDescription, causality: str) -> list[tuple[str, str]]:
    return [(v.name, v.type) for v in md.modelVariables if v.causality == causality]


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


def _initial_outputs(params: Mapping[str, Value], names: Iterable[str]) -> dict[str, float]:
    """The plant's outputs after initialization with ``params`` (its trim at pos0)."""
    with FmuInstance(plant_fmu(), PLANT) as fmu:
        fmu.initialize(parameters=params)
        return {n: float(fmu.get(n)) for n in names}


def component_parameters(airframe: str | Path = "paper_hexacopter",
                         pos0: Sequence[float] = (0.0, 0.0, -3.0),
                         connections: Iterable[Connection] = (),
                         euler0: Sequence[float] = (0.0, 0.0, 0.0),
                         ) -> dict[str, dict[str, Value]]:
    """Start values per component (by FMU variable name) for a hover at ``pos0``, ``euler0``.

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
    return consistent_start(plant, ctrl, connections)


def consistent_start(plant: Mapping[str, Value], ctrl: Mapping[str, Value],
                     connections: Iterable[Connection]) -> dict[str, dict[str, Value]]:
    """Both FMUs' start values made consistent at t = 0 for a runner that initialises
    connected inputs from start values: the controller's connected measurement inputs get the
    plant's initial outputs (with ``plant`` set), the plant's connected command inputs the
    actuator state it initialises to (its trim)."""
    conns = list(connections)
    measured = [fv for fc, fv, _, _ in conns if fc == PLANT]
    commanded = [tv for fc, _, tc, tv in conns if tc == PLANT and fc == CONTROLLER]
    # the plant's trim: its measured actuator states are what the commands must be
    trim_of = {n: n.replace("_cmd[", "[") for n in commanded}
    y0 = _initial_outputs(plant, sorted(set(measured) | set(trim_of.values())))
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


def ssd_document(name: str, mds: Mapping[str, ModelDescription],
                 connections: Sequence[Connection], ssv: Mapping[str, str],
                 step: float, stop_time: float) -> bytes:
    """The SystemStructure.ssd (SSP 1.0) of the components ``mds`` (name -> modelDescription)."""
    root = etree.Element(_q(NS_SSD, "SystemStructureDescription"),
                         nsmap={"ssd": NS_SSD, "ssc": NS_SSC, "osp": NS_OSP, "oms": NS_OMS},
                         version="1.0",
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
        conns = etree.SubElement(el, _q(NS_SSD, "Connectors"))
        for v in md.modelVariables:
            if v.causality == "output" or (
                    v.causality == "input" and (comp, v.name) in connected_inputs):
                c = etree.SubElement(conns, _q(NS_SSD, "Connector"), name=v.name,
                                     kind=v.causality)
                if v.type in ("Real", "Integer", "Boolean", "String"):
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
               fmus: Path | None = None) -> Path:
    """Write the closed loop hovering at ``pos0``, ``euler0`` as an SSP 1.0 archive.

    Returns its path; ``path`` gets the ``.ssp`` suffix if it has another one.  ``step`` and
    ``stop_time`` are recorded in the SSD's DefaultExperiment (libcosim applies both; for
    fmpy's runner pass :func:`fmpy_options`).  ``fmus``: a folder to take the FMUs from
    (:func:`fmu_file`), e.g. with binaries for every platform.  The output is deterministic:
    the same inputs (and FMUs) give identical bytes.
    """
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be positive, got {step}")
    if not (math.isfinite(stop_time) and stop_time > 0):
        raise ValueError(f"stop_time must be positive, got {stop_time}")
    data = {PLANT: fmu_file(PLANT, fmus).read_bytes(),
            CONTROLLER: fmu_file(CONTROLLER, fmus).read_bytes()}
    mds = {comp: read_model_description(io.BytesIO(b)) for comp, b in data.items()}
    connections = connection_table(mds[PLANT], mds[CONTROLLER])
    values = component_parameters(airframe, pos0, connections, euler0)
    af_name = load_airframe(airframe).name
    return write_archive(path, f"fullpose_{af_name}_hover", data, mds, connections, values,
                         step, stop_time, af_name)


def fmu_file(model: str, folder: Path | None = None) -> Path:
    """The FMU ``model`` (``MultirotorPlant``, ``FullPoseController``, ``ScenarioSignals``)
    from ``folder`` (e.g. ``fullpose build-fmus --out`` with binaries for every platform),
    else the installed one; a missing file is a FileNotFoundError naming it."""
    if folder is None:
        found = {PLANT: plant_fmu, CONTROLLER: controller_fmu, SIGNALS_FMU: signals_fmu}
        return Path(found[model]())
    path = Path(folder) / f"{model}.fmu"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such FMU (--fmus {folder} must hold "
                                f"{PLANT}.fmu, {CONTROLLER}.fmu and, for a scenario, "
                                "ScenarioSignals.fmu, as `fullpose build-fmus --out` writes)")
    return path


def write_archive(path: Path, name: str, fmus: Mapping[str, bytes],
                  mds: Mapping[str, ModelDescription], connections: Sequence[Connection],
                  values: Mapping[str, Mapping[str, Value]], step: float, stop_time: float,
                  label: str) -> Path:
    """Write an SSP archive of the components ``fmus`` (name -> FMU bytes, in SSD order)
    connected by ``connections``, one SSV per component of ``values`` (named
    ``"<component> (<label>)"``), the step and stop time in the DefaultExperiment; returns
    its path (``.ssp`` suffix added when missing).  Deterministic; written whole or not at
    all (a temporary file renamed into place)."""
    path = Path(path)
    if path.suffix != ".ssp":
        path = path.with_suffix(".ssp")
    ssv_files = {comp: f"resources/{comp}.ssv" for comp in fmus if comp in values}
    entries: dict[str, tuple[bytes, int]] = {}
    for comp, data in fmus.items():
        if comp in values:
            doc = ssv_document(f"{comp} ({label})", _typed(mds[comp], values[comp]))
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


def fmpy_options(ssp_path: str | Path) -> dict[str, object]:
    """Keyword arguments that make fmpy's runner play the archive as recorded.

    fmpy 0.3.x's ``simulate_ssp`` reads neither the DefaultExperiment nor the parameter
    bindings from an archive (its step defaults to stop_time / 100, 0.1 s for a 10 s
    experiment, far beyond the controller's 2 ms sample time): ``simulate_ssp(path,
    **fmpy_options(path))`` passes the recorded start, stop and step and the bindings.
    """
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
