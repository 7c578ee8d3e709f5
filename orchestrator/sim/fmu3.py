"""An FMI 3.0 co-simulation FMU behind the same handle as an FMI 2.0 one
(:class:`~orchestrator.sim.fmu.FmuInstance`), through fmpy's ``FMU3Slave``.

FMI 3.0 gives a vector one variable (``pos``, a Float64 array of 3) where FMI 2.0 gives one
scalar per element (``pos[1]`` .. ``pos[3]``).  The master, the recording and the scenario
overrides all name elements, so the handle shows the elements of every array under their FMI
2.0 names (a matrix ``poly_A[i,j]``, row-major) with element references of its own (their
place in the list), reads and writes whole variables underneath, and hands the step kernel
an adapter with FMI 2.0-shaped entry points on those element references
(``fmu_src/host/fp_cosim.h``, "The FMI 3.0 adapter"), created once the instance is initialized.
"""

from __future__ import annotations

import ctypes
import shutil
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from fmpy import extract
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave

from orchestrator.sim.fmu import (
    FAILED_STATUSES,
    FmuError,
    FmuInstance,
    Kernel,
    LogSink,
    Signal,
    status_name,
)
from plant.common.model_description import model_description

Value = float | int | bool
_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean"}
_KIND = {"Real": 0, "Integer": 1, "Boolean": 2}  # fp_cosim.h FP_FMI3_*


@dataclass(frozen=True)
class Element:
    """One element of an FMI 3.0 variable, seen as an FMI 2.0 scalar variable: its FMI 2.0
    name, element reference, type name ("Real", "Integer", "Boolean") and the variable's
    attributes (causality, variability, start of this element, min, max, description)."""

    name: str
    valueReference: int
    type: str
    causality: str
    variability: str
    start: str | None
    min: str | None
    max: str | None
    description: str | None
    variable: str  # the FMI 3.0 variable's name
    vr: int  # its value reference
    index: int  # the element's place in it (row-major)
    size: int  # its element count


def _element_names(name: str, shape: tuple[int, ...]) -> list[str]:
    if not shape:
        return [name]
    if len(shape) == 1:
        return [f"{name}[{i + 1}]" for i in range(shape[0])]
    if len(shape) == 2:
        return [f"{name}[{i + 1},{j + 1}]" for i in range(shape[0]) for j in range(shape[1])]
    raise ValueError(f"{name}: arrays of {len(shape)} dimensions are not used here")


def elements(md: Any) -> list[Element]:
    """The elements of an FMI 3.0 model description's Float64, Int32 and Boolean variables
    (the independent variable left out), in its order."""
    out: list[Element] = []
    for v in md.modelVariables:
        kind = _TYPES.get(v.type)
        if kind is None or v.causality == "independent":
            continue
        shape = tuple(int(x) for x in (v.shape or ()))
        names = _element_names(v.name, shape)
        starts = (str(v.start).split() if v.start is not None else [None] * len(names))
        if len(starts) == 1 and len(names) > 1:
            starts = starts * len(names)
        for k, n in enumerate(names):
            out.append(Element(n, len(out), kind, str(v.causality), str(v.variability),
                               starts[k] if k < len(starts) else None, v.min, v.max,
                               v.description, v.name, int(v.valueReference), k, len(names)))
    return out


