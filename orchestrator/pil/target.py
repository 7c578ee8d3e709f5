"""The controller image on an emulated Cortex-M7: QEMU's ``mps2-an500`` runs ``fpc_pil.elf``
(fmu_src/embedded/pil) and answers requests over two named pipes, one at a time.

    with PilTarget(elf) as target:
        guid = target.hello()
        target.set_reals([1], [0.002]); target.start(0.0)
        reply = target.sample(t, in_refs, values, out_refs, int_refs)

QEMU runs with ``-icount shift=N``: the virtual clock advances 2**N ns per instruction
executed, so the board timer (25 MHz) that the image reads around each controller call counts
instructions: :func:`instructions` converts.  The wire format is pil_main.c's.
"""

from __future__ import annotations

import os
import select
import shutil
import struct
import subprocess
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MACHINE = "mps2-an500"
"""QEMU's Arm MPS2 board with the AN500 FPGA image: a Cortex-M7 with the double-precision
FPU (fpv5-d16)."""
ICOUNT_SHIFT = 6
"""2**6 = 64 ns of virtual time per instruction: 1.6 timer ticks of 40 ns each."""
TICK_NS = 40.0
"""The board timer's period (its 25 MHz peripheral clock)."""
MAX_VALUES = 512
"""Elements one request may carry (pil_main.c MAX_VALUES): longer ones are sent in parts."""
START_TIMEOUT = 20.0
"""Seconds QEMU may take to boot the image and open its pipes."""
REPLY_TIMEOUT = 60.0
"""Seconds one request may take (the slowest is initialization, a few million instructions)."""

FP_OK, FP_WARNING, FP_DISCARD, FP_ERROR = 0, 1, 2, 3
LIBM = ("sin", "cos", "tan", "asin", "acos", "atan2", "hypot")
"""The libm functions the controller calls that are not exact by definition (fmod, frexp,
ldexp, nextafter are; sqrt and fabs are instructions), in pil_main.c's order."""


class PilError(RuntimeError):
    """The target cannot be started or stopped answering; the message says why (QEMU's own
    output included)."""


def instructions(ticks: int | np.ndarray, shift: int = ICOUNT_SHIFT) -> float | np.ndarray:
    """Board-timer ticks measured under ``-icount shift`` as instructions executed."""
    return ticks * TICK_NS / float(2 ** shift)


@dataclass(frozen=True)
class Reply:
    """One answer of the target: the controller call's status, the board timer's ticks over
    it, the C library's use so far (format calls, heap bytes), the deepest stack so far
    (bytes), the values asked for and the messages the controller said."""

    status: int
    ticks: int
    format_calls: int
    heap_bytes: int
    stack_bytes: int
    values: bytes
    text: str

    @property
    def failed(self) -> bool:
        """The call returned FP_ERROR or FP_DISCARD."""
        return self.status >= FP_DISCARD


def check_image(elf: Path) -> None:
    """ValueError unless elf is a 32-bit little-endian Arm ELF executable (what the emulated
    Cortex-M7 runs), naming the file."""
    with open(elf, "rb") as f:
        head = f.read(20)
    # e_ident: magic, class 1 (32-bit), data 1 (little-endian); e_type 2 (executable);
    # e_machine 40 (EM_ARM)
    if (len(head) < 20 or head[:4] != b"\x7fELF" or head[4] != 1 or head[5] != 1
            or struct.unpack("<HH", head[16:20]) != (2, 40)):
        raise ValueError(f"{elf} is not an Arm ELF executable: the controller image is the "
                         "fpc_pil.elf that `fullpose build-embedded` builds")


def qemu_command(elf: Path, shift: int = ICOUNT_SHIFT) -> list[str]:
    """The qemu-system-arm command line that runs the image (in the pipes' folder)."""
    return ["qemu-system-arm", "-M", MACHINE, "-nographic", "-monitor", "none",
            "-serial", "none", "-semihosting-config", "enable=on,target=native",
            "-icount", f"shift={shift},align=off,sleep=off", "-kernel", str(elf)]


