"""Play an exported SSP archive (``fullpose export-ssp``) with a fixed-step Jacobi master on
fmpy's FMU classes: SSP 1.0 with FMI 2.0 FMUs, and SSP 2.0 with FMI 3.0 FMUs, whose vectors
are array connectors (``orchestrator.export.ssp``).

    result = replay_ssp("s1.ssp")                      # the archive's start, stop and step
    result = replay_ssp("s1_fmi3.ssp", stop_time=1.0)  # any of them overridden
    result["MultirotorPlant.pos[3]"]                   # NumPy structured array

The player exists because the SSP runners at hand read SSP 1.0 with FMI 2.0 FMUs only
(fmpy 0.3.x's ``simulate_ssp``, libcosim) or cannot play our FMI 3.0 archive (OMSimulator
3.0.0: docs/orchestrator.md).  It does what an SSP importer does, from the archive alone:

* reads ``SystemStructure.ssd`` (version 1.0 or 2.0): the components (FMUs in the archive,
  co-simulation), their connectors (name, kind, type, ``ssc:Dimension`` sizes), the
  connections, each component's ParameterBindings (SSV files in the archive, an optional
  ``prefix``), the DefaultExperiment and the step annotation
  (:func:`orchestrator.export.ssp.experiment`);
* checks them against the FMUs' modelDescriptions: a connector names a variable of its FMU,
  its kind is the variable's causality, its type and dimensions the variable's; a connection
  goes from an output to an input of the same type and shape, each input fed once; a
  parameter names a variable, with as many values (row-major) as it has elements.  What an
  archive of ours never holds (nested systems, system connectors, ``startIndices`` /
  ``endIndices``, inline parameter values, other connector kinds, types beyond
  Real/Float64, Integer/Int32 and Boolean) is refused with a ValueError saying so;
* instantiates every component (FMI 2.0: ``fmi2Instantiate``, ``fmi2SetupExperiment`` at the
  start time; FMI 3.0: ``fmi3InstantiateCoSimulation`` without Event Mode), sets its
  parameter values (FMI 3.0: one ``fmi3SetFloat64``/``Int32``/``Boolean`` per variable, the
  whole array), then enters and exits initialization at the start time;
* steps every component from t_k = start + k * step by step (Jacobi): at k = 0 from the
  inputs it was initialised with (their start values: what libcosim and OMSimulator do), at
  k > 0 with each connected input set to the output it is connected to after step k - 1;
  inputs are set and outputs read one call per type and component (FMI 3.0: the whole
  arrays, ``nValues`` their total size).

The result has a ``time`` column (t_0 .. t_n) and one column per output element of every
component, named ``<component>.<element>`` with FMI 2.0 element names (the FMI 3.0 array
``pos`` as ``pos[1]`` .. ``pos[3]``, ``poly_A`` as ``poly_A[1,1]`` ..., row-major): row 0
holds the outputs after initialization, row k those after step k.  The same names for both
versions, so that the replays of the FMI 2.0 and FMI 3.0 archives of one export compare
column by column (tests/test_orchestrator/test_ssp_fmi3.py: equal to the bit).  An FMU's
error is a RuntimeError naming the component, the call and the FMU's own messages.
"""

from __future__ import annotations

import functools
import itertools
import logging
import math
import tempfile
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np
from fmpy import calloc, free, read_model_description
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.fmi3 import FMU3Slave
from lxml import etree

from orchestrator.export.ssp import NS_SSC, NS_SSD, NS_SSV, SSD_NAME, experiment

log = logging.getLogger(__name__)

_NS = {"ssd": NS_SSD, "ssc": NS_SSC, "ssv": NS_SSV}
FMU_TYPE = "application/x-fmu-sharedlibrary"
PARAMETER_SET_TYPE = "application/x-ssp-parameter-set"
_FAMILY = {"Real": "float", "Float64": "float", "Integer": "int", "Int32": "int",
           "Boolean": "bool"}
"""The SSP and FMI type names played, by the kind of value they hold."""
_DTYPE = {"float": np.float64, "int": np.int32, "bool": np.bool_}
_STATUS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")

Value = float | int | bool


@dataclass(frozen=True)
class Connector:
    """A component's connector as the SSD declares it (``type`` None: not given)."""

    name: str
    kind: str
    type: str | None
    shape: tuple[int, ...]


