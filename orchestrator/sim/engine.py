"""The step engine of every closed loop: connections, recording layout and the stepping.

A run plan has three named parts, built in this order:

* :class:`Connections`: which variable feeds which, found by matching names between the two
  FMUs' modelDescriptions, for the airframe's rotors only;
* :class:`Recording`: the matrices every exchanged signal is written to, one row per step,
  and typed views of their blocks.  Columns are ``time | ref | plant | dist | ctrl``, the
  plant's outputs ordered with the controller's measured inputs first and the controller's
  outputs with the plant's command inputs first, so that ``[ref, measured]`` and
  ``[dist, commands]`` are contiguous: each connection is one ``fmi2SetReal`` reading straight
  from the recording, no copies;
* an engine that runs the per-step FMI call sequence on those buffers: :class:`NativeEngine`
  (``fp_cosim_steps`` in C, the engine of scenario runs, live sessions, sweeps and the hover
  demo) or :class:`PythonEngine` (the same calls from Python: the oracle that proves the C
  kernel bit-identical, selected with ``engine="python"``).

Coupling (a modelling choice, recorded in every result):

* ``gauss-seidel`` (default): at t_k the controller samples y_k and computes u_k; the plant
  then integrates [t_k, t_k+1] with u_k (zero computational delay);
* ``jacobi``: both FMUs step from t_k; the plant integrates with u_{k-1} (one-sample delay).
  Row -1 of the controller's outputs is the recording's spare last row.

An open loop (``ctrl=None``: the plant alone, as in the hover demo) records the plant's
command inputs in the ``ctrl`` block and holds whatever the caller wrote there.
"""

from __future__ import annotations

import ctypes
import mmap
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from orchestrator.sim.fmu import FmuInstance, Kernel

MAX_ROTORS = 8
ROTOR_SIGNALS = frozenset({"omega_cmd", "alpha_cmd", "beta_cmd", "omega", "alpha", "beta",
                           "efficiency", "rotor_health", "rotor_eff_est"})
"""Per-rotor vectors (8 elements): a run records and connects only the airframe's rotors."""
REF_INPUTS = ("pos_ref", "euler_ref", "vel_ref", "acc_ref", "euler_rate_ref", "rotor_health")
DIST_INPUTS = ("f_d", "tau_d", "a_d", "efficiency")
HELD_INPUTS = frozenset({"armed"})
"""Inputs a run holds at their start value instead of feeding them every step (the
controller's ``armed``: true through a scenario run; the MAVLink bridge drives it)."""
COUPLINGS = ("gauss-seidel", "jacobi")
ENGINES = ("native", "python")

Value = float | int | bool
_OK_STATUS = 1  # fmi2OK 0, fmi2Warning 1: anything above stops the run


class RunError(RuntimeError):
    """An FMU refused a call during the run; the message carries its log."""

    def __init__(self, message: str, row: int = -1) -> None:
        super().__init__(message)
        self.row = row  # the recording row whose step failed (-1: not known)


MAX_CONTACTS = 8
CONTACT_SIGNALS = frozenset({"contact_force", "contact_flags"})
"""The plant's landing-gear outputs: a run records the gear's points only, none without one."""


def contact_used(name: str, n_contacts: int) -> bool:
    """False for a landing-gear output beyond the gear's point count (all of them without a
    gear)."""
    base, _, index = name.partition("[")
    if base not in CONTACT_SIGNALS:
        return True
    return n_contacts > 0 and (not index or int(index.rstrip("]")) <= n_contacts)


def rotor_used(name: str, n_rotors: int) -> bool:
    """False for the element of a per-rotor vector beyond the airframe's rotor count."""
    base, _, index = name.partition("[")
    return base not in ROTOR_SIGNALS or int(index.rstrip("]").split(",")[0]) <= n_rotors


