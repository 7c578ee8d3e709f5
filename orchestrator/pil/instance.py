"""The controller FMU's place in a closed loop, taken by the controller image on the emulated
Cortex-M7 (processor in the loop).

:class:`PilController` is an :class:`~orchestrator.sim.fmu.FmuInstance` to the master and
the step engines: the same variables (the controller FMU's modelDescription: the image is
built from the same sources, checked by the model GUID), the same start values, and the
FMI 2.0-shaped entries the engines call each step.  Those entries are C callbacks that carry
the sample to the target: the inputs set, ``fmi2DoStep`` one request (inputs, the sample,
every output group the engine reads), the gets served from its reply.  What the target
measures of each sample is kept in :attr:`PilController.samples`.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from orchestrator.pil.target import (
    FP_WARNING,
    MACHINE,
    PilError,
    PilTarget,
    Reply,
    instructions,
    packed_refs,
)
from orchestrator.sim.fmu import FmuError, FmuInstance, Kernel, Signal
from plant.common.model_description import model_description

_ARRAY = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t,
                          ctypes.c_void_p)
_STEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                         ctypes.c_int)
_OK, _ERROR = 0, 3
_STATUS_NAME = {"warning": "WARNING", "error": "ERROR", "discard": "DISCARD"}


@dataclass
class SampleLog:
    """What the target measured of each sample, in order: board-timer ticks over the
    controller call, and the C library's use and the stack depth after it."""

    ticks: list[int] = field(default_factory=list)
    format_calls: list[int] = field(default_factory=list)
    heap_bytes: list[int] = field(default_factory=list)
    stack_bytes: list[int] = field(default_factory=list)

    def add(self, reply: Reply) -> None:
        """Keep one sample's figures."""
        self.ticks.append(reply.ticks)
        self.format_calls.append(reply.format_calls)
        self.heap_bytes.append(reply.heap_bytes)
        self.stack_bytes.append(reply.stack_bytes)

    def instructions(self, shift: int) -> np.ndarray:
        """Instructions of each sample's controller call."""
        return np.asarray(instructions(np.asarray(self.ticks, dtype=float), shift))


@dataclass
class _Group:
    kind: str  # "real" or "int" (Integer and Boolean)
    refs: list[int]
    values: np.ndarray