@dataclass(frozen=True)
class Parameter:
    """A parameter value of a bound SSV: its name (with the binding's prefix), type, value
    texts (row-major) and ``ssc:Dimension`` sizes (None: not given)."""

    name: str
    type: str
    values: tuple[str, ...]
    shape: tuple[int, ...] | None


@dataclass
class Component:
    """An FMU component: its name, its source in the archive, connectors and parameters (in
    binding order: a later value of a name overrides an earlier one)."""

    name: str
    source: str
    connectors: list[Connector] = field(default_factory=list)
    parameters: list[Parameter] = field(default_factory=list)


@dataclass
class Archive:
    """What the player takes from an archive."""

    version: str
    name: str
    components: list[Component]
    connections: list[tuple[str, str, str, str]]
    start: float
    stop: float
    step: float


def _shape(el: etree._Element, where: str) -> tuple[int, ...]:
    sizes = []
    for d in el.findall("ssc:Dimension", _NS):
        if d.get("size") is None:
            raise ValueError(f"{where}: a Dimension without a size (sizeConnector) is not "
                             "played")
        sizes.append(int(d.get("size")))
    return tuple(sizes)


def _typed_child(el: etree._Element, ns: str) -> etree._Element | None:
    for child in el:
        if isinstance(child.tag, str) and etree.QName(child).namespace == ns \
                and etree.QName(child).localname not in ("Dimension", "Annotations",
                                                         "Clock", "ConnectorGeometry"):
            return child
    return None


def _refuse(el: etree._Element, path: str, what: str, where: str) -> None:
    if el.find(path, _NS) is not None:
        raise ValueError(f"{where}: {what} is not played (an export-ssp archive has none)")


def _read_ssv(data: bytes, prefix: str, where: str) -> list[Parameter]:
    root = etree.fromstring(data)
    if root.tag != f"{{{NS_SSV}}}ParameterSet":
        raise ValueError(f"{where}: not an SSV ParameterSet")
    out = []
    for p in root.findall("ssv:Parameters/ssv:Parameter", _NS):
        name = p.get("name")
        typed = _typed_child(p, NS_SSV)
        if typed is None:
            raise ValueError(f"{where}: parameter {name} has no type")
        typ = etree.QName(typed).localname
        if typ not in _FAMILY:
            raise ValueError(f"{where}: parameter {name} is of type {typ}, which is not played "
                             f"(played: {', '.join(_FAMILY)})")
        dims = _shape(p, f"{where}: parameter {name}")
        out.append(Parameter(prefix + name, typ, tuple(str(typed.get("value", "")).split()),
                             dims if p.find("ssc:Dimension", _NS) is not None else None))
    return out