TRUTH_SUFFIX = "_true"
"""The plant's true-state outputs (``pos_true``, ...): the measured ones without sensor
noise, sampling or latency, recorded only when ``truth`` is asked for
(``master.sensors_differ``); with ideal sensors they would be copies of the measured
columns."""


def _outputs(inst: FmuInstance, kind: str, n_rotors: int, truth: bool = True,
             n_contacts: int = MAX_CONTACTS) -> list[str]:
    return [v.name for v in inst.variables.values()
            if v.causality == "output" and v.type == kind and rotor_used(v.name, n_rotors)
            and contact_used(v.name, n_contacts)
            and (truth or not v.name.split("[")[0].endswith(TRUTH_SUFFIX))]


def _inputs(inst: FmuInstance, n_rotors: int) -> list[str]:
    return [v.name for v in inst.variables.values()
            if v.causality == "input" and rotor_used(v.name, n_rotors)
            and v.name not in HELD_INPUTS]


def _expand(inst: FmuInstance, groups: Sequence[str], n_rotors: int) -> list[list[str]]:
    return [[v for v in inst.expand(g) if rotor_used(v, n_rotors)] for g in groups]


@dataclass(frozen=True)
class Connections:
    """Variable names of every block a run exchanges, in recording order."""

    n_rotors: int
    ref: tuple[tuple[str, ...], ...]  # controller reference inputs, by group of REF_INPUTS
    dist: tuple[tuple[str, ...], ...]  # plant disturbance inputs, by group of DIST_INPUTS
    measured: tuple[str, ...]  # plant outputs = controller inputs
    commands: tuple[str, ...]  # controller outputs = plant inputs
    plant_out: tuple[str, ...]  # every recorded Real plant output, measured first
    ctrl_out: tuple[str, ...]  # every recorded Real controller output, commands first
    plant_int: tuple[str, ...]
    ctrl_int: tuple[str, ...]
    ctrl_bool: tuple[str, ...]

    def widths(self) -> tuple[int, int]:
        """(float64 columns, int32 columns) of a recording of these connections."""
        return (1 + sum(map(len, self.ref)) + len(self.plant_out) + sum(map(len, self.dist))
                + len(self.ctrl_out), len(self.plant_int) + len(self.ctrl_int)
                + len(self.ctrl_bool))

    @property
    def ref_names(self) -> list[str]:
        """The controller's reference inputs the master drives, in order."""
        return [v for g in self.ref for v in g]

    @property
    def dist_names(self) -> list[str]:
        """The plant's disturbance inputs the master drives, in order."""
        return [v for g in self.dist for v in g]

    @staticmethod
    def closed_loop(plant: FmuInstance, ctrl: FmuInstance,
                    n_rotors: int = MAX_ROTORS, truth: bool = False,
                    n_contacts: int = MAX_CONTACTS) -> Connections:
        """Plant and controller connected by matching names; every input must be fed.
        ``truth``: record the plant's true-state outputs too (:data:`TRUTH_SUFFIX`);
        ``n_contacts``: the landing gear's points (:data:`CONTACT_SIGNALS`)."""
        n = n_rotors
        p_out = _outputs(plant, "Real", n, truth, n_contacts)
        c_out = _outputs(ctrl, "Real", n)
        c_in, p_in = _inputs(ctrl, n), _inputs(plant, n)
        measured = [v for v in c_in if v in set(p_out)]
        commands = [v for v in p_in if v in set(c_out)]
        ref = _expand(ctrl, REF_INPUTS, n)
        dist = _expand(plant, DIST_INPUTS, n)
        fed_c = set(measured) | {v for g in ref for v in g}
        fed_p = set(commands) | {v for g in dist for v in g}
        unconnected = ([f"controller.{v}" for v in c_in if v not in fed_c]
                       + [f"plant.{v}" for v in p_in if v not in fed_p])
        if unconnected:
            raise RunError(f"inputs left unconnected: {', '.join(unconnected)}")
        return Connections(
            n_rotors=n, ref=tuple(tuple(g) for g in ref), dist=tuple(tuple(g) for g in dist),
            measured=tuple(measured), commands=tuple(commands),
            plant_out=tuple(measured + [v for v in p_out if v not in measured]),
            ctrl_out=tuple(commands + [v for v in c_out if v not in commands]),
            plant_int=tuple(_outputs(plant, "Integer", n, n_contacts=n_contacts)),
            ctrl_int=tuple(_outputs(ctrl, "Integer", n)),
            ctrl_bool=tuple(_outputs(ctrl, "Boolean", n)))

    @staticmethod
    def open_loop(plant: FmuInstance, commands: Sequence[str],
                  n_rotors: int = MAX_ROTORS) -> Connections:
        """The plant alone: ``commands`` (its command inputs) are held from the recording."""
        n = n_rotors
        cmd = [v for g in commands for v in plant.expand(g) if rotor_used(v, n)]
        return Connections(
            n_rotors=n, ref=(), dist=tuple(tuple(g) for g in _expand(plant, DIST_INPUTS, n)),
            measured=(), commands=tuple(cmd),
            plant_out=tuple(_outputs(plant, "Real", n, truth=False)),
            ctrl_out=tuple(cmd), plant_int=tuple(_outputs(plant, "Integer", n)),
            ctrl_int=(), ctrl_bool=())