class PilTarget:
    """One QEMU process running the controller image; closed by :meth:`close` (or ``with``)."""

    def __init__(self, elf: str | Path, shift: int = ICOUNT_SHIFT) -> None:
        self.elf = Path(elf)
        if not self.elf.is_file():
            raise PilError(f"no controller image at {self.elf}: build it with "
                           "'fullpose build-embedded'")
        check_image(self.elf)
        if shutil.which("qemu-system-arm") is None:
            raise PilError("qemu-system-arm is not installed (Debian: apt-get install "
                           "qemu-system-arm)")
        self.shift = shift
        self.folder = Path(tempfile.mkdtemp(prefix="fullpose-pil-"))
        self._in = self._out = -1
        self._got_reply = False
        os.mkfifo(self.folder / "pil.in")
        os.mkfifo(self.folder / "pil.out")
        self._log = open(self.folder / "qemu.log", "w+b")
        self.proc = subprocess.Popen(qemu_command(self.elf, shift), cwd=self.folder,
                                     stdin=subprocess.DEVNULL, stdout=self._log,
                                     stderr=subprocess.STDOUT)
        try:
            self._connect()
        except BaseException:
            self.close()
            raise

    # -- the pipes -------------------------------------------------------------

    def _qemu_said(self) -> str:
        self._log.flush()
        self._log.seek(0)
        lines = self._log.read().decode(errors="replace").strip().splitlines()
        # the first lines say what happened; a fault's register dump follows them
        text = "; ".join(line.strip() for line in lines[:3] if line.strip())
        return f" (QEMU: {text})" if text else ""

    def _dead(self, what: str) -> PilError:
        try:  # a target that closed its pipe is exiting: its status tells why
            code: int | None = self.proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            code = None
        state = f"QEMU exited with code {code}" if code is not None else "QEMU is running"
        return PilError(f"the controller target {what}: {state}{self._qemu_said()}")

    def _connect(self) -> None:
        """Open the pipes in the order the image does: requests, then replies."""
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            try:
                self._in = os.open(self.folder / "pil.in", os.O_WRONLY | os.O_NONBLOCK)
                break
            except OSError:  # ENXIO: no reader yet
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    raise self._dead("did not start") from None
                time.sleep(0.005)
        os.set_blocking(self._in, True)
        self._out = os.open(self.folder / "pil.out", os.O_RDONLY | os.O_NONBLOCK)

    def _read(self, n: int) -> bytes:
        parts, got = [], 0
        deadline = time.monotonic() + REPLY_TIMEOUT
        while got < n:
            ready, _, _ = select.select([self._out], [], [], 0.05)
            if ready:
                chunk = os.read(self._out, n - got)
                if chunk:
                    parts.append(chunk)
                    got += len(chunk)
                    self._got_reply = True
                    continue
                if self._got_reply:  # end of file after the first reply: the target stopped
                    raise self._dead("stopped answering")
                time.sleep(0.001)  # the image has not opened its end yet
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise self._dead("did not answer")
        return b"".join(parts)

    def request(self, op: bytes, payload: bytes = b"") -> Reply:
        """Send one request (operation byte and arguments) and read its reply."""
        body = op + payload
        try:
            os.write(self._in, struct.pack("<I", len(body)) + body)
        except OSError:
            raise self._dead("refused a request") from None
        status, ticks, fmt, heap, stack, n = struct.unpack("<iIIIII", self._read(24))
        values = self._read(n) if n else b""
        (m,) = struct.unpack("<I", self._read(4))
        text = self._read(m).decode(errors="replace") if m else ""
        return Reply(status, ticks, fmt, heap, stack, values, text)

    # -- the operations (pil_main.c) --------------------------------------------

    def hello(self) -> str:
        """The GUID of the model the image was built from (the FMU's, for the same sources)."""
        return self.request(b"h").values.decode()

    def defaults(self) -> Reply:
        """Every variable back at its start value (fpc_defaults)."""
        return self.request(b"d")

    def set_reals(self, refs: Sequence[int], values: Sequence[float] | np.ndarray) -> Reply:
        """fpc_set_reals_vr, in parts of MAX_VALUES; the first failing part's reply, else the
        last."""
        return self._set(b"R", refs, np.asarray(values, dtype="<f8").tobytes(), 8)

    def set_ints(self, refs: Sequence[int], values: Sequence[int]) -> Reply:
        """fpc_set_ints_vr (Integer and Boolean variables), in parts of MAX_VALUES."""
        return self._set(b"I", refs, np.asarray(values, dtype="<i4").tobytes(), 4)

    def _set(self, op: bytes, refs: Sequence[int], data: bytes, size: int) -> Reply:
        reply = Reply(FP_OK, 0, 0, 0, 0, b"", "")
        for a in range(0, max(len(refs), 1), MAX_VALUES):
            part = list(refs[a:a + MAX_VALUES])
            reply = self.request(op, _refs(part) + data[a * size:(a + len(part)) * size])
            if reply.failed:
                return reply
        return reply

    def get_reals(self, refs: Sequence[int]) -> tuple[Reply, np.ndarray]:
        """fpc_get_reals_vr (at most MAX_VALUES)."""
        reply = self.request(b"r", _refs(refs))
        return reply, np.frombuffer(reply.values, dtype="<f8")

    def get_ints(self, refs: Sequence[int]) -> tuple[Reply, np.ndarray]:
        """fpc_get_ints_vr (at most MAX_VALUES)."""
        reply = self.request(b"i", _refs(refs))
        return reply, np.frombuffer(reply.values, dtype="<i4")

    def start(self, t0: float) -> Reply:
        """fpc_start at t0 from the inputs set."""
        return self.request(b"s", struct.pack("<d", t0))

    def sample(self, t: float, in_refs: bytes, in_values: np.ndarray, out_refs: bytes,
               int_refs: bytes) -> Reply:
        """One sample at t: the inputs set, fpc_step, the outputs read (refs packed by
        :func:`packed_refs`); values: the Reals then the Integers/Booleans."""
        return self.request(b"x", struct.pack("<d", t) + in_refs
                            + np.asarray(in_values, dtype="<f8").tobytes() + out_refs + int_refs)

    def libm(self, function: str, x: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """The board's C library's ``function`` (one of :data:`LIBM`) at x (and y for atan2
        and hypot), in parts of MAX_VALUES / 2."""
        fid = LIBM.index(function)
        x = np.asarray(x, dtype="<f8")
        y = np.zeros_like(x) if y is None else np.asarray(y, dtype="<f8")
        out = []
        half = MAX_VALUES // 2
        for a in range(0, len(x), half):
            xs, ys = x[a:a + half], y[a:a + half]
            reply = self.request(b"m", bytes([fid]) + struct.pack("<I", len(xs)) + xs.tobytes()
                                 + ys.tobytes())
            if reply.failed:
                raise PilError(f"the target refused libm {function}: {reply.text}")
            out.append(np.frombuffer(reply.values, dtype="<f8"))
        return np.concatenate(out) if out else np.zeros(0)

    def calibrate(self, turns: int) -> float:
        """Instructions counted over a loop of exactly 2 turns + 1 instructions (pil_main.c 'c';
        plus the timer reads' own, the same for any turns): checks the counting."""
        reply = self.request(b"c", struct.pack("<I", turns))
        if reply.failed:
            raise PilError(f"calibration refused: {reply.text.strip()}")
        return float(instructions(reply.ticks, self.shift))

    def record_libm(self, on: bool) -> Reply:
        """Record the controller's calls of the :data:`LIBM` functions (the tracing image,
        fpc_pil_trace.elf; another image refuses)."""
        return self.request(b"l", bytes([1 if on else 0]))

    def take_libm(self) -> tuple[np.ndarray, int]:
        """The calls recorded since the last take, as rows (function index in :data:`LIBM`,
        x, y, result), and how many did not fit the image's log (256 per take)."""
        reply = self.request(b"L")
        if reply.failed or len(reply.values) < 4:
            raise PilError(f"the target cannot give its libm calls: {reply.text.strip()}")
        (dropped,) = struct.unpack("<I", reply.values[:4])
        return np.frombuffer(reply.values[4:], dtype="<f8").reshape(-1, 4), dropped

    def close(self) -> None:
        """Stop QEMU and remove the pipes."""
        if self._in >= 0:
            try:
                os.write(self._in, struct.pack("<I", 1) + b"q")
            except OSError:
                pass
            os.close(self._in)
            self._in = -1
        if self.proc.poll() is None:
            try:
                self.proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self._out >= 0:
            os.close(self._out)
            self._out = -1
        self._log.close()
        shutil.rmtree(self.folder, ignore_errors=True)

    def __enter__(self) -> PilTarget:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _refs(refs: Sequence[int]) -> bytes:
    return struct.pack("<I", len(refs)) + np.asarray(refs, dtype="<u4").tobytes()


def packed_refs(refs: Sequence[int]) -> bytes:
    """Value references as a request carries them (count, then each)."""
    if len(refs) > MAX_VALUES:
        raise ValueError(f"at most {MAX_VALUES} references per sample, got {len(refs)}")
    return _refs(refs)