def read_archive(path: str | Path) -> Archive:
    """The components, connections, parameter values and experiment of an SSP archive (the
    SSD and its SSVs read, nothing checked against the FMUs yet)."""
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
        if SSD_NAME not in names:
            raise ValueError(f"{path}: no {SSD_NAME}")
        root = etree.fromstring(zf.read(SSD_NAME))
        if root.tag != f"{{{NS_SSD}}}SystemStructureDescription":
            raise ValueError(f"{path}: {SSD_NAME} is no SSP SystemStructureDescription")
        version = str(root.get("version"))
        if version not in ("1.0", "2.0"):
            raise ValueError(f"{path}: SSP version {version} (played: 1.0, 2.0)")
        system = root.find("ssd:System", _NS)
        if system is None:
            raise ValueError(f"{path}: {SSD_NAME} has no System")
        where = f"{path}: system {system.get('name')}"
        _refuse(system, "ssd:Connectors", "a connector of the system", where)
        _refuse(system, "ssd:ParameterBindings", "a parameter binding of the system", where)
        _refuse(system, "ssd:Elements/ssd:System", "a nested system", where)
        _refuse(system, "ssd:Elements/ssd:SignalDictionaryReference", "a signal dictionary",
                where)
        components = []
        for el in system.findall("ssd:Elements/ssd:Component", _NS):
            name = str(el.get("name"))
            here = f"{path}: component {name}"
            if el.get("type", FMU_TYPE) != FMU_TYPE:
                raise ValueError(f"{here}: type {el.get('type')} (played: {FMU_TYPE})")
            if el.get("implementation", "any") not in ("any", "CoSimulation"):
                raise ValueError(f"{here}: implementation {el.get('implementation')} (played: "
                                 "CoSimulation)")
            source = str(el.get("source"))
            if source not in names:
                raise ValueError(f"{here}: its source {source} is not in the archive")
            comp = Component(name, source)
            for c in el.findall("ssd:Connectors/ssd:Connector", _NS):
                typed = _typed_child(c, NS_SSC)
                typ = None if typed is None else etree.QName(typed).localname
                if typ is not None and typ not in _FAMILY:
                    raise ValueError(f"{here}: connector {c.get('name')} is of type {typ}, "
                                     f"which is not played (played: {', '.join(_FAMILY)})")
                comp.connectors.append(Connector(str(c.get("name")), str(c.get("kind")), typ,
                                                 _shape(c, f"{here}: connector {c.get('name')}")))
            for b in el.findall("ssd:ParameterBindings/ssd:ParameterBinding", _NS):
                if b.get("type", PARAMETER_SET_TYPE) != PARAMETER_SET_TYPE:
                    raise ValueError(f"{here}: a parameter binding of type {b.get('type')}")
                src = b.get("source")
                if src is None:
                    raise ValueError(f"{here}: inline parameter values are not played")
                if b.get("sourceBase", "SSD") != "SSD":
                    raise ValueError(f"{here}: a parameter binding relative to the component")
                entry = str(PurePosixPath(src))
                if entry not in names:
                    raise ValueError(f"{here}: its parameter set {src} is not in the archive")
                comp.parameters += _read_ssv(zf.read(entry), b.get("prefix", ""),
                                             f"{path}: {entry}")
            components.append(comp)
        connections = []
        for c in system.findall("ssd:Connections/ssd:Connection", _NS):
            ends = (c.get("startElement"), c.get("startConnector"), c.get("endElement"),
                    c.get("endConnector"))
            if ends[0] is None or ends[2] is None:
                raise ValueError(f"{where}: a connection to a system connector is not played")
            if c.get("startIndices") is not None or c.get("endIndices") is not None:
                raise ValueError(f"{where}: a connection of array elements (startIndices, "
                                 "endIndices) is not played")
            connections.append((str(ends[0]), str(ends[1]), str(ends[2]), str(ends[3])))
    try:
        start, stop, step = experiment(path)
    except ValueError:  # no DefaultExperiment or no step annotation: the caller gives them
        start, stop, step = 0.0, math.nan, math.nan
    return Archive(version, str(root.get("name")), components, connections, start, stop, step)


def element_names(name: str, shape: Sequence[int]) -> list[str]:
    """``pos``, (3,) -> ``pos[1]``, ``pos[2]``, ``pos[3]``; ``A``, (2, 2) -> ``A[1,1]``,
    ``A[1,2]``, ``A[2,1]``, ``A[2,2]`` (row-major, FMI 2.0's names); a scalar keeps its name."""
    if not shape:
        return [name]
    return [f"{name}[{','.join(str(i + 1) for i in idx)}]"
            for idx in itertools.product(*(range(n) for n in shape))]


def _parse(text: str, family: str) -> Value:
    if family == "float":
        return float(text)
    if family == "int":
        return int(text)
    if text not in ("true", "false", "1", "0"):
        raise ValueError(f"{text!r} is not a Boolean")
    return text in ("true", "1")


@dataclass(frozen=True)
class _Var:
    vr: int
    family: str
    shape: tuple[int, ...]
    causality: str

    @property
    def size(self) -> int:
        return math.prod(self.shape)