SMALL_PAGES_FROM = 32 * 2**20
"""Recordings of this many bytes or more (~48 s of the paper hexacopter at 500 Hz) get
their own anonymous mapping, with 4 KiB pages (:func:`zeroed`)."""


def zeroed(shape: tuple[int, int]) -> np.ndarray:
    """A zeroed float64 matrix.  From ``SMALL_PAGES_FROM`` bytes on, in an anonymous mapping
    of its own that asks the kernel for no transparent huge pages: numpy asks for them for
    every array of 4 MiB or more, and where the kernel has to compact memory to find them
    the first touch of a 70 MB recording stalled for 0.1-0.65 s instead of ~30 ms
    (docs/orchestrator.md), whatever numpy's setting in the program that runs.  glibc maps
    blocks this large afresh for every allocation anyway; smaller ones come from numpy, whose
    memory glibc reuses from run to run (a sweep's recordings)."""
    size = shape[0] * shape[1] * 8
    if size < SMALL_PAGES_FROM or not hasattr(mmap, "MADV_NOHUGEPAGE"):  # (Linux's alone)
        return np.zeros(shape)
    # private, as numpy's memory is; zero-filled; unmapped when the last view of it goes
    buf = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE)
    buf.madvise(mmap.MADV_NOHUGEPAGE)  # (also where THP is "always")
    return np.frombuffer(buf, dtype=np.float64).reshape(shape)


