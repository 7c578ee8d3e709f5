"""Worker processes that draw a run's figures beside the simulation.

Drawing the five figures of a run costs ~3 s of matplotlib on one core, more than the run
itself.  A :class:`FigurePool` is started before the run: its workers import matplotlib and
draw the airframe's force-set figure (which needs no run) while the simulation steps on the
other core, then share the run's figures, each drawn once, while the caller writes the
results.  The workers only return PNG bytes; the caller writes every file, so the results
folder stays whole or absent (``orchestrator.runner.publish``).

The run's data reaches the workers as a temporary ``.npy`` file that they map read-only
(no copy through a pipe), named with the run's owner tag (:func:`owner_tag`): the file of a
run killed before it could remove it is removed when the next pool starts
(:func:`remove_stale_handoffs`).  Workers are forked, which is cheap and needs no re-import, where
the OS forks safely (Linux): the first worker imports matplotlib and forks the second from
itself, so the import is paid once.  Elsewhere :func:`available` is False and the caller draws
in its own process.  A worker that fails or dies costs only the parallelism: the caller draws
what is missing itself.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import queue
import re
import signal
import sys
import tempfile
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from orchestrator.output.run_result import RunResult

if TYPE_CHECKING:
    from plant.airframe import Airframe

WORKERS = 2
HANDOFF_PREFIX = "fullpose-run-"
"""The hand-over files' name prefix, followed by the owner tag of the run
(:func:`owner_tag`: ``PID-START-``), then mkstemp's random part."""
_HANDOFF = re.compile(re.escape(HANDOFF_PREFIX) + r"(\d+)-(?:(\d+)-)?[a-z0-9_]+\.npy")
"""A hand-over file's name: the pid and start time of its run (files of earlier versions
have only the pid)."""
HANDOFF_BYTES = 512 * 2**20
"""Runs up to this size reach the workers as a copy in shared memory (~2 min of 500 Hz
recording); larger ones through their written ``results.parquet``, so a long run never
needs a second copy of itself in memory."""
AFFINITY = {"force_set": 1, "forces": 1, "actuators": 1, "tracking": 0,
            "disturbance_timing": 0}
"""Which worker draws which figure.  The force-set figure goes to the forked worker, idle
while the run steps, and is drawn during the loop; it imports scipy.optimize for the slices
(0.33 s), so the other figure with force sets follows it there warm.  After the loop each
worker has ~0.4 s of drawing (measured warm: forces 0.24 + actuators 0.18 against tracking
0.26 + disturbance_timing 0.13 CPU s); the first worker, the zygote, also serves the
main process's first messages."""
POLL = 0.05  # s between checks that the workers are alive while waiting


# ---------------------------------------------------------------------------
# Whose a temporary file is (here, the hand-over files; ``orchestrator.runner``, the folders
# beside a results folder)
#
# Every temporary file or folder a run makes carries its owner in its name: an *owner tag*
# ``PID-START``, the process id and the process's start time (clock ticks since boot, field
# 22 of ``/proc/PID/stat``; 0 where there is no ``/proc``).  A file whose owner no longer
# runs is a leftover of a killed run and a later run removes it; a live run's files are
# never touched.  The start time tells a dead owner from a new process that reuses its id.

TAG = r"(\d+)-(\d+)"
"""The owner tag in a name (a regular expression: groups pid, start)."""


def process_start(pid: int) -> int | None:
    """The start time of process ``pid`` (clock ticks since boot); 0 where the OS does not
    say (no ``/proc``); None when no such process runs (a zombie counts as ended)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        if Path("/proc/self/stat").exists():
            return None  # Linux, and no such process
        return 0 if _pid_runs(pid) else None
    if fields[0] in ("Z", "X"):
        return None
    return int(fields[19])


def _pid_runs(pid: int) -> bool:
    """Without /proc: POSIX's signal 0.  Elsewhere (Windows, where os.kill would end the
    process) every process counts as running, so nothing of another run is removed."""
    if os.name != "posix":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # (EPERM: it runs, as another user)
        return True
    return True


def owner_tag() -> str:
    """This process's tag, ``PID-START``, for the names of the temporary files it makes."""
    pid = os.getpid()
    return f"{pid}-{process_start(pid) or 0}"


def owner_alive(pid: int, start: int) -> bool:
    """Whether the process that made a file tagged ``pid-start`` still runs."""
    now = process_start(pid)
    return now is not None and (start == 0 or now == 0 or now == start)


def tag_alive(match: re.Match[str], group: int = 1) -> bool:
    """:func:`owner_alive` for a match of :data:`TAG` whose pid is group ``group``."""
    return owner_alive(int(match.group(group)), int(match.group(group + 1)))


def handoff_folder() -> Path | None:
    """Where the hand-over files go: /dev/shm (memory, not disk) where the OS has it, else
    the temporary folder (None)."""
    shm = Path("/dev/shm")
    return shm if shm.is_dir() else None


