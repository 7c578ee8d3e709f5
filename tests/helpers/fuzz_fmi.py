"""A seeded FMI 2.0 call-sequence fuzzer for the plant and controller FMUs.

Random but bounded sequences of FMI 2.0 co-simulation calls, through raw ctypes on the FMU's
shared library (the fmi2 prototypes are declared here; fmpy only extracts the FMU and reads
its modelDescription): instantiate / free (several instances at once), setupExperiment,
enter / exit initialization, terminate, reset, get / set of every type with valid, wrong-type
and unknown value references, NULL arrays, NaN / inf / 1e300 values, doStep with valid, odd,
invalid and huge step sizes, FMU states (get, set, reuse, free, serialize, deserialize, with
corrupt, truncated, extended and foreign buffers: the other FMU's serialized state and state
objects), the status functions, SetDebugLogging and the optional functions the FMUs do not
provide.

Oracle, per call:
- no crash and no hang (each batch runs in child processes: a signal or a stall ends the
  child, is recorded as a finding and the batch goes on with the next episode);
- fmi2GetReal answering fmi2OK / fmi2Warning returns only finite outputs (every output
  variable read is checked), fmi2GetBoolean only 0 or 1;
- every non-OK return comes with at least one message of status >= fmi2Warning, logged for
  that instance during that call;
- every call the FMI 2.0 co-simulation state machine (FMI 2.0.4, section 4.2.4, the table of
  functions per state) forbids in the current state, or with invalid arguments (unknown value
  reference, an output or a fixed parameter set after initialization, NULL arrays, a step
  that is not positive or not at the current time) is refused with fmi2Error.  The expected
  state is tracked here from the calls and their statuses: fmi2Error puts the instance into
  Error, fmi2Fatal into Fatal, fmi2Discard from doStep into StepFailed; a restored FMU state
  brings back the state it was saved in;
- the memory the FMU gets from the importer's allocator (ours: every block in its own pages,
  ending at a PROT_NONE guard page, freed blocks kept PROT_NONE for a while) is neither
  overrun (a write or read past a block faults at once and is counted as a crash of that
  call), nor freed twice, nor freed when not ours.

Calls on an instance after fmi2FreeInstance are undefined behaviour by the standard; they
run only with ``use_after_free=True`` (``--use-after-free``), never by default.

The call index of a finding is ``1000 * episode + k`` (k: the call within the episode; an
episode is ``episode_calls`` calls, then cleanup calls).  ``--seed S --episode E`` replays
one episode.  Usage::

    python tests/helpers/fuzz_fmi.py --calls 5000 --seed 1 --fmu both
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import math
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

EPISODE_STRIDE = 1000
MODELS = {"plant": "MultirotorPlant", "controller": "FullPoseController"}

# --------------------------------------------------------------------------- #
# findings and the report (parent side)


@dataclass(frozen=True)
class Finding:
    seed: int
    index: int
    kind: str
    description: str
    fmu: str = ""
    call: str = ""


@dataclass
class FuzzReport:
    fmu: str
    seed: int
    findings: list[Finding] = field(default_factory=list)
    calls: int = 0  # calls on the fuzzed FMU
    helper_calls: int = 0  # calls on the other FMU (foreign states)
    episodes: int = 0
    state_calls: Counter = field(default_factory=Counter)  # by expected state
    children: int = 0  # child processes (a crash or a hang starts a new one)
    crashes: int = 0
    hangs: int = 0
    seconds: float = 0.0
    truncated: bool = False

    def by_kind(self) -> Counter:
        return Counter(f.kind for f in self.findings)

    def distinct(self) -> dict[tuple[str, str], list[Finding]]:
        """Findings grouped by kind and description with the numbers taken out."""
        seen: dict[tuple[str, str], list[Finding]] = {}
        for f in self.findings:
            key = re.sub(r"[-+]?(\d[\d.]*(e[-+]?\d+)?|nan|inf)", "#", f.description)
            seen.setdefault((f.kind, key), []).append(f)
        return seen

    def triples(self) -> list[tuple[int, int, str]]:
        """The findings as (seed, call index, description)."""
        return [(f.seed, f.index, f"[{f.kind}] {f.description} <- {f.call}")
                for f in self.findings]

    def summary(self, max_lines: int = 40) -> str:
        kinds = self.by_kind()
        lines = [
            f"{self.fmu}: {self.calls} calls ({self.helper_calls} helper calls on the other "
            f"FMU), {self.episodes} episodes in {self.children} child processes, "
            f"{self.seconds:.1f} s; {self.crashes} crashes, {self.hangs} hangs, "
            f"{len(self.findings)} findings" + (" (time budget exhausted)" if self.truncated
                                                else "")
        ]
        if self.state_calls:
            lines.append("  calls by expected state: " + ", ".join(
                f"{k} {v}" for k, v in self.state_calls.most_common()))
        for kind, n in sorted(kinds.items()):
            lines.append(f"  {kind}: {n}")
        # one line per distinct (kind, description), with the first (seed, index)
        seen = self.distinct()
        for (kind, _), fs in list(seen.items())[:max_lines]:
            first = fs[0]
            lines.append(f"  - ({first.seed}, {first.index}) [{kind}] x{len(fs)}: "
                         f"{first.description}" + (f"  <- {first.call}" if first.call else ""))
        if len(seen) > max_lines:
            lines.append(f"  ... {len(seen) - max_lines} more distinct findings")
        return "\n".join(lines)


# --------------------------------------------------------------------------- #
# ctypes declarations of the FMI 2.0 API (child side)

c_vp = ctypes.c_void_p
LOGGER = ctypes.CFUNCTYPE(None, c_vp, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                          ctypes.c_char_p)
ALLOC = ctypes.CFUNCTYPE(c_vp, ctypes.c_size_t, ctypes.c_size_t)
FREE = ctypes.CFUNCTYPE(None, c_vp)
STEP_FINISHED = ctypes.CFUNCTYPE(None, c_vp, ctypes.c_int)


class Callbacks(ctypes.Structure):
    _fields_ = [("logger", LOGGER), ("allocateMemory", ALLOC), ("freeMemory", FREE),
                ("stepFinished", STEP_FINISHED), ("componentEnvironment", c_vp)]


_I, _D, _S = ctypes.c_int, ctypes.c_double, ctypes.c_size_t
PROTOTYPES = {
    "fmi2GetTypesPlatform": (ctypes.c_char_p, []),
    "fmi2GetVersion": (ctypes.c_char_p, []),
    "fmi2SetDebugLogging": (_I, [c_vp, _I, _S, c_vp]),
    "fmi2Instantiate": (c_vp, [ctypes.c_char_p, _I, ctypes.c_char_p, ctypes.c_char_p, c_vp,
                               _I, _I]),
    "fmi2FreeInstance": (None, [c_vp]),
    "fmi2SetupExperiment": (_I, [c_vp, _I, _D, _D, _I, _D]),
    "fmi2EnterInitializationMode": (_I, [c_vp]),
    "fmi2ExitInitializationMode": (_I, [c_vp]),
    "fmi2Terminate": (_I, [c_vp]),
    "fmi2Reset": (_I, [c_vp]),
    "fmi2GetReal": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2GetInteger": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2GetBoolean": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2GetString": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2SetReal": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2SetInteger": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2SetBoolean": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2SetString": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2GetFMUstate": (_I, [c_vp, c_vp]),
    "fmi2SetFMUstate": (_I, [c_vp, c_vp]),
    "fmi2FreeFMUstate": (_I, [c_vp, c_vp]),
    "fmi2SerializedFMUstateSize": (_I, [c_vp, c_vp, c_vp]),
    "fmi2SerializeFMUstate": (_I, [c_vp, c_vp, c_vp, _S]),
    "fmi2DeSerializeFMUstate": (_I, [c_vp, c_vp, _S, c_vp]),
    "fmi2GetDirectionalDerivative": (_I, [c_vp, c_vp, _S, c_vp, _S, c_vp, c_vp]),
    "fmi2SetRealInputDerivatives": (_I, [c_vp, c_vp, _S, c_vp, c_vp]),
    "fmi2GetRealOutputDerivatives": (_I, [c_vp, c_vp, _S, c_vp, c_vp]),
    "fmi2DoStep": (_I, [c_vp, _D, _D, _I]),
    "fmi2CancelStep": (_I, [c_vp]),
    "fmi2GetStatus": (_I, [c_vp, _I, c_vp]),
    "fmi2GetRealStatus": (_I, [c_vp, _I, c_vp]),
    "fmi2GetIntegerStatus": (_I, [c_vp, _I, c_vp]),
    "fmi2GetBooleanStatus": (_I, [c_vp, _I, c_vp]),
    "fmi2GetStringStatus": (_I, [c_vp, _I, c_vp]),
}
OK, WARNING, DISCARD, ERROR, FATAL, PENDING = range(6)
STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")

# States of the co-simulation state machine (FMI 2.0.4, 4.2.4), plus U: not known (an
# accepted corrupt state was restored), where the state-machine oracle is off.
I, N, C, F, T, E, X, U = (  # noqa: E741
    "Instantiated", "Init", "StepComplete", "StepFailed", "Terminated", "Error", "Fatal",
    "Unknown")
ALL_BUT_FATAL = frozenset({I, N, C, F, T, E})
GETTERS = frozenset({N, C, F, T, E})
ENTERS_ERROR = frozenset({"fmi2ExitInitializationMode", "fmi2DoStep"})
VARIABLE_GETS = frozenset({"fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString"})
"""The calls whose fmi2Error is a failed computation: the instance is then in Error."""

ALLOWED = {
    "fmi2SetDebugLogging": ALL_BUT_FATAL,
    "fmi2SetupExperiment": frozenset({I}),
    "fmi2EnterInitializationMode": frozenset({I}),
    "fmi2ExitInitializationMode": frozenset({N}),
    "fmi2Terminate": frozenset({C, F}),
    "fmi2Reset": ALL_BUT_FATAL,
    **{f"fmi2Get{t}": GETTERS for t in ("Real", "Integer", "Boolean", "String")},
    **{f"fmi2Set{t}": frozenset({I, N, C}) for t in ("Real", "Integer", "Boolean", "String")},
    **{fn: ALL_BUT_FATAL for fn in ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
                                    "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate",
                                    "fmi2DeSerializeFMUstate")},
    "fmi2GetDirectionalDerivative": GETTERS,
    "fmi2SetRealInputDerivatives": frozenset({I, N, C}),
    "fmi2GetRealOutputDerivatives": frozenset({C, F, T, E}),
    "fmi2DoStep": frozenset({C}),
    "fmi2CancelStep": frozenset(),  # only in stepInProgress: never, our steps are synchronous
    **{f"fmi2Get{t}Status": frozenset({C, F, T})
       for t in ("", "Real", "Integer", "Boolean", "String")},
}

ACTION_FN = {
    "setup": "fmi2SetupExperiment", "enter": "fmi2EnterInitializationMode",
    "exit": "fmi2ExitInitializationMode", "terminate": "fmi2Terminate", "reset": "fmi2Reset",
    "set_real": "fmi2SetReal", "set_int": "fmi2SetInteger", "set_bool": "fmi2SetBoolean",
    "set_string": "fmi2SetString", "get_real": "fmi2GetReal", "get_int": "fmi2GetInteger",
    "get_bool": "fmi2GetBoolean", "get_string": "fmi2GetString", "step": "fmi2DoStep",
    "status": "fmi2GetStatus", "unsupported": "fmi2CancelStep",
}

SPECIAL_REALS = (math.nan, math.inf, -math.inf, 1e300, -1e300, 1e15, -1e15, 1000.0, -1000.0,
                 1e6, 0.0, -0.0, 5e-324, 1e-300, -1e-300)
SPECIAL_INTS = (-(2**31), 2**31 - 1, -1, 0, 1, 2, 3, 7, 8, 9, 64, 65, 100, 1000)


# --------------------------------------------------------------------------- #
# guarded allocator: every block ends at a PROT_NONE page, freed blocks stay PROT_NONE


class GuardedHeap:
    PROT_NONE, PROT_RW = 0, 3
    QUARANTINE = 512

    def __init__(self, report) -> None:
        self.libc = ctypes.CDLL(None, use_errno=True)
        self.libc.mmap.restype = c_vp
        self.libc.mmap.argtypes = [c_vp, _S, _I, _I, _I, ctypes.c_long]
        self.libc.mprotect.argtypes = [c_vp, _S, _I]
        self.libc.munmap.argtypes = [c_vp, _S]
        self.page = os.sysconf("SC_PAGE_SIZE")
        self.blocks: dict[int, list] = {}  # ptr -> [base, total, n, span, freed, owner]
        self.quarantine: list[int] = []
        self.report = report  # report(kind, description)
        self.fail_rate = 0.0
        self.rng = random.Random(0)
        self.c_alloc = ALLOC(self._alloc_cb)
        self.c_free = FREE(self._free_cb)

    def alloc(self, n: int, owner: str) -> int | None:
        span = max(16, (n + 15) // 16 * 16)
        pages = (span + self.page - 1) // self.page + 1
        total = pages * self.page
        base = self.libc.mmap(None, total, self.PROT_RW, 0x02 | 0x20, -1, 0)  # PRIVATE|ANON
        if base in (None, ctypes.c_void_p(-1).value):
            return None
        self.libc.mprotect(base + total - self.page, self.page, self.PROT_NONE)
        ptr = base + total - self.page - span
        if span > n:
            ctypes.memset(ptr + n, 0xA5, span - n)
        self.blocks[ptr] = [base, total, n, span, False, owner]
        return ptr

    def _alloc_cb(self, nobj: int, size: int) -> int | None:
        try:
            n = nobj * size
            if n > (1 << 31):
                return None
            if self.fail_rate and self.rng.random() < self.fail_rate:
                return None  # injected out-of-memory
            return self.alloc(n, "fmu")
        except Exception as exc:  # never let an exception cross into C
            self.report("harness", f"allocator: {exc!r}")
            return None

    def check(self, ptr: int, what: str) -> None:
        _base, _total, n, span, freed, owner = self.blocks[ptr]
        if not freed and span > n and ctypes.string_at(ptr + n, span - n) != b"\xa5" * (span - n):
            self.report("heap_overflow", f"{what}: bytes written past the end of a "
                        f"{n}-byte block ({owner})")

    def release(self, ptr: int, by_fmu: bool = False) -> None:
        blk = self.blocks.get(ptr)
        if blk is None:
            self.report("bad_free", "freeMemory called with a pointer the allocator never "
                        "returned")
            return
        if blk[4]:
            self.report("double_free", f"freeMemory called twice on a {blk[2]}-byte block")
            return
        if by_fmu and blk[5] != "fmu":
            self.report("bad_free", f"the FMU freed a {blk[2]}-byte buffer owned by the "
                        "importer")
            return
        self.check(ptr, "freeMemory")
        blk[4] = True
        self.libc.mprotect(blk[0], blk[1], self.PROT_NONE)
        self.quarantine.append(ptr)
        if len(self.quarantine) > self.QUARANTINE:
            old = self.quarantine.pop(0)
            ob = self.blocks.pop(old)
            self.libc.munmap(ob[0], ob[1])

    def _free_cb(self, ptr: int | None) -> None:
        try:
            if ptr:
                self.release(ptr, by_fmu=True)
        except Exception as exc:
            self.report("harness", f"free: {exc!r}")

    def size_of(self, ptr: int) -> int | None:
        blk = self.blocks.get(ptr)
        return None if blk is None or blk[4] else blk[2]

    def is_live(self, ptr: int) -> bool:
        blk = self.blocks.get(ptr)
        return blk is not None and not blk[4]

    def check_all(self, what: str) -> None:
        for ptr in list(self.blocks):
            self.check(ptr, what)


# --------------------------------------------------------------------------- #
# the child: one process runs a range of episodes


class Model:
    """One loaded FMU binary and what its modelDescription says."""

    def __init__(self, spec: dict) -> None:
        self.key = spec["key"]
        self.name = spec["model"]
        self.guid = spec["guid"].encode()
        self.resources = spec["resources"].encode()
        self.dll = ctypes.CDLL(spec["dll"])
        for fn, (res, args) in PROTOTYPES.items():
            f = getattr(self.dll, fn)
            f.restype, f.argtypes = res, args
        self.vars = spec["variables"]  # list of [name, vr, type, causality, variability, start]
        self.by_type: dict[str, list] = {}
        for v in self.vars:
            self.by_type.setdefault(v[2], []).append(v)
        self.vr_of = {(v[1], v[2]): v for v in self.vars}
        self.all_vrs = sorted({v[1] for v in self.vars})
        self.categories = [c.encode() for c in spec["categories"]]
        self.caps = spec["caps"]


@dataclass
class Inst:
    model: Model
    handle: int
    name: bytes
    env: int
    cb: Callbacks
    state: str = I
    pre_error: str | None = None
    error_from: str = ""
    time: float | None = 0.0
    set_up: bool = False


@dataclass
class StateObj:
    ptr: int
    model: Model  # the FMU that made it
    meta: tuple | None  # (state, pre_error, time) it was saved in, None: unknown


class Child:
    def __init__(self, specs: dict, opts: dict, journal) -> None:
        self.opts = opts
        self.seed = int(opts["seed"])
        self.journal = journal
        self.heap = GuardedHeap(self.finding)
        self.target = Model(specs["target"])
        self.other = Model(specs["other"])
        self.messages: dict[int, list[tuple[int, str]]] = {}
        self.c_logger = LOGGER(self._log)
        self.next_env = 1
        self.idx = 0
        self.calls = 0
        self.helper_calls = 0
        self.plant_bug = opts.get("plant_bug")
        self.planted = False  # the planted crash or hang has happened (self-tests)
        self.allow_huge = bool(opts.get("allow_huge", True))
        self.uaf = bool(opts.get("use_after_free", False))
        self.helper: Inst | None = None
        self.n_findings = 0
        self.state_calls: Counter = Counter()

    # -- journal ---------------------------------------------------------------

    def write(self, line: str) -> None:
        os.write(self.journal, (line.replace("\n", " ") + "\n").encode(errors="replace"))

    def finding(self, kind: str, description: str, detail: str = "") -> None:
        self.n_findings += 1
        self.reported_this_call = True
        call = f"{self.cur_fn}; {detail}" if detail else self.cur_fn
        self.write("F " + json.dumps({"index": self.idx, "kind": kind,
                                      "description": description, "call": call}))

    cur_fn = ""
    reported_this_call = False

    # -- callbacks -------------------------------------------------------------

    def _log(self, env, name, status, category, message) -> None:
        try:
            self.messages.setdefault(env or 0, []).append(
                (status, (message or b"").decode(errors="replace")[:200]))
        except Exception:
            pass

    def callbacks(self, env: int) -> Callbacks:
        cb = Callbacks()
        cb.logger = self.c_logger
        cb.allocateMemory = self.heap.c_alloc
        cb.freeMemory = self.heap.c_free
        cb.stepFinished = STEP_FINISHED()
        cb.componentEnvironment = env
        return cb

    # -- one checked call ------------------------------------------------------

    def call(self, inst: Inst | None, model: Model, fn: str, args: list, desc: str,
             *, expect_refusal: str = "", helper: bool = False, env: int = 0):
        """Journal, call, and check the message rule; returns the status (or handle)."""
        if helper:
            self.helper_calls += 1
        else:
            self.calls += 1
            self.write(f"C {self.idx} {model.key} {fn} {desc}")
        self.cur_fn = f"{fn}({desc})"
        self.reported_this_call = False
        if inst is not None and not helper:
            self.state_calls[inst.state] += 1
        env = inst.env if inst is not None else env
        before = len(self.messages.get(env, ()))
        f = getattr(model.dll, fn)
        bug = self.plant_bug if not helper else None
        if bug in ("crash", "hang") and self.calls >= 200 and not self.planted:
            self.planted = True  # the first own call from the 200th on (helpers do not count)
            if bug == "crash":
                ctypes.string_at(0)  # planted crash (self-test)
            time.sleep(3600)  # planted hang (self-test)
        if bug == "accept_forbidden" and fn == "fmi2DoStep" and inst is not None \
                and inst.state == I:
            result = OK  # planted: an FMU that steps before initialization
        elif bug == "silent_error" and fn == "fmi2GetInteger":
            result = ERROR  # planted: an error without a message
        else:
            result = f(*args)
        if bug == "nan_output" and fn == "fmi2GetReal" and result in (OK, WARNING) \
                and args[3] is not None:
            args[3][0] = math.nan  # planted: a NaN output with fmi2OK
        if helper or fn in ("fmi2FreeInstance", "fmi2GetTypesPlatform", "fmi2GetVersion"):
            return result
        status = result if fn != "fmi2Instantiate" else (OK if result else ERROR)
        if status != OK:
            new = self.messages.get(env, [])[before:]
            if not any(s >= WARNING for s, _ in new):
                note = expect_refusal or ("allocation failures injected"
                                          if self.heap.fail_rate else "")
                self.finding("silent_nonok", f"{fn} returned {STATUS[status]} without a "
                             f"message{' (' + note + ')' if note else ''}")
        return result

    # -- the state machine model ----------------------------------------------

    def transition(self, inst: Inst, fn: str, status: int, legal: bool, why: str,
                   on_ok=None) -> None:
        """Checks refusal of a forbidden call and moves the expected state."""
        if inst.state == U:
            if status in (OK, WARNING) and on_ok is not None:
                on_ok()
            elif status == FATAL:
                inst.state = X
            return
        if not legal:
            if status in (ERROR, FATAL):
                pass  # refused, as it must be
            elif inst.state == E and inst.pre_error is not None and \
                    fn in ALLOWED and inst.pre_error in ALLOWED[fn] and not why.startswith("arg"):
                self.finding("error_state_not_kept", f"after returning fmi2Error from "
                             f"{inst.error_from} the FMU is not in Error: a later call "
                             "the Error state forbids is accepted",
                             f"{fn} answered {STATUS[status]}, as if in {inst.pre_error}")
                inst.state, inst.pre_error = inst.pre_error, None
            elif not self.reported_this_call:
                self.finding("forbidden_accepted", f"{fn} answered {STATUS[status]} in state "
                             f"{inst.state}: {why}")
        if status == ERROR:
            # docs/robustness.md: a call refused before it changes anything (a forbidden call,
            # a bad argument, a rejected state buffer) leaves the instance as it was; a failed
            # computation (initialization, a step) puts it in Error.  A get with valid
            # arguments in Initialization mode runs the initialization: its fmi2Error is a
            # refused initialization.
            if legal and (fn in ENTERS_ERROR or (inst.state == N and fn in VARIABLE_GETS)):
                if inst.state != E:
                    inst.pre_error, inst.error_from = inst.state, fn
                inst.state = E
        elif status == FATAL:
            inst.state = X
        elif status == DISCARD and fn == "fmi2DoStep":
            inst.state = F
        elif status in (OK, WARNING) and on_ok is not None:
            on_ok()

    def legal(self, inst: Inst, fn: str) -> tuple[bool, str]:
        if inst.state == U:
            return True, ""
        if fn in ("fmi2GetDirectionalDerivative",) and not self.target.caps["dd"]:
            return False, "providesDirectionalDerivative is false"
        if fn == "fmi2SetRealInputDerivatives" and not self.target.caps["interp"]:
            return False, "canInterpolateInputs is false"
        if fn == "fmi2GetRealOutputDerivatives" and self.target.caps["max_order"] < 1:
            return False, "maxOutputDerivativeOrder is 0"
        if inst.state in ALLOWED.get(fn, ()):
            return True, ""
        return False, f"not allowed in state {inst.state}"

    # -- instances -------------------------------------------------------------

    def instantiate(self, model: Model, rng: random.Random, helper: bool = False,
                    variant: str = "ok") -> Inst | None:
        env = self.next_env
        self.next_env += 1
        name = f"{model.key}{env}".encode()
        cb = self.callbacks(env)
        guid, kind, nm = model.guid, 1, name
        if variant == "bad_guid":
            guid = b"{00000000-0000-0000-0000-000000000000}"
        elif variant == "null_guid":
            guid = None
        elif variant == "model_exchange":
            kind = 0
        elif variant == "empty_name":
            nm = b""
        elif variant == "null_name":
            nm = None
        logging_on = int(rng.random() < 0.2)
        handle = self.call(None, model, "fmi2Instantiate",
                           [nm, kind, guid, model.resources, ctypes.addressof(cb),
                            int(rng.random() < 0.5), logging_on], f"variant={variant}",
                           helper=helper, env=env)
        if variant == "model_exchange" and model.caps["me"]:
            # a Model Exchange FMU too (the plant): accepted; its calls are fuzzed by
            # tests/test_fmus/test_model_exchange.py, not here
            if not handle and self.heap.fail_rate == 0.0:
                self.finding("instantiate_failed", "fmi2Instantiate(model_exchange) returned "
                             "NULL for an FMU with <ModelExchange>")
            if handle:
                model.dll.fmi2FreeInstance(handle)
            return None
        if variant != "ok":
            if handle:
                self.finding("forbidden_accepted", f"fmi2Instantiate({variant}) returned an "
                             "instance")
                model.dll.fmi2FreeInstance(handle)
            return None
        if not handle:
            if self.heap.fail_rate == 0.0:
                self.finding("instantiate_failed", "fmi2Instantiate returned NULL for valid "
                             "arguments")
            return None
        return Inst(model, handle, name, env, cb)

    def free_instance(self, inst: Inst, helper: bool = False) -> None:
        self.call(inst, inst.model, "fmi2FreeInstance", [inst.handle], inst.name.decode(),
                  helper=helper)
        self.messages.pop(inst.env, None)

    def initialized(self, model: Model, rng: random.Random) -> Inst | None:
        """A helper instance of `model`, initialized with its defaults (not checked)."""
        inst = self.instantiate(model, rng, helper=True)
        if inst is None:
            return None
        h = inst.handle
        ok = self.call(inst, model, "fmi2SetupExperiment", [h, 0, 0.0, 0.0, 0, 0.0], "",
                       helper=True) == OK
        ok = ok and self.call(inst, model, "fmi2EnterInitializationMode", [h], "",
                              helper=True) == OK
        ok = ok and self.call(inst, model, "fmi2ExitInitializationMode", [h], "",
                              helper=True) <= WARNING
        inst.state = C if ok else E
        return inst

    # -- value generation ------------------------------------------------------

    def pick_vars(self, rng: random.Random, inst: Inst, typ: str, setting: bool):
        """(value refs with their variables (None: unknown vr), why the call is forbidden).

        Most calls use only variables the call may use in the expected state; about one in
        ten has one bad element: an unknown or wrong-type value reference, or (setting) an
        output or a fixed parameter after initialization."""
        m = inst.model
        n = rng.choice((1, 1, 1, 2, 3, 5, 12)) if rng.random() < 0.97 else 0
        pool = m.by_type.get(typ, [])

        def settable(v) -> bool:
            caus, var = v[3], v[4]
            if caus in ("output", "calculatedParameter", "local") or var == "constant":
                return False
            if caus == "parameter" and var == "fixed":
                return inst.state in (I, N, U)
            return True

        if setting:
            inputs = [v for v in pool if v[3] == "input"]
            ok_pool = [v for v in pool if settable(v)]
            good = inputs if inputs and rng.random() < 0.6 else ok_pool
        else:
            outs = [v for v in pool if v[3] == "output"]
            good = outs if outs and rng.random() < 0.7 else pool
        chosen = [(v[1], v) for v in (rng.choice(good) for _ in range(n))] if good else []
        why = ""
        if n and (rng.random() < 0.1 or not good):
            r = rng.random()
            if r < 0.4 or not pool:
                vr = rng.choice((rng.randrange(0, 6000), 2**32 - 1, 2**31, max(m.all_vrs) + 1))
                v = m.vr_of.get((vr, typ))
            elif r < 0.7:
                other = [t for t in m.by_type if t != typ]
                v2 = rng.choice(m.by_type[rng.choice(other)]) if other else rng.choice(pool)
                vr, v = v2[1], m.vr_of.get((v2[1], typ))
            else:
                v = rng.choice(pool)
                vr = v[1]
            if v is None:
                why = f"unknown value reference {vr} of type {typ}"
            elif setting and not settable(v) and inst.state != U:
                why = f"{v[0]} ({v[3]}, {v[4]}) may not be set in {inst.state}"
            chosen[rng.randrange(len(chosen)) if chosen else 0:0] = [(vr, v)]
        elif not good and n:
            why = f"no variable of type {typ}"
        return chosen, why

    def real_value(self, rng: random.Random, v) -> float:
        if rng.random() < 0.25 or v is None:
            return rng.choice(SPECIAL_REALS)
        start = v[5] if isinstance(v[5], (int, float)) else 0.0
        if rng.random() < 0.5:
            return float(start)
        return float(start) + rng.gauss(0.0, 0.1 * (abs(start) + 0.1))

    def int_value(self, rng: random.Random, v, boolean: bool) -> int:
        if boolean:
            return rng.choice((0, 1, 1, 0, 2, -1)) if rng.random() < 0.3 else int(bool(v and v[5]))
        if rng.random() < 0.3 or v is None:
            return rng.choice(SPECIAL_INTS)
        start = int(v[5]) if isinstance(v[5], (int, float, bool)) else 0
        return start if rng.random() < 0.6 else start + rng.choice((-1, 1))

    # -- actions ---------------------------------------------------------------

    def act_set(self, rng, inst: Inst, typ: str) -> None:
        fn = {"Real": "fmi2SetReal", "Integer": "fmi2SetInteger",
              "Boolean": "fmi2SetBoolean", "String": "fmi2SetString"}[typ]
        chosen, why = self.pick_vars(rng, inst, typ, setting=True)
        legal, lwhy = self.legal(inst, fn)
        n = len(chosen)
        vrs = (ctypes.c_uint * max(n, 1))(*[c[0] for c in chosen])
        if typ == "Real":
            vals = (ctypes.c_double * max(n, 1))(*[self.real_value(rng, c[1]) for c in chosen])
        elif typ == "String":
            vals = (ctypes.c_char_p * max(n, 1))(*[b"x" for _ in chosen])
        else:
            vals = (ctypes.c_int * max(n, 1))(
                *[self.int_value(rng, c[1], typ == "Boolean") for c in chosen])
        null = rng.random() < 0.03 and n > 0
        if null:
            why = "arg: NULL array with nvr > 0"
            if rng.random() < 0.5:
                vrs = None
            else:
                vals = None
        desc = f"{inst.name.decode()} n={n} vr={[c[0] for c in chosen][:4]}" + \
            (f" v={list(vals)[:3]}" if vals is not None and typ != "String" else "")
        st = self.call(inst, inst.model, fn, [inst.handle, vrs, n, vals], desc,
                       expect_refusal=why or lwhy)
        if typ == "String" and n > 0:
            why = why or "no String variables"
        ok = legal and not why
        self.transition(inst, fn, st, ok, why or lwhy)

    def act_get(self, rng, inst: Inst, typ: str) -> None:
        fn = {"Real": "fmi2GetReal", "Integer": "fmi2GetInteger",
              "Boolean": "fmi2GetBoolean", "String": "fmi2GetString"}[typ]
        chosen, why = self.pick_vars(rng, inst, typ, setting=False)
        legal, lwhy = self.legal(inst, fn)
        n = len(chosen)
        vrs = (ctypes.c_uint * max(n, 1))(*[c[0] for c in chosen])
        ctype = {"Real": ctypes.c_double, "String": ctypes.c_char_p}.get(typ, ctypes.c_int)
        vals = (ctype * max(n, 1))()
        if rng.random() < 0.03 and n > 0:
            why = "arg: NULL array with nvr > 0"
            vrs, vals = (None, vals) if rng.random() < 0.5 else (vrs, None)
        if typ == "String" and n > 0:
            why = why or "no String variables"
        desc = f"{inst.name.decode()} n={n} vr={[c[0] for c in chosen][:4]}"
        st = self.call(inst, inst.model, fn, [inst.handle, vrs, n, vals], desc,
                       expect_refusal=why or lwhy)
        if st in (OK, WARNING) and vals is not None:
            for (_vr, v), x in zip(chosen, vals, strict=False):
                if v is None:
                    continue
                if typ == "Real" and v[3] == "output" and not math.isfinite(x):
                    self.finding("nonfinite_output", f"{fn} answered {STATUS[st]} with "
                                 f"{v[0]} = {x} in state {inst.state}")
                if typ == "Boolean" and x not in (0, 1):
                    self.finding("bad_boolean", f"{v[0]} = {x}")
        self.transition(inst, fn, st, legal and not why, why or lwhy)

    STEPS_VALID = (0.002, 0.002, 0.002, 0.002, 0.004, 0.006, 0.01, 0.02)
    STEPS_ODD = (0.0005, 0.001, 0.0015, 0.0013, 0.00200001, 0.0020000000001, 1e-9, 1e-300,
                 5e-324, 0.2, 1.0, 3.0)
    STEPS_BAD = (0.0, -0.0, -0.002, math.nan, math.inf, -math.inf)
    STEPS_HUGE = (1e6, 1e15, 1e300, 3600.0)

    def act_step(self, rng, inst: Inst) -> None:
        r = rng.random()
        if r < 0.80:
            h = rng.choice(self.STEPS_VALID)
        elif r < 0.93:
            h = rng.choice(self.STEPS_ODD)
        elif r < 0.99 or not self.allow_huge:
            h = rng.choice(self.STEPS_BAD)
        else:
            h = rng.choice(self.STEPS_HUGE)
        t = inst.time if inst.time is not None else rng.choice((0.0, 0.002, 1.0))
        why = ""
        if rng.random() < 0.05:
            t = rng.choice((t + 0.001, t - 0.002, math.nan, -1.0, t + 1e3))
            if inst.time is not None and not (abs(t - inst.time) <= 1e-9 * (1 + abs(inst.time))):
                why = f"arg: currentCommunicationPoint {t} is not the FMU time {inst.time}"
        if not (h > 0 and math.isfinite(h)):
            why = why or f"arg: communicationStepSize {h} is not positive and finite"
        legal, lwhy = self.legal(inst, "fmi2DoStep")
        st = self.call(inst, inst.model, "fmi2DoStep",
                       [inst.handle, t, h, int(rng.random() < 0.5)],
                       f"{inst.name.decode()} t={t!r} h={h!r}", expect_refusal=why or lwhy)

        def advance() -> None:
            inst.time = t + h if inst.time is not None else None
        self.transition(inst, "fmi2DoStep", st, legal and not (why and inst.time is not None),
                        why or lwhy, advance)

    def act_simple(self, rng, inst: Inst, fn: str) -> None:
        legal, why = self.legal(inst, fn)
        args = [inst.handle]
        on_ok = None
        desc = inst.name.decode()
        if fn == "fmi2SetupExperiment":
            start = rng.choice((0.0, 0.0, 0.0, 1.5, -3.0, 1e9)) if rng.random() < 0.9 else \
                rng.choice((math.nan, math.inf, 1e300))
            stop_def = int(rng.random() < 0.3)
            stop = start + rng.choice((10.0, 0.0, -1.0, math.nan))
            args += [int(rng.random() < 0.5), rng.choice((1e-6, 0.0, -1.0, math.nan)), start,
                     stop_def, stop]
            desc += f" start={start} stopDefined={stop_def} stop={stop}"
            if not math.isfinite(start) or (stop_def and not stop >= start):
                why = why or "arg: invalid experiment interval"
                legal = False

            def on_ok() -> None:
                inst.time = start
        elif fn == "fmi2EnterInitializationMode":
            def on_ok() -> None:
                inst.state = N
        elif fn == "fmi2ExitInitializationMode":
            def on_ok() -> None:
                inst.state = C
        elif fn == "fmi2Terminate":
            def on_ok() -> None:
                inst.state = T
        elif fn == "fmi2Reset":
            def on_ok() -> None:
                inst.state, inst.pre_error, inst.time = I, None, 0.0
        elif fn == "fmi2CancelStep":
            pass
        st = self.call(inst, inst.model, fn, args, desc, expect_refusal=why)
        self.transition(inst, fn, st, legal, why, on_ok)

    def act_status(self, rng, inst: Inst) -> None:
        typ = rng.choice(("", "Real", "Integer", "Boolean", "String"))
        fn = f"fmi2Get{typ}Status"
        kind = rng.choice((0, 1, 2, 3, 4, 2, 3, -1, 99))
        ctype = {"Real": ctypes.c_double, "String": ctypes.c_char_p}.get(typ, ctypes.c_int)
        val = ctype()
        ptr = None if rng.random() < 0.05 else ctypes.byref(val)
        legal, why = self.legal(inst, fn)
        if ptr is None:
            why, legal = why or "arg: NULL value pointer", False
        st = self.call(inst, inst.model, fn, [inst.handle, kind, ptr],
                       f"{inst.name.decode()} kind={kind}{' value=NULL' if ptr is None else ''}",
                       expect_refusal=why)
        if st == OK and legal and fn == "fmi2GetRealStatus" and inst.time is not None \
                and inst.state != U and not math.isclose(val.value, inst.time, abs_tol=1e-9):
            self.finding("wrong_status", f"fmi2LastSuccessfulTime = {val.value}, the last "
                         f"successful step ended at {inst.time}")
        self.transition(inst, fn, st, legal, why)

    def act_debug(self, rng, inst: Inst) -> None:
        cats = list(inst.model.categories)
        r = rng.random()
        why = ""
        if r < 0.3:
            chosen = []
        elif r < 0.8:
            chosen = rng.sample(cats, rng.randint(1, len(cats)))
        elif r < 0.9:
            chosen = [rng.choice(cats), b"noSuchCategory"]
            why = "arg: unknown category"
        else:
            chosen = [None]
            why = "arg: NULL category"
        arr = (ctypes.c_char_p * max(1, len(chosen)))(*chosen)
        n = len(chosen)
        if rng.random() < 0.05:
            arr, n, why = None, 2, "arg: NULL categories with nCategories > 0"
        legal, lwhy = self.legal(inst, "fmi2SetDebugLogging")
        st = self.call(inst, inst.model, "fmi2SetDebugLogging",
                       [inst.handle, int(rng.random() < 0.6), n, arr],
                       f"{inst.name.decode()} n={n} {chosen[:3]}", expect_refusal=why or lwhy)
        self.transition(inst, "fmi2SetDebugLogging", st, legal and not why, why or lwhy)

    def act_unsupported(self, rng, inst: Inst) -> None:
        fn = rng.choice(("fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives",
                         "fmi2GetRealOutputDerivatives", "fmi2CancelStep"))
        vr = (ctypes.c_uint * 1)(inst.model.vars[-1][1])
        d = (ctypes.c_double * 1)(1.0)
        order = (ctypes.c_int * 1)(1)
        args = {"fmi2GetDirectionalDerivative": [inst.handle, vr, 1, vr, 1, d, d],
                "fmi2SetRealInputDerivatives": [inst.handle, vr, 1, order, d],
                "fmi2GetRealOutputDerivatives": [inst.handle, vr, 1, order, d],
                "fmi2CancelStep": [inst.handle]}[fn]
        legal, why = self.legal(inst, fn)
        st = self.call(inst, inst.model, fn, args, inst.name.decode(), expect_refusal=why)
        self.transition(inst, fn, st, legal, why)

    # -- FMU states ------------------------------------------------------------

    def meta_of(self, inst: Inst) -> tuple | None:
        return None if inst.state == U else (inst.state, inst.pre_error, inst.time,
                                             inst.error_from)

    def restore(self, inst: Inst, meta: tuple | None) -> None:
        if meta is None:
            inst.state, inst.pre_error, inst.time = U, None, None
        else:
            inst.state, inst.pre_error, inst.time, inst.error_from = meta

    def act_get_state(self, rng, inst: Inst, states: list, foreign: StateObj | None) -> None:
        legal, why = self.legal(inst, "fmi2GetFMUstate")
        reuse = None
        if foreign is not None:
            reuse = foreign
        elif states and rng.random() < 0.3:
            same = [s for s in states if s.model is inst.model]
            reuse = rng.choice(same) if same else None
        box = c_vp(reuse.ptr if reuse else None)
        arg = None if rng.random() < 0.02 else ctypes.byref(box)
        if arg is None:
            why, legal = why or "arg: NULL FMUstate pointer", False
        desc = f"{inst.name.decode()} reuse=" + (
            "none" if reuse is None else f"{reuse.model.name}:{self.heap.size_of(reuse.ptr)}B")
        st = self.call(inst, inst.model, "fmi2GetFMUstate", [inst.handle, arg], desc,
                       expect_refusal=why)
        if st in (OK, WARNING) and arg is not None:
            if reuse is not None and reuse.model is not inst.model:
                self.finding("foreign_state_accepted", f"fmi2GetFMUstate overwrote a state "
                             f"object of {reuse.model.name} ({self.heap.size_of(reuse.ptr)} "
                             "bytes) with its own state")
            if box.value and (reuse is None or box.value != reuse.ptr):
                states.append(StateObj(box.value, inst.model, self.meta_of(inst)))
            elif reuse is not None:
                reuse.model, reuse.meta = inst.model, self.meta_of(inst)
        self.transition(inst, "fmi2GetFMUstate", st, legal, why)

    def act_set_state(self, rng, inst: Inst, s: StateObj | None) -> None:
        legal, why = self.legal(inst, "fmi2SetFMUstate")
        if s is not None and s.model is not inst.model:
            why, legal = why or f"arg: a state object of {s.model.name}", False
        if s is None:
            why, legal = why or "arg: NULL FMUstate", False
        desc = f"{inst.name.decode()} state=" + ("NULL" if s is None else s.model.name)
        st = self.call(inst, inst.model, "fmi2SetFMUstate",
                       [inst.handle, s.ptr if s else None], desc, expect_refusal=why)
        if st in (OK, WARNING) and s is not None and s.model is not inst.model:
            self.finding("foreign_state_accepted", f"fmi2SetFMUstate accepted a state object "
                         f"of {s.model.name}")
            inst.state = U
            return
        self.transition(inst, "fmi2SetFMUstate", st, legal, why,
                        lambda: self.restore(inst, s.meta if s else None))

    def act_free_state(self, rng, inst: Inst, states: list, s: StateObj | None) -> None:
        legal, why = self.legal(inst, "fmi2FreeFMUstate")
        box = c_vp(s.ptr if s else None)
        st = self.call(inst, inst.model, "fmi2FreeFMUstate", [inst.handle, ctypes.byref(box)],
                       f"{inst.name.decode()} state=" + ("NULL" if s is None else s.model.name),
                       expect_refusal=why)
        if st in (OK, WARNING) and s is not None:
            if box.value:
                self.finding("state_not_freed", "fmi2FreeFMUstate answered OK but left "
                             "*FMUstate non-NULL")
            if self.heap.is_live(s.ptr):
                self.finding("state_not_freed", "fmi2FreeFMUstate answered OK but did not "
                             "free the state's memory")
            else:
                states.remove(s)
        self.transition(inst, "fmi2FreeFMUstate", st, legal, why)

    def act_serialize(self, rng, inst: Inst, s: StateObj | None, blobs: list) -> None:
        m = inst.model
        legal, why = self.legal(inst, "fmi2SerializedFMUstateSize")
        size = ctypes.c_size_t(0)
        st = self.call(inst, m, "fmi2SerializedFMUstateSize",
                       [inst.handle, s.ptr if s else None, ctypes.byref(size)],
                       f"{inst.name.decode()} state=" + ("NULL" if s is None else s.model.name))
        self.transition(inst, "fmi2SerializedFMUstateSize", st, legal, why)
        if st != OK:
            return
        n = size.value
        legal, why = self.legal(inst, "fmi2SerializeFMUstate")
        r = rng.random()
        cap = n if r < 0.9 else rng.choice((n - 1, 0, n // 2, n + 8))
        if cap < n:
            why, legal = why or f"arg: buffer of {cap} bytes, {n} needed", False
        if s is None:
            why, legal = why or "arg: NULL FMUstate", False
        elif s.model is not m:
            why, legal = why or f"arg: a state object of {s.model.name}", False
        buf = self.heap.alloc(cap, "importer")
        st = self.call(inst, m, "fmi2SerializeFMUstate",
                       [inst.handle, s.ptr if s else None, buf, cap],
                       f"{inst.name.decode()} state=" + ("NULL" if s is None else
                                                         s.model.name) + f" size={cap}/{n}",
                       expect_refusal=why)
        if st in (OK, WARNING) and buf:
            data = ctypes.string_at(buf, min(cap, n))
            if s is not None and s.model is not m:
                self.finding("foreign_state_accepted", f"fmi2SerializeFMUstate serialized a "
                             f"state object of {s.model.name} "
                             f"({self.heap.size_of(s.ptr)} bytes) as {n} bytes")
            else:
                blobs.append((data, m, s.meta if s else None))
        if buf:
            self.heap.check(buf, "fmi2SerializeFMUstate's buffer")
            self.heap.release(buf)
        self.transition(inst, "fmi2SerializeFMUstate", st, legal, why)

    def act_deserialize(self, rng, inst: Inst, states: list, blobs: list,
                        foreign_blob: bytes | None) -> None:
        m = inst.model
        legal, why = self.legal(inst, "fmi2DeSerializeFMUstate")
        own = [b for b in blobs if b[1] is m]
        meta = None
        variant = "random"
        if foreign_blob is not None:
            data, variant = foreign_blob, "foreign"
            why, legal = why or f"arg: serialized by {self.other.name}", False
        elif own:
            data, _, meta = rng.choice(own)
            r = rng.random()
            if r < 0.5:
                variant = "exact"
            elif r < 0.65:
                k = rng.choice((1, 8, len(data) // 2, len(data) - 1, len(data)))
                data, variant = data[:-k] if k else data, f"truncated-{k}"
                why, legal = why or "arg: truncated", False
            elif r < 0.7:
                data, variant = data + b"\0" * rng.choice((1, 8)), "extended"
                why, legal = why or "arg: too long", False
            else:
                b = bytearray(data)
                for _ in range(rng.choice((1, 1, 2, 8))):
                    # mostly the header, sometimes anywhere
                    pos = rng.randrange(min(len(b), 96) if rng.random() < 0.5 else len(b))
                    b[pos] = rng.randrange(256)
                data, variant, meta = bytes(b), "corrupt", None
        else:
            data = bytes(rng.randrange(256) for _ in range(rng.choice((0, 16, 96))))
        reuse = None
        same = [s for s in states if s.model is m]
        if same and rng.random() < 0.2:
            reuse = rng.choice(same)
        box = c_vp(reuse.ptr if reuse else None)
        buf = self.heap.alloc(len(data), "importer")
        if buf is None:
            return
        ctypes.memmove(buf, data, len(data))
        null = rng.random() < 0.02
        if null:
            why, legal = why or "arg: NULL buffer", False
        st = self.call(inst, m, "fmi2DeSerializeFMUstate",
                       [inst.handle, None if null else buf, len(data), ctypes.byref(box)],
                       f"{inst.name.decode()} {variant} {len(data)}B reuse={reuse is not None}",
                       expect_refusal=why)
        self.heap.release(buf)
        if st in (OK, WARNING) and box.value:
            if variant == "foreign":
                self.finding("foreign_state_accepted", f"fmi2DeSerializeFMUstate accepted "
                             f"data serialized by {self.other.name}")
            elif variant.startswith(("truncated", "extended")):
                self.finding("forbidden_accepted", f"fmi2DeSerializeFMUstate accepted "
                             f"{variant} data")
            if reuse is not None:
                reuse.meta = meta
            else:
                states.append(StateObj(box.value, m, meta))
        self.transition(inst, "fmi2DeSerializeFMUstate", st, legal, why)

    # -- helper instance of the other FMU (foreign states) ---------------------

    def foreign_state(self, rng) -> StateObj | None:
        if self.helper is None:
            self.helper = self.initialized(self.other, rng)
        if self.helper is None:
            return None
        box = c_vp(None)
        h = self.helper
        if self.call(h, self.other, "fmi2GetFMUstate", [h.handle, ctypes.byref(box)], "",
                     helper=True) != OK:
            return None
        return StateObj(box.value, self.other, None)

    def foreign_bytes(self, rng) -> bytes | None:
        s = self.foreign_state(rng)
        if s is None:
            return None
        h = self.helper
        size = ctypes.c_size_t(0)
        self.call(h, self.other, "fmi2SerializedFMUstateSize", [h.handle, s.ptr,
                                                                ctypes.byref(size)], "",
                  helper=True)
        buf = (ctypes.c_char * size.value)()
        self.call(h, self.other, "fmi2SerializeFMUstate", [h.handle, s.ptr, buf, size.value],
                  "", helper=True)
        box = c_vp(s.ptr)
        self.call(h, self.other, "fmi2FreeFMUstate", [h.handle, ctypes.byref(box)], "",
                  helper=True)
        return bytes(buf)

    # -- an episode ------------------------------------------------------------

    def episode(self, ep: int, n_calls: int) -> None:
        rng = random.Random(f"fullpose-fuzz:{self.seed}:{self.target.key}:{ep}")
        self.heap.rng = random.Random(f"oom:{self.seed}:{ep}")
        self.heap.fail_rate = 0.0 if rng.random() < 0.85 else 0.05
        # a third of the episodes are "flights": mostly steps, inputs and outputs, so long
        # runs with held extreme inputs happen
        flight = rng.random() < 0.35
        insts: list[Inst] = []
        dead: list[Inst] = []
        states: list[StateObj] = []
        blobs: list = []
        m = self.target
        base = ep * EPISODE_STRIDE
        for k in range(n_calls):
            self.idx = base + k
            if not insts:
                variant = "ok" if rng.random() < 0.9 else rng.choice(
                    ("bad_guid", "null_guid", "model_exchange", "empty_name", "null_name"))
                inst = self.instantiate(m, rng, variant=variant)
                if inst is not None:
                    insts.append(inst)
                continue
            inst = rng.choice(insts)
            if self.uaf and dead and rng.random() < 0.05:
                d = rng.choice(dead)
                self.act_simple(rng, d, rng.choice(("fmi2Reset", "fmi2Terminate",
                                                    "fmi2EnterInitializationMode")))
                continue
            w = {
                "free": 0.6, "setup": 2.0, "enter": 2.5, "exit": 2.5, "terminate": 0.6,
                "reset": 0.8, "set_real": 10, "set_int": 2, "set_bool": 1.5, "set_string": 0.3,
                "get_real": 9, "get_int": 2, "get_bool": 1.5, "get_string": 0.3, "step": 12,
                "get_state": 2.5, "set_state": 2.0, "free_state": 1.2, "serialize": 2.0,
                "deserialize": 2.0, "status": 2.0, "debug": 0.8, "unsupported": 0.4,
                "platform": 0.3, "foreign": 0.25, "instantiate": 0.5 if len(insts) < 3 else 0,
            }
            if flight:
                w = {a: (x * 4 if a in ("step", "get_real") else x
                         if a in ("set_real", "setup", "enter", "exit", "reset") else x * 0.15)
                     for a, x in w.items()}
            st = inst.state
            if st == I:
                w["setup"] *= 3
                w["enter"] *= 3
            elif st == N:
                w["exit"] *= 3
            elif st == C:
                w["step"] *= 2
            elif st in (T, F):
                w["reset"] *= 4
            elif st == E:
                w["reset"] *= 15
            if st not in (U, E) and rng.random() < 0.9:
                # mostly calls the state allows, so the deeper states are reached
                w = {a: x for a, x in w.items()
                     if ACTION_FN.get(a) is None or st in ALLOWED[ACTION_FN[a]]}
            action = rng.choices(list(w), weights=list(w.values()))[0]
            if action == "instantiate":
                new = self.instantiate(m, rng)
                if new is not None:
                    insts.append(new)
            elif action == "free":
                insts.remove(inst)
                self.free_instance(inst)
                if self.uaf:
                    dead.append(inst)
            elif action in ("setup", "enter", "exit", "terminate", "reset"):
                fn = {"setup": "fmi2SetupExperiment", "enter": "fmi2EnterInitializationMode",
                      "exit": "fmi2ExitInitializationMode", "terminate": "fmi2Terminate",
                      "reset": "fmi2Reset"}[action]
                self.act_simple(rng, inst, fn)
            elif action.startswith("set_") and action != "set_state":
                self.act_set(rng, inst, {"real": "Real", "int": "Integer", "bool": "Boolean",
                                         "string": "String"}[action[4:]])
            elif action.startswith("get_") and action != "get_state":
                self.act_get(rng, inst, {"real": "Real", "int": "Integer", "bool": "Boolean",
                                         "string": "String"}[action[4:]])
            elif action == "step":
                self.act_step(rng, inst)
            elif action == "get_state":
                self.act_get_state(rng, inst, states, None)
            elif action == "set_state":
                own = [s for s in states if s.model is m]
                self.act_set_state(rng, inst, rng.choice(own) if own and rng.random() < 0.97
                                   else None)
            elif action == "free_state":
                own = [s for s in states if s.model is m]
                self.act_free_state(rng, inst, states, rng.choice(own) if own else None)
            elif action == "serialize":
                own = [s for s in states if s.model is m]
                self.act_serialize(rng, inst, rng.choice(own) if own and rng.random() < 0.97
                                   else None, blobs)
            elif action == "deserialize":
                self.act_deserialize(rng, inst, states, blobs, None)
            elif action == "status":
                self.act_status(rng, inst)
            elif action == "debug":
                self.act_debug(rng, inst)
            elif action == "unsupported":
                self.act_unsupported(rng, inst)
            elif action == "platform":
                self.calls += 1
                self.write(f"C {self.idx} {m.key} fmi2GetTypesPlatform/fmi2GetVersion")
                if m.dll.fmi2GetTypesPlatform() != b"default" or m.dll.fmi2GetVersion() != b"2.0":
                    self.finding("wrong_version", "fmi2GetTypesPlatform / fmi2GetVersion")
            elif action == "foreign":
                kind = rng.choice(("set", "get_reuse", "serialize", "deserialize", "free"))
                if kind == "deserialize":
                    blob = self.foreign_bytes(rng)
                    if blob is not None:
                        self.act_deserialize(rng, inst, states, blobs, blob)
                    continue
                fs = self.foreign_state(rng)
                if fs is None:
                    continue
                if kind == "set":
                    self.act_set_state(rng, inst, fs)
                elif kind == "get_reuse":
                    self.act_get_state(rng, inst, states, fs)
                    if fs.model is m:  # overwritten: now ours
                        states.append(fs)
                        continue
                elif kind == "serialize":
                    self.act_serialize(rng, inst, fs, blobs)
                else:
                    self.act_free_state(rng, inst, [fs], fs)
                    if not self.heap.is_live(fs.ptr):
                        continue
                if self.heap.is_live(fs.ptr) and self.helper is not None:
                    box = c_vp(fs.ptr)
                    self.call(self.helper, self.other, "fmi2FreeFMUstate",
                              [self.helper.handle, ctypes.byref(box)], "", helper=True)
        # cleanup: free the states, then the instances (counted, checked calls)
        k = n_calls
        for s in list(states):
            owner = next((i for i in insts if i.model is s.model), None)
            if owner is None:
                continue
            self.idx = base + k
            k += 1
            self.act_free_state(rng, owner, states, s)
        for inst in insts:
            self.idx = base + k
            k += 1
            self.free_instance(inst)
        self.heap.check_all(f"episode {ep} end")
        self.write(f"S {ep} {self.calls} {self.helper_calls} "
                   + json.dumps(dict(self.state_calls)))


# --------------------------------------------------------------------------- #
# the parent: specs, child processes, crash and hang accounting


def _spec(key: str, unzip_root: str) -> dict:
    from fmpy import extract, read_model_description

    if key == "plant":
        import plant

        path = plant.plant_fmu()
    else:
        import controller

        path = controller.controller_fmu()
    md = read_model_description(str(path))
    unzip = os.path.join(unzip_root, key)
    if not os.path.isdir(unzip):
        extract(str(path), unzip)
    ident = md.coSimulation.modelIdentifier
    dll = next(Path(unzip, "binaries").glob(f"*/{ident}.*"))

    def start(v):
        try:
            if v.type == "Real":
                return float(v.start)
            if v.type in ("Integer", "Enumeration"):
                return int(v.start)
            if v.type == "Boolean":
                return v.start in (True, "true", "1", 1)
        except (TypeError, ValueError):
            return None
        return None

    return {
        "key": key, "model": md.modelName, "guid": md.guid, "dll": str(dll),
        "resources": Path(unzip, "resources").as_uri(), "fmu": str(path),
        "variables": [[v.name, int(v.valueReference), v.type, v.causality, v.variability,
                       start(v)] for v in md.modelVariables],
        "categories": [c.name for c in md.logCategories],
        "caps": {"dd": bool(md.coSimulation.providesDirectionalDerivative),
                 "interp": bool(md.coSimulation.canInterpolateInputs),
                 "max_order": int(md.coSimulation.maxOutputDerivativeOrder or 0),
                 "me": md.modelExchange is not None},
    }


def run_fuzz(fmu: str, calls: int, seed: int, *, use_after_free: bool = False,
             plant_bug: str | None = None, episode_calls: int = 250,
             hang_timeout: float = 5.0, time_budget: float = 600.0,
             huge_after_hang: bool = False, env: dict | None = None) -> FuzzReport:
    """Fuzz one FMU ("plant" or "controller") with about `calls` calls; a finished report.

    Each run of episodes is one child process; a crash (signal) or a hang (no call finished
    within `hang_timeout` s) is a finding, and the batch continues with the next episode.
    After the first hang, huge step sizes are left out unless `huge_after_hang` (each hang
    costs `hang_timeout`)."""
    assert fmu in MODELS and episode_calls < EPISODE_STRIDE - 100
    report = FuzzReport(fmu, seed)
    t0 = time.monotonic()
    n_eps = max(1, math.ceil(calls / episode_calls))
    other = "controller" if fmu == "plant" else "plant"
    with tempfile.TemporaryDirectory(prefix="fuzz_fmi_") as tmp:
        specs = {"target": _spec(fmu, tmp), "other": _spec(other, tmp)}
        spec_file = os.path.join(tmp, "spec.json")
        ep = 0
        allow_huge = True
        while ep < n_eps:
            if time.monotonic() - t0 > time_budget:
                report.truncated = True
                break
            journal = os.path.join(tmp, f"journal{report.children}.txt")
            opts = {"seed": seed, "start": ep, "end": n_eps, "episode_calls": episode_calls,
                    "use_after_free": use_after_free, "plant_bug": plant_bug,
                    "allow_huge": allow_huge, "journal": journal}
            with open(spec_file, "w") as f:
                json.dump({"specs": specs, "opts": opts}, f)
            open(journal, "w").close()
            err_path = os.path.join(tmp, f"stderr{report.children}.txt")
            with open(err_path, "wb") as err:
                proc = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--child",
                                         spec_file], stdout=subprocess.DEVNULL, stderr=err,
                                        env=env)
                report.children += 1
                last_size, last_change, hung = -1, time.monotonic(), False
                while proc.poll() is None:
                    time.sleep(0.02)
                    size = os.path.getsize(journal)
                    now = time.monotonic()
                    if size != last_size:
                        last_size, last_change = size, now
                    elif now - last_change > hang_timeout:
                        proc.kill()
                        proc.wait()
                        hung = True
                        break
            calls_done = helpers_done = 0
            child_states: Counter = Counter()
            last_call, last_idx, eps_done = "", -1, ep - 1
            with open(journal, encoding="utf-8", errors="replace") as f:
                for line in f:
                    tag, _, rest = line.rstrip("\n").partition(" ")
                    if tag == "C":
                        idx, _, desc = rest.partition(" ")
                        last_idx, last_call = int(idx), desc
                        calls_done += 1
                    elif tag == "F":
                        d = json.loads(rest)
                        report.findings.append(Finding(seed, d["index"], d["kind"],
                                                       d["description"], fmu, d["call"]))
                    elif tag == "S":
                        e, _c_calls, c_helpers, states = rest.split(" ", 3)
                        eps_done = int(e)
                        helpers_done = int(c_helpers)
                        child_states = Counter(json.loads(states))
            report.calls += calls_done
            report.state_calls.update(child_states)
            report.helper_calls += helpers_done
            if proc.returncode == 0 and not hung:
                report.episodes += eps_done - ep + 1
                break
            crashed_ep = last_idx // EPISODE_STRIDE if last_idx >= 0 else ep
            report.episodes += crashed_ep - ep + 1
            tail = Path(err_path).read_text(errors="replace").strip().splitlines()[-3:]
            if hung:
                report.hangs += 1
                report.findings.append(Finding(seed, last_idx, "hang",
                                               f"no return within {hang_timeout:g} s from "
                                               f"{last_call}", fmu))
                allow_huge = huge_after_hang
            else:
                report.crashes += 1
                rc = proc.returncode
                sig = signal.Signals(-rc).name if rc < 0 else f"exit {rc}"
                report.findings.append(Finding(seed, last_idx, "crash",
                                               f"{sig} in {last_call}"
                                               + (f" | {' / '.join(tail)[-300:]}"
                                                  if tail and rc > 0 else ""), fmu))
            ep = crashed_ep + 1
    report.seconds = time.monotonic() - t0
    return report


def _child_main(spec_file: str) -> int:
    import faulthandler

    faulthandler.enable()
    with open(spec_file) as f:
        data = json.load(f)
    opts = data["opts"]
    fd = os.open(opts["journal"], os.O_WRONLY | os.O_APPEND)
    child = Child(data["specs"], opts, fd)
    if opts.get("only_episode") is not None:
        child.episode(int(opts["only_episode"]), int(opts["episode_calls"]))
    else:
        for ep in range(int(opts["start"]), int(opts["end"])):
            child.episode(ep, int(opts["episode_calls"]))
    if child.helper is not None:
        child.free_instance(child.helper, helper=True)
    os.close(fd)
    return 0


def main(argv: list[str] | None = None) -> int:
    root = str(Path(__file__).resolve().parents[2])
    if root not in sys.path:
        sys.path.insert(0, root)
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--child", help=argparse.SUPPRESS)
    p.add_argument("--calls", type=int, default=5000, help="calls per FMU")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--fmu", choices=("plant", "controller", "both"), default="both")
    p.add_argument("--use-after-free", action="store_true",
                   help="also call functions on freed instances (undefined behaviour)")
    p.add_argument("--hang-timeout", type=float, default=5.0)
    p.add_argument("--episode-calls", type=int, default=250)
    p.add_argument("--plant-bug", choices=("nan_output", "silent_error", "accept_forbidden",
                                           "crash", "hang"), help="self-test of the oracle")
    p.add_argument("--max-lines", type=int, default=40)
    args = p.parse_args(argv)
    if args.child:
        return _child_main(args.child)
    total = 0
    for fmu in ("plant", "controller") if args.fmu == "both" else (args.fmu,):
        rep = run_fuzz(fmu, args.calls, args.seed, use_after_free=args.use_after_free,
                       plant_bug=args.plant_bug, episode_calls=args.episode_calls,
                       hang_timeout=args.hang_timeout)
        print(rep.summary(args.max_lines))
        total += len(rep.findings)
    return 1 if total else 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())