class Recording:
    """The matrices of a run (``rows`` rows plus a spare one: Jacobi's u_{-1}) and typed
    views of their blocks; ``columns`` / ``int_columns`` name every column.  With ``file``
    the float matrix is that ``.npy`` file, mapped into memory: the OS writes the rows out
    as the run goes and keeps in memory only what it has room for (a long run's recording
    need not fit in memory); the caller removes the file."""

    def __init__(self, conn: Connections, rows: int, file: Path | None = None) -> None:
        self.rows = rows
        names = (["time"], [f"ref.{v}" for v in conn.ref_names],
                 [f"plant.{v}" for v in conn.plant_out], [f"dist.{v}" for v in conn.dist_names],
                 [f"ctrl.{v}" for v in conn.ctrl_out])
        self.columns: list[str] = [c for block in names for c in block]
        edges = np.cumsum([0] + [len(b) for b in names])
        self.blocks = {k: slice(int(a), int(b)) for k, a, b in zip(
            ("time", "ref", "plant", "dist", "ctrl"), edges[:-1], edges[1:], strict=True)}
        int_names = ([f"plant.{v}" for v in conn.plant_int], [f"ctrl.{v}" for v in conn.ctrl_int],
                     [f"ctrl.{v}" for v in conn.ctrl_bool])
        self.int_columns: list[str] = [c for block in int_names for c in block]
        iedges = np.cumsum([0] + [len(b) for b in int_names])
        self.int_blocks = {k: slice(int(a), int(b)) for k, a, b in zip(
            ("plant", "ctrl", "ctrl_bool"), iedges[:-1], iedges[1:], strict=True)}
        # one matrix with room for the integer outputs at the end of each row: the result
        # (``result_data``) is this matrix, not a copy of it
        shape = (rows + 1, len(self.columns) + len(self.int_columns))
        self._full: np.ndarray = (zeroed(shape) if file is None else
                                  np.lib.format.open_memmap(file, mode="w+", dtype=np.float64,
                                                             shape=shape))
        self.data = self._full[:, :len(self.columns)]
        self.ints = np.zeros((rows + 1, len(self.int_columns)), dtype=np.int32)
        self.n_commands = len(conn.commands)
        self._vectors: dict[str, slice] = {}  # columns_of, found once per name

    def block(self, name: str) -> np.ndarray:
        """The float64 view of one block (``ref``, ``plant``, ``dist``, ``ctrl``) of all rows."""
        return self.data[:, self.blocks[name]]

    def int_block(self, name: str) -> np.ndarray:
        """The int32 view of ``plant``, ``ctrl`` (Integer) or ``ctrl_bool`` outputs."""
        return self.ints[:, self.int_blocks[name]]

    @property
    def time(self) -> np.ndarray:
        """The recorded time column."""
        return self.data[:, 0]

    def result_data(self, rows: int) -> np.ndarray:
        """Rows 0..rows-1 of every column, the integer outputs last as floats (columns
        ``columns + int_columns``): a view of the recording, filled in place."""
        full = self._full[:rows]
        full[:, len(self.columns):] = self.ints[:rows]
        return full

    ref = property(lambda self: self.block("ref"), doc="references r_k, controller inputs")
    plant = property(lambda self: self.block("plant"), doc="plant outputs y_k, measured first")
    dist = property(lambda self: self.block("dist"), doc="disturbances d_k, plant inputs")
    ctrl = property(lambda self: self.block("ctrl"), doc="controller outputs u_k, commands first")

    @property
    def commands(self) -> np.ndarray:
        """The controller's actuator-command columns of every row."""
        return self.ctrl[:, :self.n_commands]

    @property
    def spare(self) -> int:
        """Index of the spare row (the controller's outputs before the first step)."""
        return self.rows

    def columns_of(self, name: str) -> slice:
        """Columns of a recorded vector by full name, e.g. ``plant.pos`` (its elements are
        consecutive)."""
        found = self._vectors.get(name)
        if found is None:
            first = self.columns.index(f"{name}[1]")
            n = 1
            while first + n < len(self.columns) and \
                    self.columns[first + n].startswith(f"{name}["):
                n += 1
            found = self._vectors[name] = slice(first, first + n)
        return found


def _refs(inst: FmuInstance, names: Sequence[str]) -> ctypes.Array[ctypes.c_uint]:
    return (ctypes.c_uint * len(names))(*[inst.vr(n) for n in names])


_ARRAY_FN = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t,
                             ctypes.c_void_p)
_STEP_FN = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                            ctypes.c_int)
_GROUPS = ("c_in", "c_out", "c_int", "c_bool", "p_in", "p_cmd", "p_dist", "p_out", "p_int")
"""The value-reference groups, in the order fp_cosim_steps takes them."""
_CTRL_FNS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean")
_PLANT_FNS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal", "fmi2GetInteger")


