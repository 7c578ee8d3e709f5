"""Figures drawn by worker processes (orchestrator/output/figure_pool.py) are the figures drawn in
the caller's process, byte for byte (Agg is deterministic), whatever happens to a worker."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from orchestrator.output import figure_pool
from orchestrator.output.plots import RUN_FIGURES, figure_inputs, render_png
from orchestrator.output.run_result import RunResult
from orchestrator.runner import prepare, run_scenario

pytestmark = pytest.mark.skipif(not figure_pool.available(),
                                reason="figure workers need fork and 2 cores (Linux)")


@pytest.fixture(scope="module")
def short(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, Path]]:
    """The same 3 s run written with the workers and without them, beside the file a killed
    run of an earlier version whose pid this process reused would have left."""
    sc = prepare("hover_varying_orientation", duration=3.0)
    base = tmp_path_factory.mktemp("pool")
    folder = figure_pool.handoff_folder() or Path(tempfile.gettempdir())
    stale = folder / f"{figure_pool.HANDOFF_PREFIX}{os.getpid()}-leftover.npy"
    stale.write_bytes(b"")
    try:
        run_scenario(sc, base / "pool", timing=False, figure_workers=True)
        run_scenario(sc, base / "here", timing=False, figure_workers=False)
        assert not stale.exists()  # removed by the run
        yield base / "pool", base / "here"
    finally:
        stale.unlink(missing_ok=True)


def own_handoffs() -> list[Path]:
    """This process's hand-over files left in /dev/shm: named with its pid *and* start time,
    so neither another run's files nor those of a killed run whose pid this process reused
    count (the test depends on no state of the machine it did not make)."""
    folder = figure_pool.handoff_folder() or Path(tempfile.gettempdir())
    return list(folder.glob(f"{figure_pool.HANDOFF_PREFIX}{figure_pool.owner_tag()}-*.npy"))


def ended_pid() -> int:
    """The id of a process that has ended (and been reaped)."""
    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    return int(done.stdout)


def test_killed_runs_hand_overs_are_removed_and_live_ones_kept(tmp_path: Path):
    """What a run killed by SIGKILL leaves in /dev/shm (its hand-over file, which only its
    own close() removes) is removed when the next figure pool starts; a file of this
    process's pid from an earlier version's run (the pid reused) too; a live process's file
    stays."""
    folder = figure_pool.handoff_folder() or Path(tempfile.gettempdir())
    dead = ended_pid()
    start = figure_pool.process_start(os.getpid())
    planted = {
        "dead": folder / f"{figure_pool.HANDOFF_PREFIX}{dead}-{start}-zz{dead}.npy",
        "dead_old_version": folder / f"{figure_pool.HANDOFF_PREFIX}{dead}-yy{dead}.npy",
        "our_pid_old_version": folder / f"{figure_pool.HANDOFF_PREFIX}{os.getpid()}-xx.npy",
        "our_pid_other_start": folder / f"{figure_pool.HANDOFF_PREFIX}{os.getpid()}-1-ww.npy",
        "live": folder / f"{figure_pool.HANDOFF_PREFIX}{figure_pool.owner_tag()}-vv.npy",
    }
    try:
        for path in planted.values():
            path.write_bytes(b"\0" * 64)
        pool = figure_pool.FigurePool(None, force_set=False)
        pool.close()
        assert {k for k, p in planted.items() if p.exists()} == {"live"}
    finally:
        for path in planted.values():
            path.unlink(missing_ok=True)


def test_workers_draw_the_figures_the_caller_draws(short: tuple[Path, Path]):
    pool, here = short
    names = sorted(p.name for p in here.glob("*.png"))
    assert names == sorted(f"{n}.png" for n in (*RUN_FIGURES, "force_set"))
    assert sorted(p.name for p in pool.glob("*.png")) == names
    for name in names:
        assert (pool / name).read_bytes() == (here / name).read_bytes(), name
    assert not own_handoffs()  # the hand-over is gone


@pytest.mark.heavy  # (a worker killed and the figures drawn without it: 3.1 s)
def test_a_dead_worker_costs_only_the_parallelism(short: tuple[Path, Path]):
    here = short[1]
    result = RunResult.read(here)  # float32 columns: the figures are the reader's own
    af, afs, s0 = figure_inputs(result)
    pool = figure_pool.FigurePool(af)
    try:
        second = pool.worker_pids()[1]
        assert second is not None and second != os.getpid()
        os.kill(second, signal.SIGKILL)
        pool.submit(result, RUN_FIGURES)
        pngs = pool.collect(timeout=120.0)
    finally:
        pool.close()
    assert sorted(pngs) == sorted((*RUN_FIGURES, "force_set"))
    for name in RUN_FIGURES:
        assert pngs[name] == render_png(name, result, af, afs, s0), name


def test_workers_end_with_the_pool():
    pool = figure_pool.FigurePool(None, force_set=False)
    pids = pool.worker_pids()
    assert all(p is not None for p in pids)
    pool.close()
    assert not any(figure_pool._alive(p) for p in pids)


def test_a_long_run_reaches_the_workers_through_its_results_file(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setattr(figure_pool, "HANDOFF_BYTES", 0)  # every run counts as long here
    sc = prepare("hover_varying_orientation", duration=2.0)
    run_scenario(sc, tmp_path / "r", timing=False, figure_workers=True)
    written = RunResult.read(tmp_path / "r")  # what the workers drew from
    af, afs, s0 = figure_inputs(written)
    for name in RUN_FIGURES:
        assert (tmp_path / "r" / f"{name}.png").read_bytes() == render_png(
            name, written, af, afs, s0), name


def test_no_room_for_the_copy_hands_the_results_file_over(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch):
    def full(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(figure_pool.np, "save", full)
    sc = prepare("hover_varying_orientation", duration=2.0)
    run_scenario(sc, tmp_path / "r", timing=False, figure_workers=True)
    written = RunResult.read(tmp_path / "r")
    af, afs, s0 = figure_inputs(written)
    assert (tmp_path / "r" / "tracking.png").read_bytes() == render_png(
        "tracking", written, af, afs, s0)
    assert not own_handoffs()
