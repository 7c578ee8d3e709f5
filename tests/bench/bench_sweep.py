"""Benchmark: sweep throughput against the single-run loop (prints figures, asserts nothing).

In one process, on the sweep's own cases (hover on the paper's hexacopter, perturbed plant,
disturbance step, sensor noise; ``--duration`` s each, designs hinf and baseline):

* the single-run loop speed: ``orchestrator.master.run`` of the first sweep runs, each on
  fresh FMUs, real-time factor of the stepping loop alone (``meta["wall_time"]``);
* sweeps (``orchestrator.sweep.run_sweep``), wall time of the whole call: every worker's
  start-up (process, FMU loading) included, the designs' gains computed beforehand:

  - the old path, fresh FMUs for every case (``reuse=False``), 1 worker;
  - FMUs instantiated once per worker and reset between cases: 1 worker (in process),
    2 local worker processes, 2 workers of a local Dask cluster (2 processes x 1 thread,
    started and its workers' imports done before the clock starts);

  with runs/s, runs/s and real-time factor per worker, per worker against the loop
  (target >= 80 %) and 2 workers against 1 (target >= 1.9x).

The figures need a quiet machine: the load average before and after is printed.

Usage: python tests/bench/bench_sweep.py [--cases 60] [--old-cases 10] [--duration 6]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import Any

from orchestrator import sweep
from orchestrator.master import CoSimulation
from orchestrator.runner import prepare

DESIGNS = ("hinf", "baseline")


def loop_rtf(n_runs: int, duration: float) -> tuple[float, float]:
    """(RTF, mean loop seconds) of single runs of the sweep's first ``n_runs`` runs."""
    params = sweep.designs()
    hover = prepare("hover", duration)
    walls = []
    for case in sweep.sample_cases(n_runs // len(DESIGNS) + 1, 0):
        for d in DESIGNS:
            sc = sweep.perturbed(hover, case, d, params[d], duration)
            walls.append(CoSimulation(sc).run().meta["wall_time"])
    walls = walls[:n_runs]
    mean = statistics.fmean(walls)
    return duration / mean, mean


def timed_sweep(cases: int, duration: float, **kw: Any) -> tuple[float, list[dict[str, Any]]]:
    t0 = time.perf_counter()
    rows = sweep.run_sweep(cases, seed=0, duration=duration, design_set=DESIGNS,
                           progress=False, **kw)
    return time.perf_counter() - t0, rows


def with_dask(work: Callable[[Any], tuple[float, list[dict[str, Any]]]]
              ) -> tuple[float, list[dict[str, Any]]] | None:
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        return None
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        client.run(lambda: __import__("orchestrator.sweep"))  # imports, not FMUs
        return work(client)


def row(label: str, workers: int, wall: float, rows: list[dict[str, Any]], duration: float,
        rtf_loop: float, one: float | None) -> float:
    rate = len(rows) / wall
    per = rate / workers
    vs_one = f"{rate / one:10.2f}x" if one else f"{'':11s}"
    steady = duration / statistics.fmean(r["wall_time"] for r in rows)
    print(f"{label:34s} {workers:7d} {len(rows):5d} {wall:7.2f} {rate:7.2f} {per:13.2f} "
          f"{duration * per:9.1f}x {100 * duration * per / rtf_loop:7.0f} % {vs_one} "
          f"{steady:8.1f}x")
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=60,
                        help="cases of the reused-FMU sweeps (x 2 designs; default 60)")
    parser.add_argument("--old-cases", type=int, default=10,
                        help="cases of the fresh-FMU sweep (x 2 designs; default 10)")
    parser.add_argument("--loop-runs", type=int, default=10,
                        help="single runs that give the loop speed (default 10)")
    parser.add_argument("--duration", type=float, default=6.0, help="s per run (default 6)")
    args = parser.parse_args()
    d = args.duration
    load0 = os.getloadavg()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"Python {platform.python_version()}; load average {load0[0]:.2f} before")
    sweep.designs()  # the gains, once per process (what every sweep call then reuses)
    rtf_loop, loop_s = loop_rtf(args.loop_runs, d)
    print(f"single-run loop (orchestrator.master.run, meta wall_time, {args.loop_runs} runs of "
          f"the sweep's cases, {d:g} s each): RTF {rtf_loop:.1f}x ({1e3 * loop_s:.1f} ms/run)")
    print(f"{'sweep':34s} {'workers':>7s} {'runs':>5s} {'wall s':>7s} {'runs/s':>7s} "
          f"{'runs/s/worker':>13s} {'RTF/worker':>10s} {'vs loop':>9s} {'vs 1 worker':>11s} "
          f"{'per run':>9s}")
    row("fresh FMUs per case (reuse=False)", 1,
        *timed_sweep(args.old_cases, d, reuse=False), d, rtf_loop, None)
    one = row("reused FMUs, in process", 1, *timed_sweep(args.cases, d), d, rtf_loop, None)
    row("reused FMUs, 2 local processes", 2, *timed_sweep(args.cases, d, workers=2), d,
        rtf_loop, one)
    done = with_dask(lambda client: timed_sweep(args.cases, d, dask=client))
    if done is None:
        print("dask.distributed not installed: no Dask figures")
    else:
        row("reused FMUs, Dask LocalCluster 2x1", 2, *done, d, rtf_loop, one)
    print(f"load average {os.getloadavg()[0]:.2f} after; 'per run': RTF of one run_case "
          "(reset, set-up, loop, metrics) without the sweep around it")


if __name__ == "__main__":
    main()