class Engine(ABC):
    """Steps rows [first, last) of a recording: ``engine.steps(first, last, t0)``."""

    def __init__(self, plant: FmuInstance, ctrl: FmuInstance | None, conn: Connections,
                 rec: Recording, h: float, jacobi: bool) -> None:
        self.plant, self.ctrl, self.conn, self.rec = plant, ctrl, conn, rec
        self.h, self.jacobi = h, jacobi
        def c_refs(names: Sequence[str]) -> ctypes.Array[ctypes.c_uint]:
            # an open loop has no controller variables: its groups are empty
            return _refs(ctrl, names) if ctrl is not None else _refs(plant, [])

        self.vrs = {
            "c_in": c_refs(conn.ref_names + list(conn.measured)),
            "c_out": c_refs(conn.ctrl_out), "c_int": c_refs(conn.ctrl_int),
            "c_bool": c_refs(conn.ctrl_bool),
            "p_in": _refs(plant, conn.dist_names + list(conn.commands)),
            "p_cmd": _refs(plant, conn.commands), "p_dist": _refs(plant, conn.dist_names),
            "p_out": _refs(plant, conn.plant_out), "p_int": _refs(plant, conn.plant_int),
        }
        self._entries: dict[str, tuple[Kernel, dict[str, Callable[..., int]]]] = {}

    def _kernel(self, which: str) -> tuple[Kernel, dict[str, Callable[..., int]]]:
        """(the kernel's view, typed entries) of the plant or the controller, found at first
        use: an FMI 3.0 instance's adapter exists once the instance is initialized."""
        found = self._entries.get(which)
        if found is None:
            inst = self.plant if which == "plant" else self.ctrl
            assert inst is not None
            k = inst.kernel()
            found = self._entries[which] = (k, _raw(k.entries))
        return found

    @property
    def _p(self) -> dict[str, Callable[..., int]]:
        return self._kernel("plant")[1]

    @property
    def _c(self) -> dict[str, Callable[..., int]] | None:
        return self._kernel("ctrl")[1] if self.ctrl is not None else None

    @property
    def _pc(self) -> int:
        return self._kernel("plant")[0].component

    @property
    def _cc(self) -> int:
        return self._kernel("ctrl")[0].component

    def initialize(self, plant_params: Mapping[str, Value], ctrl_params: Mapping[str, Value],
                   ref0: np.ndarray) -> None:
        """The plant at its start values; the controller initialized from y_0 and r_0; row 0
        recorded."""
        plant, ctrl, conn = self.plant, self.ctrl, self.conn
        plant.initialize(parameters=plant_params)
        if ctrl is not None:
            ctrl.enter_initialization(0.0, ctrl_params)
            ctrl.write(ctrl.signal(conn.measured), plant.read(plant.signal(conn.measured)))
            ctrl.write(ctrl.signal(conn.ref_names), ref0)
            ctrl.exit_initialization()
            self.rec.ref[0] = ref0
        self.record_initial(0)

    @abstractmethod
    def steps(self, first: int, last: int, t0: float) -> None:
        """Rows first .. last-1: each FMU called as the coupling says; RunError on a failure."""

    def fail(self, t: float, row: int = -1) -> None:
        """Raise RunError at t (row: the last complete row), with the FMUs' last error messages."""
        insts = [i for i in (self.plant, self.ctrl) if i is not None]
        msgs = [f"{i.md.modelName}: {m}" for i in insts
                for s, _, m in i.messages if s in ("ERROR", "FATAL", "DISCARD")]
        raise RunError(f"the co-simulation failed at t = {t:.3f} s: "
                       + ("; ".join(msgs[-3:]) or "an FMU call returned an error"), row)

    def controller_answer(self, k: int, t: float) -> None:
        """The controller's answer to row k without stepping the plant (the last row)."""
        ctrl, rec = self.ctrl, self.rec
        if ctrl is None:
            return
        fns = self._c
        assert fns is not None
        v = self.vrs
        cc = self._cc
        a = fns["fmi2SetReal"](cc, v["c_in"], len(v["c_in"]), _address(rec.ref, k))
        a |= fns["fmi2DoStep"](cc, t, self.h, 1)
        a |= fns["fmi2GetReal"](cc, v["c_out"], len(v["c_out"]), _address(rec.ctrl, k))
        a |= fns["fmi2GetInteger"](cc, v["c_int"], len(v["c_int"]),
                                   _address(rec.int_block("ctrl"), k))
        a |= fns["fmi2GetBoolean"](cc, v["c_bool"], len(v["c_bool"]),
                                   _address(rec.int_block("ctrl_bool"), k))
        if a > _OK_STATUS:
            self.fail(t, k)

    def record_initial(self, k: int) -> None:
        """The plant's outputs into row k; the controller's current ones into the spare row."""
        rec, v = self.rec, self.vrs
        p = self._p
        pc = self._pc
        p["fmi2GetReal"](pc, v["p_out"], len(v["p_out"]), _address(rec.plant, k))
        p["fmi2GetInteger"](pc, v["p_int"], len(v["p_int"]), _address(rec.int_block("plant"), k))
        c = self._c
        if self.ctrl is not None and c is not None:
            c["fmi2GetReal"](self._cc, v["c_out"], len(v["c_out"]), _address(rec.ctrl, rec.spare))


