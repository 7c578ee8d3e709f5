"""A thin typed handle on one FMI 2.0 co-simulation FMU through fmpy's low-level API.

Value references are resolved once by variable name; vectors of them are kept
as ctypes arrays so a step costs one FMI call per direction, not a Python loop.
"""

from __future__ import annotations

import ctypes
import shutil
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from fmpy import calloc, extract, free
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2ValueReference,
)
from fmpy.model_description import ModelDescription

from plant.common.model_description import model_description

LogSink = Callable[[int, str, str], None]
"""Receives (status, category, message) for every message the FMU logs."""

_STATUS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")
FAILED_STATUSES = ("DISCARD", "ERROR", "FATAL")
"""The status names of a failed FMI call (their messages explain an FmuError)."""


def installed_fmu(model: str) -> Path:
    """Path of an installed FMU by model name (``MultirotorPlant`` or
    ``FullPoseController``)."""
    from controller import CONTROLLER_FMU, controller_fmu
    from plant import PLANT_FMU, plant_fmu

    where = {PLANT_FMU: plant_fmu, CONTROLLER_FMU: controller_fmu}.get(model)
    if where is None:
        raise ValueError(f"unknown FMU {model!r} (known: {PLANT_FMU}, {CONTROLLER_FMU})")
    return where()


def status_name(status: int) -> str:
    """The FMI status name of a status code (fmi2OK -> 'OK', ...)."""
    return _STATUS[status] if 0 <= status < len(_STATUS) else str(status)


class FmuError(FMICallException, RuntimeError):
    """An FMI call failed.  The message is the FMU's own: what it logged (naming the
    variable, value and reason) for the failing call, e.g.
    ``FullPoseController: parameter poly_margin = 2: must be in (0, 1]``.  It is an
    fmpy ``FMICallException`` too, so code written against fmpy keeps catching it."""

    def __init__(self, model: str, call: str, messages: list[str],
                 function: str = "", status: int = 3) -> None:
        self.model, self.call, self.messages = model, call, messages
        self.function, self.status = function, status  # as fmpy's FMICallException
        text = "; ".join(messages) if messages else f"{call} failed (the FMU logged no reason)"
        Exception.__init__(self, f"{model}: {text}")


@dataclass(frozen=True)
class Kernel:
    """What the step kernel (``libfp_cosim``) calls on an instance: its component and the
    addresses of its FMI 2.0-shaped entries ``fmi2SetReal``, ``fmi2DoStep``,
    ``fmi2GetReal``, ``fmi2GetInteger``, ``fmi2GetBoolean`` (an FMI 3.0 instance: an
    adapter's, ``orchestrator.sim.fmu3``)."""

    component: int
    entries: dict[str, int]


KERNEL_ENTRIES = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal", "fmi2GetInteger",
                  "fmi2GetBoolean")


@dataclass
class Signal:
    """A group of Real variables read or written together (e.g. ``pos[1..3]``)."""

    names: list[str]
    refs: ctypes.Array[fmi2ValueReference]
    values: np.ndarray = field(repr=False)


def set_by_type(slave: Any, variables: Mapping[str, Any],
                values: Mapping[str, float | int | bool]) -> None:
    """Sets ``values`` (name -> value) on an fmpy FMU2Slave with one fmi2Set* call per type,
    by the value references of ``variables`` (name -> fmpy ScalarVariable); an FMU refuses a
    whole call before it writes anything (FMICallException)."""
    by_type: dict[str, tuple[list[int], list[float | int | bool]]] = {}
    for name, value in values.items():
        v = variables[name]
        refs, vals = by_type.setdefault(v.type, ([], []))
        refs.append(int(v.valueReference))
        vals.append(value)
    for kind, (refs, vals) in by_type.items():
        if kind == "Real":
            slave.setReal(refs, [float(x) for x in vals])
        elif kind == "Integer":
            slave.setInteger(refs, [int(x) for x in vals])
        else:
            slave.setBoolean(refs, [bool(x) for x in vals])