class _Unit:
    """One instantiated component: its variables, typed get/set of whole variables, step."""

    def __init__(self, comp: Component, folder: Path, start: float) -> None:
        self.name = comp.name
        self.messages: list[tuple[str, str]] = []
        md = read_model_description(str(folder / "modelDescription.xml"), validate=False)
        if md.coSimulation is None:
            raise ValueError(f"{comp.name}: {comp.source} provides no co-simulation")
        self.fmi = 3 if str(md.fmiVersion).startswith("3") else 2
        self.vars: dict[str, _Var] = {}
        for v in md.modelVariables:
            family = _FAMILY.get(v.type)
            if family is not None and v.causality != "independent":
                shape = tuple(int(x) for x in (getattr(v, "shape", None) or ()))
                self.vars[v.name] = _Var(int(v.valueReference), family, shape,
                                         str(v.causality))
        kwargs = {"guid": md.guid, "unzipDirectory": str(folder),
                  "modelIdentifier": md.coSimulation.modelIdentifier, "instanceName": comp.name}
        self.slave: Any
        if self.fmi == 3:
            self.slave = FMU3Slave(**kwargs)
            self._log3 = self._on_log3  # kept alive with the instance
            self._call("fmi3InstantiateCoSimulation",
                       lambda: self.slave.instantiate(logMessage=self._log3))
        else:
            self._callbacks = fmi2CallbackFunctions()
            self._callbacks.logger = fmi2CallbackLoggerTYPE(self._on_log2)
            self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            self.slave = FMU2Slave(**kwargs)
            self._call("fmi2Instantiate",
                       lambda: self.slave.instantiate(callbacks=self._callbacks))
            self._call("fmi2SetupExperiment", lambda: self.slave.setupExperiment(startTime=start))

    # -- messages and failures -------------------------------------------------------

    def _keep(self, status: int, message: bytes) -> None:
        name = _STATUS[status] if 0 <= status < len(_STATUS) else str(status)
        text = message.decode(errors="replace") if message else ""
        self.messages.append((name, text))
        level = logging.INFO if name == "OK" else logging.WARNING
        log.log(level, "%s [%s] %s", self.name, name, text)

    def _on_log2(self, env: object, name: bytes, status: int, category: bytes,
                 message: bytes) -> None:
        self._keep(status, message.replace(b"%%", b"%") if message else b"")

    def _on_log3(self, env: object, status: int, category: bytes, message: bytes) -> None:
        self._keep(status, message)

    def _call(self, what: str, fn: Callable[[], Any]) -> Any:
        seen = len(self.messages)
        try:
            return fn()
        except Exception as e:  # fmpy's FMICallException, or a bare Exception for NULL
            said = [m for s, m in self.messages[seen:] if s in ("DISCARD", "ERROR", "FATAL")]
            raise RuntimeError(f"{self.name}: {what} failed: "
                               + ("; ".join(said) if said else str(e))) from None

    # -- values ------------------------------------------------------------------

    def set_values(self, items: Sequence[tuple[_Var, Sequence[Value]]], what: str) -> None:
        """Set whole variables, one call per type."""
        for family in ("float", "int", "bool"):
            chosen = [(v, vals) for v, vals in items if v.family == family]
            if not chosen:
                continue
            vrs = [v.vr for v, _ in chosen]
            flat = [x for _, vals in chosen for x in vals]
            self._call(what, functools.partial(self._set, family, vrs, flat))

    def _set(self, family: str, vrs: list[int], flat: list[Value]) -> None:
        s = self.slave
        if family == "float":
            (s.setFloat64 if self.fmi == 3 else s.setReal)(vrs, [float(x) for x in flat])
        elif family == "int":
            (s.setInt32 if self.fmi == 3 else s.setInteger)(vrs, [int(x) for x in flat])
        else:
            s.setBoolean(vrs, [bool(x) for x in flat])

    def get_values(self, chosen: Sequence[_Var], family: str) -> list[Value]:
        """The values of whole variables of one type, in one call, concatenated."""
        s = self.slave
        vrs = [v.vr for v in chosen]
        if self.fmi == 3:
            n = sum(v.size for v in chosen)
            fn = {"float": s.getFloat64, "int": s.getInt32, "bool": s.getBoolean}[family]
            return list(self._call(f"reading {family} outputs", lambda: fn(vrs, n)))
        fn = {"float": s.getReal, "int": s.getInteger, "bool": s.getBoolean}[family]
        return list(self._call(f"reading {family} outputs", lambda: fn(vrs)))

    def step(self, t: float, h: float) -> None:
        """One communication step from t by h."""
        if self.fmi == 3:
            out = self._call(f"fmi3DoStep at t = {t:.6g} s", lambda: self.slave.doStep(
                currentCommunicationPoint=t, communicationStepSize=h))
            if out[1] or out[2]:
                raise RuntimeError(f"{self.name}: fmi3DoStep at t = {t:.6g} s ended the "
                                   "simulation or returned early")
        else:
            self._call(f"fmi2DoStep at t = {t:.6g} s", lambda: self.slave.doStep(
                currentCommunicationPoint=t, communicationStepSize=h))

    def initialize(self, start: float) -> None:
        """Enter and exit initialization at the start time."""
        v = self.fmi
        self._call(f"fmi{v}EnterInitializationMode",
                   lambda: self.slave.enterInitializationMode(startTime=start) if v == 3
                   else self.slave.enterInitializationMode())
        self._call(f"fmi{v}ExitInitializationMode", self.slave.exitInitializationMode)

    def close(self) -> None:
        """Terminate (when legal) and free the instance."""
        try:
            self.slave.terminate()
        except Exception:  # after an error terminate is illegal; freeing is what matters
            pass
        self.slave.freeInstance()