def _raw(entries: Mapping[str, int]) -> dict[str, Callable[..., int]]:
    """The kernel's FMI entries (addresses), typed for buffer addresses."""
    return {name: (_STEP_FN if name == "fmi2DoStep" else _ARRAY_FN)(entries[name])
            for name in _CTRL_FNS}


def _address(view: np.ndarray, row: int) -> int:
    """Address of element [row, 0] of a 2-D view."""
    return int(view.ctypes.data) + row * view.strides[0]


class PythonEngine(Engine):
    """The per-step call sequence from Python: the oracle of :class:`NativeEngine`."""

    def steps(self, first: int, last: int, t0: float) -> None:
        """Run rows first..last (exclusive) from t0: the reference Python loop of the native
        kernel."""
        rec, v, h, jacobi = self.rec, self.vrs, self.h, self.jacobi
        pc = self._pc
        p_set, p_step, p_get, p_geti = (self._p[n] for n in _PLANT_FNS)
        # each block's row 0 address and row stride: element [k, 0] is at base + k * stride
        stride = rec.data.strides[0]
        ref, ctrl, dist, plant = (int(rec.block(b).ctypes.data)
                                  for b in ("ref", "ctrl", "dist", "plant"))
        istride = rec.ints.strides[0]
        c_int, c_bool, p_int = (int(rec.int_block(b).ctypes.data)
                                for b in ("ctrl", "ctrl_bool", "plant"))
        spare = ctrl + rec.spare * stride
        c_in, c_out, c_ints, c_bools = v["c_in"], v["c_out"], v["c_int"], v["c_bool"]
        p_in, p_cmd, p_dist, p_out, p_ints = (v["p_in"], v["p_cmd"], v["p_dist"], v["p_out"],
                                              v["p_int"])
        n_cin, n_cout, n_cint, n_cbool = len(c_in), len(c_out), len(c_ints), len(c_bools)
        n_pin, n_cmd, n_dist, n_pout, n_pint = (len(p_in), len(p_cmd), len(p_dist), len(p_out),
                                                len(p_ints))
        closed = self._c is not None and self.ctrl is not None
        if closed:
            assert self._c is not None and self.ctrl is not None
            cc = self._cc
            c_set, c_step, c_get, c_geti, c_getb = (self._c[n] for n in _CTRL_FNS)
        for k in range(first, last):
            t = t0 + k * h
            a = 0
            if closed:  # the controller samples [r_k, y_k]
                a |= c_set(cc, c_in, n_cin, ref + k * stride)
                a |= c_step(cc, t, h, 1)
                a |= c_get(cc, c_out, n_cout, ctrl + k * stride)
                a |= c_geti(cc, c_ints, n_cint, c_int + k * istride)
                a |= c_getb(cc, c_bools, n_cbool, c_bool + k * istride)
                if a > _OK_STATUS:
                    self.fail(t, k)
            if jacobi:  # the plant integrates with u_{k-1}
                a |= p_set(pc, p_cmd, n_cmd, ctrl + (k - 1) * stride if k else spare)
                a |= p_set(pc, p_dist, n_dist, dist + k * stride)
            else:  # with u_k: [dist_k, u_k] are contiguous, one call
                a |= p_set(pc, p_in, n_pin, dist + k * stride)
            a |= p_step(pc, t, h, 1)
            a |= p_get(pc, p_out, n_pout, plant + (k + 1) * stride)
            a |= p_geti(pc, p_ints, n_pint, p_int + (k + 1) * istride)
            if a > _OK_STATUS:
                self.fail(t, k)