def remove_stale_handoffs() -> list[Path]:
    """Removes the hand-over files of runs that no longer run (killed before they could
    remove them); returns them.  A file of an earlier version names only a pid: it is stale
    when that pid runs no more, or is this process (which names its files otherwise)."""
    folder = handoff_folder() or Path(tempfile.gettempdir())
    removed = []
    with contextlib.suppress(OSError):
        for path in folder.glob(f"{HANDOFF_PREFIX}*.npy"):
            m = _HANDOFF.fullmatch(path.name)
            if m is None:
                continue
            pid = int(m.group(1))
            if m.group(2) is not None:
                stale = not owner_alive(pid, int(m.group(2)))
            else:
                stale = pid == os.getpid() or not owner_alive(pid, 0)
            if stale:
                with contextlib.suppress(OSError):
                    path.unlink()
                removed.append(path)
    return removed


def available() -> bool:
    """Whether figures can be drawn in forked workers here (Linux with 2 or more cores)."""
    return (sys.platform.startswith("linux") and "fork" in mp.get_all_start_methods()
            and (os.cpu_count() or 1) >= 2)


@dataclass(frozen=True)
class _Job:
    name: str
    airframe: Airframe | None
    data: str | None  # the run's .npy copy or results file (None: a figure without a run)
    columns: tuple[str, ...] = ()
    meta: dict[str, Any] | None = None
    integer: frozenset[str] = frozenset()
    rows: int | None = None  # the run's rows of a .npy (None: all of them)


def _draw(job: _Job, runs: dict[str, RunResult]) -> tuple[bytes, list[str]]:
    from orchestrator.output.plots import figure_inputs, render_png

    result = None
    if job.data is not None:
        result = runs.get(job.data)
        if result is None and job.data.endswith(".npy"):
            result = RunResult(list(job.columns),
                               np.load(job.data, mmap_mode="r")[:job.rows],
                               dict(job.meta or {}), job.integer)
        elif result is None:
            result = RunResult.read(job.data)
            runs.clear()
            runs[job.data] = result
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if result is not None:
            af, afs, s0 = figure_inputs(result, job.airframe)
        else:
            from plant.airframe import Airframe

            af = job.airframe if isinstance(job.airframe, Airframe) else None
            afs = s0 = None
            if af is not None:
                from orchestrator.output.plots import force_sets

                afs, s0 = force_sets(af)
        png = render_png(job.name, result, af, afs, s0)
    return png, [str(w.message) for w in caught]


def _warm() -> None:
    """Load the fonts and the PNG writer while the run steps (a figure's first text costs
    the font file)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from orchestrator.output.plot_style import png_bytes

    fig = Figure(figsize=(1.0, 1.0))
    FigureCanvasAgg(fig)
    fig.add_subplot().set_title("warm-up 0123456789")
    png_bytes(fig)


def _die_with_parent() -> None:
    """Linux: this process is killed when the process that forked it ends, so a worker
    never outlives the run that started it."""
    import ctypes

    with contextlib.suppress(Exception):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def _serve(jobs: Any, done: Any) -> None:
    runs: dict[str, RunResult] = {}
    while True:
        job = jobs.get()
        if job is None:
            return
        try:
            png, notes = _draw(job, runs)
            done.put((job.name, png, notes, None))
        except Exception as exc:  # reported to the caller, which draws the figure itself
            done.put((job.name, None, [], f"{type(exc).__name__}: {exc}"))


def _zygote(queues: Sequence[Any], done: Any) -> None:
    """The first worker: imports matplotlib once, forks the others from itself (so they
    start with it imported), then serves its own queue."""
    _die_with_parent()
    with contextlib.suppress(Exception):  # only a head start: the jobs work without it
        _warm()
    children = []
    for i, jobs in enumerate(queues[1:], start=1):
        pid = os.fork()
        if pid == 0:
            code = 0
            try:
                _die_with_parent()
                _serve(jobs, done)
            except BaseException:
                code = 1
            finally:
                os._exit(code)
        children.append(pid)
        done.put((_PID, i, pid, None))
    try:
        _serve(queues[0], done)
    finally:
        for pid in children:
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)


_PID = "<pid>"  # a done-queue message that names a forked worker's process id


def _alive(pid: int | None) -> bool:
    """Whether a process (not necessarily our child) still runs: Linux's /proc."""
    if pid is None:
        return True  # not started yet: its parent's liveness says
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