def _check(units: dict[str, _Unit], archive: Archive) -> dict[tuple[str, str], _Var]:
    """Every connector against its FMU's variable; the connections against the connectors;
    returns the connectors' variables by (component, connector)."""
    out: dict[tuple[str, str], _Var] = {}
    declared: dict[tuple[str, str], Connector] = {}
    for comp in archive.components:
        unit = units[comp.name]
        for c in comp.connectors:
            here = f"connector {comp.name}.{c.name}"
            v = unit.vars.get(c.name)
            if v is None:
                raise ValueError(f"{here}: {comp.name} has no variable {c.name} of a played "
                                 "type")
            if c.kind not in ("input", "output"):
                raise ValueError(f"{here}: kind {c.kind} (played: input, output)")
            if c.kind != v.causality:
                raise ValueError(f"{here}: kind {c.kind}, but the variable's causality is "
                                 f"{v.causality}")
            if c.type is not None and _FAMILY[c.type] != v.family:
                raise ValueError(f"{here}: type {c.type}, but the variable holds {v.family}")
            if c.shape != v.shape:
                raise ValueError(f"{here}: dimensions {list(c.shape)}, but the variable's are "
                                 f"{list(v.shape)}")
            out[comp.name, c.name] = v
            declared[comp.name, c.name] = c
    fed: set[tuple[str, str]] = set()
    for fc, fv, tc, tv in archive.connections:
        here = f"connection {fc}.{fv} -> {tc}.{tv}"
        a, b = declared.get((fc, fv)), declared.get((tc, tv))
        if a is None or b is None:
            raise ValueError(f"{here}: an end is no declared connector")
        if (a.kind, b.kind) != ("output", "input"):
            raise ValueError(f"{here}: from {a.kind} to {b.kind} (played: output to input)")
        va, vb = out[fc, fv], out[tc, tv]
        if va.family != vb.family or va.shape != vb.shape:
            raise ValueError(f"{here}: {va.family}{list(va.shape)} to {vb.family}"
                             f"{list(vb.shape)}")
        if (tc, tv) in fed:
            raise ValueError(f"{here}: {tc}.{tv} is fed twice")
        fed.add((tc, tv))
    return out


def _parameters(unit: _Unit, comp: Component) -> list[tuple[_Var, list[Value]]]:
    """The component's parameter values, checked against its variables (the last of a name
    wins), in binding order."""
    chosen: dict[str, tuple[_Var, list[Value]]] = {}
    for p in comp.parameters:
        here = f"{comp.name}: parameter {p.name}"
        v = unit.vars.get(p.name)
        if v is None:
            raise ValueError(f"{here}: no variable of a played type is called so")
        if _FAMILY[p.type] != v.family:
            raise ValueError(f"{here}: type {p.type}, but the variable holds {v.family}")
        if p.shape is not None and p.shape != v.shape:
            raise ValueError(f"{here}: dimensions {list(p.shape)}, but the variable's are "
                             f"{list(v.shape)}")
        if len(p.values) != v.size:
            raise ValueError(f"{here}: {len(p.values)} value(s) for its {v.size} element(s)")
        try:
            chosen[p.name] = (v, [_parse(x, v.family) for x in p.values])
        except ValueError as e:
            raise ValueError(f"{here}: {e}") from None
    return list(chosen.values())