class NativeEngine(Engine):
    """The same call sequence run by ``fp_cosim_steps`` (C), on the same buffers."""

    def __init__(self, plant: FmuInstance, ctrl: FmuInstance | None, conn: Connections,
                 rec: Recording, h: float, jacobi: bool) -> None:
        super().__init__(plant, ctrl, conn, rec, h, jacobi)
        from orchestrator.sim.native import cosim

        self._lib = cosim()
        self._failed = ctypes.c_long(-1)
        self._args: tuple[Any, ...] | None = None

    def _arguments(self) -> tuple[Any, ...]:
        """The kernel's arguments, made at the first steps (the instances initialized)."""
        if self._args is None:
            vp, rec, ctrl = ctypes.c_void_p, self.rec, self.ctrl
            c_fns = [None] * len(_CTRL_FNS) if ctrl is None else [
                self._kernel("ctrl")[0].entries[n] for n in _CTRL_FNS]
            p_entries = self._kernel("plant")[0].entries
            fns = (vp * 9)(*c_fns, *[p_entries[n] for n in _PLANT_FNS])
            comps = (vp * 2)(None if ctrl is None else self._cc, self._pc)
            vrs = (vp * 9)(*[ctypes.addressof(self.vrs[k]) for k in _GROUPS])
            counts = (ctypes.c_size_t * 9)(*[len(self.vrs[k]) for k in _GROUPS])
            col, icol = rec.blocks, rec.int_blocks
            offsets = (ctypes.c_long * 7)(col["ref"].start, col["plant"].start,
                                          col["dist"].start, col["ctrl"].start,
                                          icol["ctrl"].start, icol["ctrl_bool"].start,
                                          icol["plant"].start)
            self._keep = (fns, comps, vrs, counts, offsets)
            self._args = (fns, comps, vrs, counts, rec.data.ctypes.data,
                          rec.data.strides[0] // rec.data.itemsize, rec.ints.ctypes.data,
                          rec.ints.strides[0] // rec.ints.itemsize,
                          _address(rec.data, rec.spare), offsets)
        return self._args

    def steps(self, first: int, last: int, t0: float) -> None:
        """Run rows first..last (exclusive) from t0 in the C step kernel (libfp_cosim)."""
        if self._lib.fp_cosim_steps(*self._arguments(), t0, self.h, int(self.jacobi), first,
                                    last, ctypes.byref(self._failed)):
            k = int(self._failed.value)
            self.fail(t0 + k * self.h, k)


def make_engine(name: str, plant: FmuInstance, ctrl: FmuInstance | None, conn: Connections,
                rec: Recording, h: float, coupling: str = "gauss-seidel") -> Engine:
    """The engine ``name`` (one of :data:`ENGINES`) for a coupling of :data:`COUPLINGS`."""
    if name not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {name!r}")
    if coupling not in COUPLINGS:
        raise ValueError(f"coupling must be one of {COUPLINGS}, got {coupling!r}")
    kind = NativeEngine if name == "native" else PythonEngine
    return kind(plant, ctrl, conn, rec, h, coupling == "jacobi")