class Fmu3Instance(FmuInstance):
    """One instance of an FMI 3.0 co-simulation FMU with the FMI 2.0 handle's interface
    (names of elements, ``get``/``set``/``signal``/``read``/``write``, initialization, steps,
    reset, close, the kernel's entries)."""

    def __init__(self, fmu_path: str | Path, instance_name: str | None = None,
                 log: LogSink | None = None, logging_on: bool = False,
                 unzip_dir: str | Path | None = None) -> None:
        self.path = Path(fmu_path)
        self.md = model_description(self.path)
        self._owns_unzip = unzip_dir is None
        self.unzip_dir = str(unzip_dir) if unzip_dir is not None else extract(str(self.path))
        self.messages: list[tuple[str, str, str]] = []
        self._sink = log
        self.elements = elements(self.md)
        self.variables = {e.name: e for e in self.elements}
        self._var_of = {e.name: e for e in self.elements}
        self._adapter: int | None = None
        self._written: dict[str, list[Value]] = {}  # whole variables set before initialization
        self._initializing = self._initialized = False
        self.slave = FMU3Slave(guid=self.md.guid, unzipDirectory=self.unzip_dir,
                               modelIdentifier=self.md.coSimulation.modelIdentifier,
                               instanceName=instance_name or self.md.modelName)
        try:
            self.slave.instantiate(loggingOn=logging_on, logMessage=self._on_log3)
        except Exception:  # fmpy raises a bare Exception when instantiation returns NULL
            logged = [m for s, _, m in self.messages if s in FAILED_STATUSES]
            raise FmuError(self.md.modelName, "fmi3InstantiateCoSimulation", logged,
                           "fmi3InstantiateCoSimulation") from None
        self.time = 0.0

    # -- logging ---------------------------------------------------------------

    def _on_log3(self, env: object, status: int, category: bytes, message: bytes) -> None:
        cat = category.decode(errors="replace") if category else ""
        msg = message.decode(errors="replace") if message else ""
        if self._sink is None or status_name(status) in FAILED_STATUSES:
            self.messages.append((status_name(status), cat, msg))
        if self._sink is not None:
            self._sink(status, cat, msg)

    # -- variables -------------------------------------------------------------

    def _read_vars(self, names: list[str]) -> dict[str, list[Value]]:
        """The whole values of the FMI 3.0 variables the elements ``names`` belong to."""
        wanted: dict[str, Element] = {}
        for n in names:
            e = self._var_of[n]
            wanted.setdefault(e.variable, e)
        out: dict[str, list[Value]] = {}
        for var, e in wanted.items():
            with self.call(f"reading {var}"):
                if e.type == "Real":
                    out[var] = list(self.slave.getFloat64([e.vr], e.size))
                elif e.type == "Integer":
                    out[var] = list(self.slave.getInt32([e.vr], e.size))
                else:
                    out[var] = [bool(x) for x in self.slave.getBoolean([e.vr], e.size)]
        return out

    def get(self, name: str) -> float | int | bool:
        """The current value of one element, by its FMI 2.0 name."""
        e = self._element(name)
        value = self._read_vars([name])[e.variable][e.index]
        return float(value) if e.type == "Real" else int(value) if e.type == "Integer" \
            else bool(value)

    def _element(self, name: str) -> Element:
        try:
            return self._var_of[name]
        except KeyError:
            raise KeyError(f"{self.md.modelName} has no variable {name!r}") from None

    def set(self, name: str, value: float | int | bool) -> None:
        """Set one element (its variable is written whole, the other elements as they are)."""
        self.set_many({name: value})

    def set_many(self, values: Mapping[str, float | int | bool]) -> None:
        """Sets every value: the variables they belong to read, changed and written, one FMI
        call per variable (so a refusal names it)."""
        for name in values:
            self._element(name)
        current = self._read_vars(list(values)) if self._readable() else {}
        changed: dict[str, tuple[Element, list[Value]]] = {}
        for name, value in values.items():
            e = self._var_of[name]
            if e.variable not in changed:
                whole = current.get(e.variable) or self._written.get(e.variable)
                if whole is None:
                    whole = [self._start(x) for x in self.elements if x.variable == e.variable]
                changed[e.variable] = (e, list(whole))
            changed[e.variable][1][e.index] = value
        for var, (e, whole) in changed.items():
            if not self._readable():
                self._written[var] = whole
            with self.call(f"setting {var}"):
                if e.type == "Real":
                    self.slave.setFloat64([e.vr], [float(x) for x in whole])
                elif e.type == "Integer":
                    self.slave.setInt32([e.vr], [int(x) for x in whole])
                else:
                    self.slave.setBoolean([e.vr], [bool(x) for x in whole])
        if self._adapter is not None:  # the kernel's copy of the values follows
            self._refresh_adapter(changed)

    def _readable(self) -> bool:
        """Whether getters are legal now (FMI 3.0: not in the Instantiated state)."""
        return self._initializing or self._initialized

    @staticmethod
    def _start(e: Element) -> Value:
        text = e.start if e.start is not None else "0"
        if e.type == "Real":
            return float(text)
        if e.type == "Integer":
            return int(text)
        return text in ("true", "1")

    def signal(self, names: str | Iterable[str]) -> Signal:
        """The Real elements called names (a vector name stands for all its elements)."""
        expanded: list[str] = []
        for n in [names] if isinstance(names, str) else names:
            expanded += self.expand(n)
        refs = (ctypes.c_uint * len(expanded))(*[self.vr(n) for n in expanded])
        return Signal(expanded, refs, np.zeros(len(expanded)))

    def read(self, sig: Signal) -> np.ndarray:
        """The current values of a signal."""
        whole = self._read_vars(sig.names)
        sig.values[:] = [whole[self._var_of[n].variable][self._var_of[n].index]
                         for n in sig.names]
        return sig.values

    def write(self, sig: Signal, values: Iterable[float] | np.ndarray) -> None:
        """Set a signal's elements to values (in the signal's order)."""
        flat = np.asarray(values, dtype=float).reshape(-1)
        self.set_many({n: float(x) for n, x in zip(sig.names, flat, strict=True)})

    # -- lifecycle -------------------------------------------------------------

    def enter_initialization(self, start_time: float = 0.0,
                             parameters: Mapping[str, float | int | bool] | None = None) -> None:
        """The start values, then fmi3EnterInitializationMode at start_time."""
        if parameters:
            self.set_many(parameters)
        with self.call("fmi3EnterInitializationMode"):
            self.slave.enterInitializationMode(startTime=start_time)
        self._initializing = True
        self.time = start_time

    def exit_initialization(self) -> None:
        """fmi3ExitInitializationMode: the FMU validates its parameters and is ready to step."""
        with self.call("fmi3ExitInitializationMode"):
            self.slave.exitInitializationMode()
        self._initializing, self._initialized = False, True

    def reset(self) -> None:
        """fmi3Reset: back to the Instantiated state, every variable at its start value."""
        self._free_adapter()
        with self.call("fmi3Reset"):
            self.slave.reset()
        self.messages.clear()
        self._written.clear()
        self._initializing = self._initialized = False
        self.time = 0.0

    def step(self, h: float) -> None:
        """fmi3DoStep from the instance's time by h seconds."""
        with self.call(f"fmi3DoStep at t = {self.time:.6g} s"):
            _, terminate, early, _ = self.slave.doStep(
                currentCommunicationPoint=self.time, communicationStepSize=h)
        if terminate or early:
            raise FmuError(self.md.modelName, "fmi3DoStep",
                           ["the FMU asked to end the simulation or returned early"])
        self.time += h

    # -- the step kernel --------------------------------------------------------

    def kernel(self) -> Kernel:
        """The adapter (``libfp_cosim``) on the initialized instance and its FMI 2.0-shaped
        entries, made at the first call."""
        from orchestrator.sim.native import cosim

        lib = cosim()
        if self._adapter is None:
            variables: dict[str, Element] = {}
            for e in self.elements:
                variables.setdefault(e.variable, e)
            vp = ctypes.c_void_p
            fns = (vp * 5)(*[ctypes.cast(getattr(self.slave.dll, n), vp).value for n in (
                "fmi3SetFloat64", "fmi3GetFloat64", "fmi3GetInt32", "fmi3GetBoolean",
                "fmi3DoStep")])
            n = len(variables)
            vrs = (ctypes.c_uint * n)(*[e.vr for e in variables.values()])
            sizes = (ctypes.c_uint * n)(*[e.size for e in variables.values()])
            kinds = (ctypes.c_int * n)(*[_KIND[e.type] for e in variables.values()])
            out = ctypes.c_void_p()
            status = lib.fp_fmi3_adapter_new(self.slave.component, fns, n, vrs, sizes, kinds,
                                             ctypes.addressof(out))
            if status != 0 or not out.value:
                logged = [m for s, _, m in self.messages if s in FAILED_STATUSES]
                raise FmuError(self.md.modelName, "reading every variable for the step kernel",
                               logged)
            self._adapter = int(out.value)
        entries = {name: ctypes.cast(getattr(lib, fn), ctypes.c_void_p).value for name, fn in (
            ("fmi2SetReal", "fp_fmi3_set_real"), ("fmi2GetReal", "fp_fmi3_get_real"),
            ("fmi2GetInteger", "fp_fmi3_get_integer"), ("fmi2GetBoolean", "fp_fmi3_get_boolean"),
            ("fmi2DoStep", "fp_fmi3_do_step"))}
        return Kernel(self._adapter, {k: int(v) for k, v in entries.items() if v is not None})

    def _refresh_adapter(self, changed: Mapping[str, tuple[Element, list[Value]]]) -> None:
        """After a set through fmpy: the kernel's copy of those Float64 elements set too."""
        from orchestrator.sim.native import cosim

        reals = [(e, whole) for e, whole in changed.values() if e.type == "Real"]
        for e, whole in reals:
            first = e.valueReference - e.index
            refs = (ctypes.c_uint * e.size)(*range(first, first + e.size))
            vals = (ctypes.c_double * e.size)(*[float(x) for x in whole])
            cosim().fp_fmi3_set_real(ctypes.c_void_p(self._adapter), refs, e.size, vals)

    def _free_adapter(self) -> None:
        if self._adapter is not None:
            from orchestrator.sim.native import cosim

            cosim().fp_fmi3_adapter_free(ctypes.c_void_p(self._adapter))
            self._adapter = None

    def close(self) -> None:
        """Terminate and free the instance (and the kernel's adapter), and remove its unzipped
        files when it unzipped them."""
        self._free_adapter()
        try:
            self.slave.terminate()
        except (FMICallException, Exception):
            pass  # terminate is illegal after an error; freeing the instance is what matters
        self.slave.freeInstance()
        if self._owns_unzip:
            shutil.rmtree(self.unzip_dir, ignore_errors=True)


def fmi_version(fmu_path: str | Path) -> int:
    """2 or 3: the FMI version of an FMU (its modelDescription's fmiVersion)."""
    return 3 if str(model_description(Path(fmu_path)).fmiVersion).startswith("3") else 2


def fmi_of(inst: FmuInstance) -> int:
    """2 or 3: the FMI version of an open instance."""
    return 3 if isinstance(inst, Fmu3Instance) else 2


def open_fmu(fmu_path: str | Path, instance_name: str | None = None,
             log: LogSink | None = None, logging_on: bool = False,
             unzip_dir: str | Path | None = None) -> FmuInstance:
    """An instance of an FMI 2.0 or 3.0 co-simulation FMU, by its modelDescription."""
    if fmi_version(fmu_path) == 3:
        return Fmu3Instance(fmu_path, instance_name, log, logging_on, unzip_dir)
    return FmuInstance(fmu_path, instance_name, log, logging_on, unzip_dir)