class PilController(FmuInstance):
    """The controller image under QEMU, with the controller FMU's interface."""

    def __init__(self, elf: str | Path, fmu_path: str | Path | None = None,
                 instance_name: str | None = None, trace_libm: bool = False) -> None:
        from controller import controller_fmu

        # (FmuInstance.__init__ would instantiate the FMU: only its description is used)
        self.path = Path(fmu_path) if fmu_path is not None else controller_fmu()
        self.md = model_description(self.path)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.messages: list[tuple[str, str, str]] = []
        self._sink = None
        self._owns_unzip = False
        self.unzip_dir = ""
        self.time = 0.0
        self.name = instance_name or self.md.modelName
        self.target = PilTarget(elf)
        try:
            guid = self.target.hello()
            if guid != self.md.guid:
                raise PilError(f"the controller image {elf} was built from other sources than "
                               f"{self.path.name} (model GUID {guid}, the FMU's {self.md.guid}): "
                               "rebuild it with 'fullpose build-embedded'")
        except BaseException:
            self.target.close()
            raise
        self.samples = SampleLog()
        # trace_libm (the tracing image): every sample's calls of libm's inexact functions
        self.trace_libm = trace_libm
        self.libm_calls: list[np.ndarray] = []
        self.libm_dropped = 0
        self._init_reply: Reply | None = None
        self._ts = 0.0
        self._pending: tuple[bytes, np.ndarray] | None = None
        self._groups: dict[int, _Group] = {}  # by the engine's reference-array address
        self._layout: tuple[bytes, bytes, list[_Group], list[_Group], int] | None = None
        self._packed: dict[tuple[int, int], bytes] = {}  # input references, packed
        self._fresh: set[int] = set()  # groups the last sample's reply filled
        self._entries = {"fmi2SetReal": _ARRAY(self._guarded(self._set_real)),
                         "fmi2DoStep": _STEP(self._guarded(self._step)),
                         "fmi2GetReal": _ARRAY(self._guarded(self._get_real)),
                         "fmi2GetInteger": _ARRAY(self._guarded(self._get_int)),
                         "fmi2GetBoolean": _ARRAY(self._guarded(self._get_int))}

    @property
    def shift(self) -> int:
        """The -icount shift the target runs with (instructions = ticks * 40 / 2**shift)."""
        return self.target.shift

    @property
    def start_instructions(self) -> float:
        """Instructions fpc_start took (the parameters' checks and the force sets)."""
        return float(instructions(self._init_reply.ticks, self.shift)) if self._init_reply else 0.0

    # -- messages ------------------------------------------------------------------------

    def _said(self, reply: Reply) -> None:
        for line in reply.text.splitlines():
            tag, _, rest = line.partition(": ")
            status = _STATUS_NAME.get(tag)
            if status is None:
                status, rest = "OK", line
            self.messages.append((status, "", rest))

    def _check(self, reply: Reply, what: str) -> Reply:
        self._said(reply)
        if reply.failed:
            logged = [m for s, _, m in self.messages if s in ("ERROR", "DISCARD")]
            raise FmuError(self.md.modelName, what, logged[-3:], what, reply.status)
        return reply

    # -- values ---------------------------------------------------------------------------

    def _by_type(self, values: Mapping[str, float | int | bool]) -> None:
        reals: tuple[list[int], list[float]] = ([], [])
        ints: tuple[list[int], list[int]] = ([], [])
        for name, value in values.items():
            v = self.variables.get(name)
            if v is None:
                raise KeyError(f"{self.md.modelName} has no variable {name!r}")
            if v.type == "Real":
                reals[0].append(int(v.valueReference))
                reals[1].append(float(value))
            else:
                ints[0].append(int(v.valueReference))
                ints[1].append(int(bool(value)) if v.type == "Boolean" else int(value))
        if reals[0]:
            self._check(self.target.set_reals(*reals), "setting " + ", ".join(list(values)[:3]))
        if ints[0]:
            self._check(self.target.set_ints(*ints), "setting " + ", ".join(list(values)[:3]))

    def set_many(self, values: Mapping[str, float | int | bool]) -> None:
        """Set every value on the target (Reals, then Integers and Booleans)."""
        self._by_type(values)

    def set(self, name: str, value: float | int | bool) -> None:
        """Set one variable, by name."""
        self._by_type({name: value})

    def get(self, name: str) -> float | int | bool:
        """The current value of one variable, by name."""
        v = self.variables[name]
        ref = [int(v.valueReference)]
        if v.type == "Real":
            reply, reals = self.target.get_reals(ref)
            self._check(reply, f"reading {name}")
            return float(reals[0])
        reply, ints = self.target.get_ints(ref)
        self._check(reply, f"reading {name}")
        return bool(ints[0]) if v.type == "Boolean" else int(ints[0])

    def read(self, sig: Signal) -> np.ndarray:
        """A signal's current values."""
        reply, reals = self.target.get_reals([int(r) for r in sig.refs])
        self._check(reply, "reading " + ", ".join(sig.names[:3]))
        sig.values[:] = reals
        return sig.values

    def write(self, sig: Signal, values: Iterable[float] | np.ndarray) -> None:
        """Set a signal's variables."""
        flat = np.asarray(values, dtype=float).reshape(-1)
        self._check(self.target.set_reals([int(r) for r in sig.refs], flat),
                    "setting " + ", ".join(sig.names[:3]))

    # -- lifecycle ----------------------------------------------------------------------

    def enter_initialization(self, start_time: float = 0.0,
                             parameters: Mapping[str, float | int | bool] | None = None) -> None:
        """Every variable at its start value, then these parameters."""
        self._check(self.target.defaults(), "fpc_defaults")
        if parameters:
            self.set_many(parameters)
        self.time = start_time

    def exit_initialization(self) -> None:
        """fpc_start on the target: the parameters checked, the states started."""
        self._init_reply = self._check(self.target.start(self.time), "fpc_start")
        if self.trace_libm:  # (from the first sample on)
            self._check(self.target.record_libm(True), "recording libm calls")
        self._ts = float(self.get("Ts"))

    def reset(self) -> None:
        """Back to the start values, ready for :meth:`enter_initialization`."""
        self._check(self.target.defaults(), "fpc_defaults")
        self.messages.clear()
        self.samples = SampleLog()
        self._groups.clear()
        self._layout = None
        self._packed.clear()
        self._fresh.clear()
        self.time = 0.0

    def step(self, h: float) -> None:
        """One sample from Python (the engines step through :meth:`kernel`)."""
        if self._step(None, self.time, h, 1) != _OK:
            raise FmuError(self.md.modelName, f"sample at t = {self.time:.6g} s",
                           [m for s, _, m in self.messages if s == "ERROR"][-3:])

    # -- the engines' entries -------------------------------------------------------------

    def kernel(self) -> Kernel:
        """The FMI 2.0-shaped entries, as callbacks into this instance (component unused)."""
        return Kernel(1, {n: ctypes.cast(f, ctypes.c_void_p).value or 0
                          for n, f in self._entries.items()})

    def _guarded(self, entry: Callable[..., int]) -> Callable[..., int]:
        """entry as a C callback may run it: an exception (the target stopped answering)
        becomes an error status with its message kept, as an FMU's failed call (ctypes would
        print it and return 0, an OK)."""
        def call(*args: Any) -> int:
            try:
                return entry(*args)
            except Exception as e:  # (every failure is the call's status)
                self.messages.append(("ERROR", "", str(e)))
                return _ERROR

        return call

    @staticmethod
    def _refs_at(address: int | None, n: int) -> list[int]:
        if not n or not address:
            return []
        return list((ctypes.c_uint * n).from_address(address))

    def _set_real(self, comp: int, vr: int | None, n: int, values: int | None) -> int:
        if n == 0:
            return _OK
        data = np.ctypeslib.as_array((ctypes.c_double * n).from_address(values or 0)).copy()
        if self._pending is not None:  # two sets before a step: the earlier one now
            reply = self.target.set_reals(self._refs_at(vr, n), data)
            self._said(reply)
            return _ERROR if reply.failed else _OK
        key = (int(vr or 0), n)  # the engine's reference arrays are fixed: packed once
        packed = self._packed.get(key)
        if packed is None:
            packed = self._packed[key] = packed_refs(self._refs_at(vr, n))
        self._pending = (packed, data)
        return _OK

    def _outputs(self) -> tuple[bytes, bytes, list[_Group], list[_Group], int]:
        """What a sample asks back: the Real and the Integer/Boolean groups' references
        (packed), the groups, and the Real count; made again only when a group joins."""
        if self._layout is None:
            reals = [g for g in self._groups.values() if g.kind == "real"]
            ints = [g for g in self._groups.values() if g.kind == "int"]
            self._layout = (packed_refs([r for g in reals for r in g.refs]),
                            packed_refs([r for g in ints for r in g.refs]), reals, ints,
                            sum(len(g.refs) for g in reals))
        return self._layout

    def _step(self, comp: int | None, t: float, h: float, flag: int) -> int:
        ts = self._ts
        if abs(h - ts) > 1e-9 * ts:
            self.messages.append(("ERROR", "", f"the controller on the target samples once per "
                                  f"step of its sample time Ts = {ts:g} s; the step is {h:g} s"))
            return _ERROR
        refs, data = self._pending if self._pending is not None else (packed_refs([]),
                                                                      np.zeros(0))
        self._pending = None
        real_refs, int_refs, reals, ints, n_real = self._outputs()
        reply = self.target.sample(t, refs, data, real_refs, int_refs)
        self._said(reply)
        if reply.failed:
            return _ERROR
        self.samples.add(reply)
        if self.trace_libm:
            calls, dropped = self.target.take_libm()
            self.libm_calls.append(calls.copy())
            self.libm_dropped += dropped
        got_r = np.frombuffer(reply.values[:8 * n_real], dtype="<f8")
        got_i = np.frombuffer(reply.values[8 * n_real:], dtype="<i4")
        a = b = 0
        for g in reals:
            g.values[:] = got_r[a:a + len(g.refs)]
            a += len(g.refs)
        for g in ints:
            g.values[:] = got_i[b:b + len(g.refs)]
            b += len(g.refs)
        self._fresh = {k for k in self._groups}
        self.time = t + h
        return _OK if reply.status <= FP_WARNING else _ERROR

    def _get(self, kind: str, vr: int | None, n: int, out: int | None) -> tuple[int, np.ndarray]:
        key = int(vr or 0)
        group = self._groups.get(key)
        if group is None or key not in self._fresh:  # first read of this group: ask, keep it
            refs = self._refs_at(vr, n)
            if kind == "real":
                reply, values = self.target.get_reals(refs)
            else:
                reply, values = self.target.get_ints(refs)
            self._said(reply)
            if reply.failed:
                return _ERROR, np.zeros(0)
            group = self._groups[key] = _Group(kind, refs, np.array(values))
            self._layout = None  # the next sample asks for this group too
        self._fresh.discard(key)
        return _OK, group.values

    def _get_real(self, comp: int, vr: int | None, n: int, out: int | None) -> int:
        if n == 0:
            return _OK
        status, values = self._get("real", vr, n, out)
        if status == _OK:
            ctypes.memmove(out or 0, values.astype("<f8").ctypes.data, 8 * n)
        return status

    def _get_int(self, comp: int, vr: int | None, n: int, out: int | None) -> int:
        if n == 0:
            return _OK
        status, values = self._get("int", vr, n, out)
        if status == _OK:
            ctypes.memmove(out or 0, values.astype("<i4").ctypes.data, 4 * n)
        return status

    def summary(self) -> dict[str, object]:
        """What the target measured, for a run's metadata: instructions per sample (mean,
        p99, max) and of fpc_start, the deepest stack of fpc_start and of the samples, and
        the C library's heap bytes and text formatting calls during the samples (0 and 0:
        the sample path uses neither; a message said in a sample formats text)."""
        s = self.samples
        ins = s.instructions(self.shift)
        first = self._init_reply
        return {
            "machine": f"{MACHINE} (Cortex-M7, fpv5-d16) under QEMU, -icount shift={self.shift}",
            "samples": len(ins),
            "instructions": ({"mean": float(ins.mean()), "p99": float(np.percentile(ins, 99)),
                              "max": float(ins.max())} if len(ins) else None),
            "start_instructions": self.start_instructions,
            "start_stack_bytes": first.stack_bytes if first is not None else 0,
            "stack_bytes": max(s.stack_bytes, default=0),
            "heap_bytes_in_samples": (s.heap_bytes[-1] - first.heap_bytes
                                      if first is not None and s.heap_bytes else 0),
            "format_calls_in_samples": (s.format_calls[-1] - first.format_calls
                                        if first is not None and s.format_calls else 0),
        }

    def close(self) -> None:
        """Stop the target."""
        self.target.close()