class FigurePool:
    """``FigurePool(airframe)`` forks the workers and queues the force-set figure;
    :meth:`submit` queues a run's figures, :meth:`collect` returns every PNG, :meth:`close`
    ends the workers."""

    def __init__(self, airframe: Airframe | None, workers: int = WORKERS,
                 force_set: bool = True) -> None:
        remove_stale_handoffs()
        ctx = mp.get_context("fork")
        self._queues = [ctx.Queue() for _ in range(workers)]
        self._done = ctx.Queue()
        self._airframe = airframe
        self._pending: set[str] = set()
        self._results: dict[str, tuple[bytes | None, list[str], str | None]] = {}
        self._data: str | None = None  # the temporary file to remove
        self._handoff: str | None = None
        self._rows: int | None = None  # the run's rows of the handed-over .npy
        self._run: RunResult | None = None
        self._names: list[str] = []
        self._zygote = ctx.Process(target=_zygote, args=(self._queues, self._done),
                                   daemon=True, name="fullpose-figures")
        self._zygote.start()
        self._pids: list[int | None] = [self._zygote.pid] + [None] * (workers - 1)
        if force_set and airframe is not None:
            self._submit(_Job("force_set", airframe, None))

    def _submit(self, job: _Job) -> None:
        self._pending.add(job.name)
        self._queues[AFFINITY.get(job.name, 0) % len(self._queues)].put(job)

    def submit(self, result: RunResult, names: Sequence[str],
               written: Path | None = None, recording: Path | None = None) -> None:
        """Queue the run figures ``names`` of ``result``; :meth:`collect` returns them.
        The workers map a copy of the data, or without a copy: ``recording``, the ``.npy``
        file whose first rows are ``result.data`` (a long run's recording,
        ``master.SPILL_BYTES``); ``written``, the run's results file, which they read
        (above :data:`HANDOFF_BYTES`)."""
        self._rows = None
        if recording is not None:
            path = str(recording)
            self._rows = len(result.data)
        elif written is not None:
            path = str(written)
        else:
            if result.data.nbytes > HANDOFF_BYTES:
                raise ValueError(f"a {result.data.nbytes / 2**20:.0f} MiB run reaches the "
                                 "figure workers through its results file: pass written=")
            # the owner in the name: a killed run's file is told from a live one's
            fd, path = tempfile.mkstemp(prefix=f"{HANDOFF_PREFIX}{owner_tag()}-",
                                        suffix=".npy", dir=handoff_folder())
            os.close(fd)
            self._data = path  # from here close() removes it, whatever interrupts the copy
            try:
                np.save(path, np.ascontiguousarray(result.data))
            except OSError:  # (a full /dev/shm): nothing half-written is left behind
                with contextlib.suppress(OSError):
                    os.unlink(path)
                self._data = None
                raise
        self._handoff = path
        self._run = result
        self._names = list(names)
        for name in names:
            self._submit(self._job(name))

    def _job(self, name: str) -> _Job:
        r = self._run
        if r is None or self._handoff is None:
            return _Job(name, self._airframe, None)
        return _Job(name, self._airframe, self._handoff, tuple(r.columns), r.meta, r.integer,
                    self._rows)

    def collect(self, timeout: float = 600.0) -> dict[str, bytes]:
        """The PNGs of the submitted run figures and of the force-set figure, by name.
        Figures the workers could not draw are drawn here; their warnings are re-issued."""
        self._wait(timeout)
        out: dict[str, bytes] = {}
        for name in [n for n in ("force_set", *self._names) if n in self._results]:
            png, notes, _ = self._results[name]
            for note in notes:
                warnings.warn(note, stacklevel=2)
            if png is None:  # the worker failed: drawn here, so its error shows as such
                png, notes = _draw(self._job(name), {})
                for note in notes:
                    warnings.warn(note, stacklevel=2)
            out[name] = png
        return out

    def _wait(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while self._pending:
            if self._pump():
                continue
            # a dead worker's job would never come back: the caller draws what is left
            alive = self._zygote.is_alive() and all(map(_alive, self._pids[1:]))
            if not alive or time.monotonic() > deadline:
                for name in self._pending:
                    self._results[name] = (None, [], "the figure workers stopped")
                self._pending.clear()

    def _pump(self) -> bool:
        """Takes one message from the workers (False: none came within :data:`POLL`)."""
        try:
            name, png, notes, error = self._done.get(timeout=POLL)
        except queue.Empty:
            return False
        if name == _PID:
            self._pids[png] = notes
        else:
            self._pending.discard(name)
            self._results[name] = (png, notes, error)
        return True

    def worker_pids(self, timeout: float = 30.0) -> list[int | None]:
        """The workers' process ids (None: not forked yet after ``timeout`` s)."""
        deadline = time.monotonic() + timeout
        while None in self._pids and time.monotonic() < deadline:
            self._pump()
        return list(self._pids)

    def close(self) -> None:
        """Stop the workers and free what they hold."""
        for q in self._queues:
            with contextlib.suppress(Exception):
                q.put(None)
        self._zygote.join(timeout=1.0)
        for pid in self._pids[1:]:
            if pid is not None and _alive(pid):
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
        if self._zygote.is_alive():
            self._zygote.terminate()
            self._zygote.join()
        for q in (*self._queues, self._done):
            q.close()
            q.cancel_join_thread()
        if self._data is not None:
            with contextlib.suppress(OSError):
                Path(self._data).unlink()
            self._data = None

    def __enter__(self) -> FigurePool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