def replay_ssp(path: str | Path, *, start_time: float | None = None,
               stop_time: float | None = None, step_size: float | None = None) -> np.ndarray:
    """Play the archive (module docstring) from its recorded start to its stop time at its
    recorded step (each overridable); returns the structured array of ``time`` and every
    component's output elements, row 0 after initialization, row k after step k."""
    archive = read_archive(path)
    start = archive.start if start_time is None else float(start_time)
    stop = archive.stop if stop_time is None else float(stop_time)
    h = archive.step if step_size is None else float(step_size)
    if math.isnan(stop) or math.isnan(h):
        raise ValueError(f"{path} records no stop time and step size (a DefaultExperiment with "
                         "a step annotation): give stop_time and step_size")
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f"step must be positive, got {h}")
    n = round((stop - start) / h)
    if n < 1 or abs(start + n * h - stop) > 1e-9 * max(1.0, abs(stop)):
        raise ValueError(f"from {start} s to {stop} s is not a whole number (>= 1) of "
                         f"{h} s steps")
    units: dict[str, _Unit] = {}
    with tempfile.TemporaryDirectory(prefix="fullpose-ssp-") as tmp, \
            zipfile.ZipFile(path) as zf:
        try:
            for k, comp in enumerate(archive.components):
                folder = Path(tmp) / str(k)
                fmu = Path(tmp) / f"{k}.fmu"
                fmu.write_bytes(zf.read(comp.source))
                with zipfile.ZipFile(fmu) as inner:
                    inner.extractall(folder)
                units[comp.name] = _Unit(comp, folder, start)
            variables = _check(units, archive)
            for comp in archive.components:
                unit = units[comp.name]
                unit.set_values(_parameters(unit, comp), "setting the parameter values")
                unit.initialize(start)
            return _run(archive, units, variables, start, h, n)
        finally:
            for unit in units.values():
                unit.close()


def _run(archive: Archive, units: dict[str, _Unit], variables: dict[tuple[str, str], _Var],
         start: float, h: float, n: int) -> np.ndarray:
    """The Jacobi loop and its recording."""
    outputs: dict[str, dict[str, list[tuple[str, _Var]]]] = {}  # comp -> family -> outputs
    columns: list[tuple[str, str, str, int]] = []  # (column, comp, family, position)
    for comp in archive.components:
        by_family: dict[str, list[tuple[str, _Var]]] = {}
        for c in comp.connectors:
            if c.kind == "output":
                by_family.setdefault(variables[comp.name, c.name].family, []).append(
                    (c.name, variables[comp.name, c.name]))
        outputs[comp.name] = by_family
        for family, items in by_family.items():
            at = 0
            for name, v in items:
                for element in element_names(name, v.shape):
                    columns.append((f"{comp.name}.{element}", comp.name, family, at))
                    at += 1
    inputs: dict[str, list[tuple[_Var, str, str]]] = {c.name: [] for c in archive.components}
    for fc, fv, tc, tv in archive.connections:
        inputs[tc].append((variables[tc, tv], fc, fv))
    dtype = np.dtype([("time", np.float64)] + [(name, _DTYPE[family])
                                                for name, _, family, _ in columns])
    rows: list[tuple[Value, ...]] = []

    def read_all() -> tuple[dict[tuple[str, str], list[Value]],
                            dict[tuple[str, str], list[Value]]]:
        flat: dict[tuple[str, str], list[Value]] = {}
        by_name: dict[tuple[str, str], list[Value]] = {}
        for comp, by_family in outputs.items():
            for family, items in by_family.items():
                values = units[comp].get_values([v for _, v in items], family)
                flat[comp, family] = values
                at = 0
                for name, v in items:
                    by_name[comp, name] = values[at:at + v.size]
                    at += v.size
        return flat, by_name

    def record(t: float, flat: dict[tuple[str, str], list[Value]]) -> None:
        rows.append((t, *[flat[comp, family][at] for _, comp, family, at in columns]))

    flat, current = read_all()
    record(start, flat)
    for k in range(n):
        t = start + k * h
        for comp in archive.components:
            unit = units[comp.name]
            if k > 0 and inputs[comp.name]:
                unit.set_values([(v, current[fc, fv]) for v, fc, fv in inputs[comp.name]],
                                f"setting the inputs at t = {t:.6g} s")
            unit.step(t, h)
        flat, current = read_all()
        record(start + (k + 1) * h, flat)
    return np.array(rows, dtype=dtype)