class FmuInstance:
    """One instance of an FMU, with name-based access and buffers built once.

    ``log`` receives the FMU's messages; by default they are kept in
    ``self.messages`` as (status name, category, message) tuples.
    """

    def __init__(
        self,
        fmu_path: str | Path,
        instance_name: str | None = None,
        log: LogSink | None = None,
        logging_on: bool = False,
        unzip_dir: str | Path | None = None,
    ) -> None:
        self.path = Path(fmu_path)
        self.md: ModelDescription = model_description(self.path)
        self._owns_unzip = unzip_dir is None
        self.unzip_dir = str(unzip_dir) if unzip_dir is not None else extract(str(self.path))
        self.messages: list[tuple[str, str, str]] = []
        self._sink = log
        self.variables = {v.name: v for v in self.md.modelVariables}
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._on_log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.slave = FMU2Slave(
            guid=self.md.guid,
            unzipDirectory=self.unzip_dir,
            modelIdentifier=self.md.coSimulation.modelIdentifier,
            instanceName=instance_name or self.md.modelName,
        )
        try:
            self.slave.instantiate(callbacks=self._callbacks, loggingOn=logging_on)
        except Exception:  # fmpy raises a bare Exception when fmi2Instantiate returns NULL
            logged = [m for s, _, m in self.messages if s in FAILED_STATUSES]
            raise FmuError(self.md.modelName, "fmi2Instantiate", logged,
                           "fmi2Instantiate") from None
        self.time = 0.0

    # -- logging ---------------------------------------------------------------

    def _on_log(self, env: object, name: bytes, status: int, category: bytes,
                message: bytes) -> None:
        cat = category.decode(errors="replace") if category else ""
        # FMI messages are printf formats.  fmpy's formatting proxy keeps one
        # process-wide logger, so it cannot serve several masters; our FMUs pass
        # no varargs and only escape '%', which is undone here.
        msg = message.decode(errors="replace").replace("%%", "%") if message else ""
        if self._sink is None or status_name(status) in FAILED_STATUSES:
            self.messages.append((status_name(status), cat, msg))  # errors: for FmuError
        if self._sink is not None:
            self._sink(status, cat, msg)

    # -- variables -------------------------------------------------------------

    def vr(self, name: str) -> int:
        """The value reference of the variable called name."""
        try:
            return int(self.variables[name].valueReference)
        except KeyError:
            raise KeyError(f"{self.md.modelName} has no variable {name!r}") from None

    def expand(self, name: str) -> list[str]:
        """``pos`` -> [``pos[1]``, ``pos[2]``, ``pos[3]``]; scalar names pass through."""
        if name in self.variables:
            return [name]
        prefix = name + "["
        names = [n for n in self.variables if n.startswith(prefix)]
        if not names:
            raise KeyError(f"{self.md.modelName} has no variable {name!r}")
        return names

    def signal(self, names: str | Iterable[str]) -> Signal:
        """The Real variables called names (a name or several; a vector name stands for all
        its elements) as one signal, read and written in one fmi2GetReal / fmi2SetReal."""
        expanded: list[str] = []
        for n in [names] if isinstance(names, str) else names:
            expanded += self.expand(n)
        refs = (fmi2ValueReference * len(expanded))(*[self.vr(n) for n in expanded])
        return Signal(expanded, refs, np.zeros(len(expanded)))

    def read(self, sig: Signal) -> np.ndarray:
        """The current values of a signal, as float64."""
        sig.values[:] = self.slave.getReal(sig.refs)
        return sig.values

    def write(self, sig: Signal, values: Iterable[float] | np.ndarray) -> None:
        """Set a signal's variables to values (in the signal's order)."""
        more = ", ..." if len(sig.names) > 3 else ""
        with self.call(f"setting {', '.join(sig.names[:3])}{more}"):
            self.slave.setReal(sig.refs, list(np.asarray(values, dtype=float).reshape(-1)))

    def get(self, name: str) -> float | int | bool:
        """The current value of one variable, by name."""
        v = self.variables[name]
        ref = [int(v.valueReference)]
        if v.type == "Real":
            return float(self.slave.getReal(ref)[0])
        if v.type == "Integer":
            return int(self.slave.getInteger(ref)[0])
        return bool(self.slave.getBoolean(ref)[0])

    def set(self, name: str, value: float | int | bool) -> None:
        """Set one variable, by name."""
        try:
            v = self.variables[name]
        except KeyError:
            raise KeyError(f"{self.md.modelName} has no variable {name!r}") from None
        ref = [int(v.valueReference)]
        with self.call(f"setting {name}"):
            if v.type == "Real":
                self.slave.setReal(ref, [float(value)])
            elif v.type == "Integer":
                self.slave.setInteger(ref, [int(value)])
            else:
                self.slave.setBoolean(ref, [bool(value)])

    def set_many(self, values: Mapping[str, float | int | bool]) -> None:
        """Sets every value: one FMI call per type (an FMU refuses a whole call before it
        writes anything), and when a call is refused, one set per name, so the error names
        the variable."""
        unknown = [name for name in values if name not in self.variables]
        if unknown:
            raise KeyError(f"{self.md.modelName} has no variable {unknown[0]!r}")
        first = len(self.messages)
        try:
            set_by_type(self.slave, self.variables, values)
        except FMICallException:
            del self.messages[first:]  # the refused call's messages: said again below
            for name, value in values.items():
                self.set(name, value)

    def kernel(self) -> Kernel:
        """The component and FMI entries the step kernel calls (the FMU's own)."""
        vp = ctypes.c_void_p
        return Kernel(int(self.slave.component),
                      {n: int(ctypes.cast(getattr(self.slave.dll, n), vp).value or 0)
                       for n in KERNEL_ENTRIES})

    # -- lifecycle -------------------------------------------------------------

    @contextmanager
    def call(self, what: str) -> Iterator[None]:
        """Turns fmpy's bare FMICallException ("fmi2X failed with status 3") into an
        :class:`FmuError` carrying what the FMU logged during the call."""
        first = len(self.messages)
        try:
            yield
        except FMICallException as e:
            logged = [m for s, _, m in self.messages[first:] if s in FAILED_STATUSES]
            raise FmuError(self.md.modelName, what, logged, e.function, e.status) from None

    def enter_initialization(self, start_time: float = 0.0,
                             parameters: Mapping[str, float | int | bool] | None = None) -> None:
        """setupExperiment, the start values, enterInitializationMode."""
        with self.call("fmi2SetupExperiment"):
            self.slave.setupExperiment(startTime=start_time)
        if parameters:
            self.set_many(parameters)
        with self.call("fmi2EnterInitializationMode"):
            self.slave.enterInitializationMode()
        self.time = start_time

    def exit_initialization(self) -> None:
        """fmi2ExitInitializationMode: the FMU validates its parameters and is ready to step."""
        with self.call("fmi2ExitInitializationMode"):
            self.slave.exitInitializationMode()

    def initialize(self, start_time: float = 0.0,
                   parameters: Mapping[str, float | int | bool] | None = None) -> None:
        """Enter and exit initialization at start_time with these parameter start values."""
        self.enter_initialization(start_time, parameters)
        self.exit_initialization()

    def reset(self) -> None:
        """fmi2Reset: the instance is back in the Instantiated state with every variable at
        its start value, as after fmi2Instantiate, ready for :meth:`enter_initialization`
        (the FMU's unzipped files and loaded library are kept).  Legal in every state but
        Fatal, so also after a failed run.  The messages logged so far are dropped: each run
        of a reused instance sees its own."""
        with self.call("fmi2Reset"):
            self.slave.reset()
        self.messages.clear()
        self.time = 0.0

    def step(self, h: float) -> None:
        """fmi2DoStep from the instance's time by h seconds (an error raises FmuError)."""
        with self.call(f"fmi2DoStep at t = {self.time:.6g} s"):
            self.slave.doStep(currentCommunicationPoint=self.time, communicationStepSize=h)
        self.time += h

    def close(self) -> None:
        """Terminate and free the instance, and remove its unzipped files when it unzipped them."""
        try:
            self.slave.terminate()
        except Exception:
            pass  # terminate is illegal after an error; freeing the instance is what matters
        self.slave.freeInstance()
        if self._owns_unzip:
            shutil.rmtree(self.unzip_dir, ignore_errors=True)

    def __enter__(self) -> FmuInstance:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

