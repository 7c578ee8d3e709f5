"""Benchmark: sweep throughput against the single-run loop (prints figures, asserts nothing).

In one process, on the sweep's own cases (hover on the paper's hexacopter, perturbed plant,
disturbance step, sensor noise; ``--duration`` s each, designs hinf and baseline):

* the single-run loop speed: ``orchestrator.master.run`` of the first sweep runs, each on
  fresh FMUs, real-time factor of the stepping loop alone (``meta["wall_time"]``);
* sweeps (``orchestrator.sweep.run_sweep``, the designs' gains computed beforehand), each
  timed at two sizes: the whole call of the larger (every worker's start-up, process and
  FMU loading, included) and the marginal rate between the two (start-up cancelled out):

  - the old path, fresh FMUs for every case (``reuse=False``), 1 worker;
  - FMUs instantiated once per worker and reset between cases: 1 worker (in process),
    2 local worker processes, 1 and 2 workers of a local Dask cluster (processes of 1
    thread, ``sweep.DASK_CONFIG``, started and its workers' imports done before the clock
    starts; the idle CPU of a default cluster and of that one printed beside);

  with runs/s, runs/s and real-time factor per worker, per worker against the loop
  (target >= 80 %) and 2 workers against 1 (target >= 1.9x): against the in-process worker,
  and for Dask also against the 1-worker Dask cluster (the same path, one worker more);
* then ``--rounds`` rounds (default 5) of the 1- and 2-worker sweeps timed back to back, each
  right after its own measure of the single-run loop, and the ratios' median and range over
  the rounds (2 workers against 1, per worker against the loop): on a VM whose speed drifts
  by tens of per cent within minutes, a ratio of two figures timed a minute apart carries
  that drift.

The figures need a quiet machine: the load average before and after is printed.

Usage: python tests/bench/bench_sweep.py [--cases 40] [--old-cases 10] [--duration 6]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import time
from dataclasses import dataclass
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


@dataclass
class Sweep:
    """A sweep timed at two sizes: the whole call of the larger one (workers' start-up
    included) and the marginal rate between them (start-up cancelled out)."""

    label: str
    workers: int
    runs: int
    wall: float
    marginal: float  # runs/s
    per_run: float  # mean wall time of one run_case, s
    cpu: float  # CPU seconds of the larger sweep, every process of it


def _cpu(who: int) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def cpu_now(client: Any = None) -> float:
    """CPU seconds so far of this process, its reaped children (pool workers) and, with a
    Dask client, the cluster's workers."""
    total = _cpu(resource.RUSAGE_SELF) + _cpu(resource.RUSAGE_CHILDREN)
    if client is not None:
        total += sum(client.run(_cpu, resource.RUSAGE_SELF).values())
    return total


def timed(cases: int, duration: float, **kw: Any) -> tuple[float, list[dict[str, Any]]]:
    t0 = time.perf_counter()
    rows = sweep.run_sweep(cases, seed=0, duration=duration, design_set=DESIGNS,
                           progress=False, **kw)
    return time.perf_counter() - t0, rows


def measure(label: str, n_workers: int, small: int, large: int, duration: float,
            **kw: Any) -> Sweep:
    t_small, rows_small = timed(small, duration, **kw)
    cpu0 = cpu_now(kw.get("dask"))
    t_large, rows = timed(large, duration, **kw)
    cpu = cpu_now(kw.get("dask")) - cpu0
    marginal = (len(rows) - len(rows_small)) / (t_large - t_small)
    return Sweep(label, n_workers, len(rows), t_large, marginal,
                 statistics.fmean(r["wall_time"] for r in rows), cpu)


def dask_sweeps(small: int, large: int, duration: float) -> tuple[Sweep, Sweep] | None:
    """The sweeps on a LocalCluster with ``sweep.DASK_CONFIG``, of 1 and of 2 workers (1
    thread each); the idle background of a default one and of that one."""
    try:
        import dask
        from dask.distributed import Client, LocalCluster
    except ImportError:
        return None
    out = []
    for label, config, n in (("default", {}, 2), ("sweep.DASK_CONFIG", sweep.DASK_CONFIG, 1),
                             ("sweep.DASK_CONFIG", sweep.DASK_CONFIG, 2)):
        with dask.config.set(config), LocalCluster(
                n_workers=n, processes=True, threads_per_worker=1,
                dashboard_address=None) as cluster, Client(cluster) as client:
            client.run(lambda: __import__("orchestrator.sweep"))  # imports, not FMUs
            if n == 2:
                idle_background(client, label)
            if config:
                out.append(measure(f"reused FMUs, Dask {n}x1, DASK_CONFIG", n, small, large,
                                   duration, dask=client))
    return out[0], out[1]


def interleaved(rounds: int, small: int, large: int, duration: float, loop_runs: int) -> None:
    """The 1- and 2-worker sweeps again, ``rounds`` times, each round timing them back to
    back (in process and 2 local processes, then Dask 1 x 1 and 2 x 1, each cluster
    started for its sweep: a forked pool beside a live cluster's threads could deadlock;
    every other round in the opposite order), each sweep right after ``loop_runs`` single
    runs, so that the machine's drift falls on a ratio's two terms alike; the ratios'
    median and range over the rounds."""
    import importlib.util

    have_dask = importlib.util.find_spec("distributed") is not None
    ratios: dict[str, list[tuple[float, float]]] = {}
    vs_loop: dict[str, list[float]] = {}

    def ratio(name: str, a: Sweep, b: Sweep) -> None:
        ratios.setdefault(name, []).append(
            (a.runs / a.wall / (b.runs / b.wall), a.marginal / b.marginal))

    def paired(label: str, n_workers: int, **kw: Any) -> Sweep:
        """The sweep right after the single-run loop's speed: its marginal RTF per worker
        against the loop's, both timed within seconds."""
        rtf_loop = loop_rtf(loop_runs, duration)[0]
        s = measure(label, n_workers, small, large, duration, **kw)
        vs_loop.setdefault(label, []).append(duration * s.marginal / n_workers / rtf_loop)
        return s

    def on_dask(n_workers: int) -> Sweep:
        import dask
        from dask.distributed import Client, LocalCluster

        kw = {"processes": True, "threads_per_worker": 1, "dashboard_address": None}
        with dask.config.set(sweep.DASK_CONFIG), \
                LocalCluster(n_workers=n_workers, **kw) as cluster, Client(cluster) as k:
            k.run(lambda: __import__("orchestrator.sweep"))
            return paired(f"Dask {n_workers}x1", n_workers, dask=k)

    for r in range(rounds):
        # the order alternates from round to round (1 then 2 workers, then 2 then 1), so
        # that a drift in one direction does not favour either side of a ratio
        if r % 2 == 0:
            one = paired("in process", 1)
            pool = paired("2 local processes", 2, workers=2)
        else:
            pool = paired("2 local processes", 2, workers=2)
            one = paired("in process", 1)
        ratio("2 local processes / in process", pool, one)
        if have_dask:
            if r % 2 == 0:
                d1, d2 = on_dask(1), on_dask(2)
            else:
                d2, d1 = on_dask(2), on_dask(1)
            ratio("Dask 2x1 / in process", d2, one)
            ratio("Dask 2x1 / Dask 1x1", d2, d1)
    print(f"2 workers vs 1, timed back to back in each of {rounds} rounds (whole call, "
          "marginal; median [range]):")
    for name, vals in ratios.items():
        whole, marg = zip(*vals, strict=True)
        print(f"  {name:34s} whole {statistics.median(whole):5.2f}x "
              f"[{min(whole):.2f}-{max(whole):.2f}]   marginal {statistics.median(marg):5.2f}x "
              f"[{min(marg):.2f}-{max(marg):.2f}]")
    print(f"per worker against the single-run loop timed just before each sweep ({loop_runs} "
          f"runs), marginal RTF per worker / loop RTF, median [range] over {rounds} rounds:")
    for name, fracs in vs_loop.items():
        print(f"  {name:34s} {100 * statistics.median(fracs):5.0f} % "
              f"[{100 * min(fracs):.0f}-{100 * max(fracs):.0f}]")


def idle_background(client: Any, label: str, seconds: float = 2.0) -> None:
    """What an idle LocalCluster burns (heartbeats, monitors, the workers' profilers): the
    cores it takes from the work on a 2-core machine."""
    workers0, main0 = sum(client.run(_cpu, resource.RUSAGE_SELF).values()), _cpu(
        resource.RUSAGE_SELF)
    time.sleep(seconds)
    workers = sum(client.run(_cpu, resource.RUSAGE_SELF).values()) - workers0
    main = _cpu(resource.RUSAGE_SELF) - main0
    print(f"idle Dask LocalCluster, {label}: {(workers + main) / seconds:.2f} cores "
          f"(scheduler, nannies "
          f"and client in this process {main / seconds:.2f}, the 2 workers "
          f"{workers / seconds:.2f})")


def report(s: Sweep, duration: float, rtf_loop: float, one: Sweep | None) -> None:
    whole, per_whole = s.runs / s.wall, s.runs / s.wall / s.workers
    per = s.marginal / s.workers
    vs_one = (f"{whole / (one.runs / one.wall):6.2f}x {s.marginal / one.marginal:6.2f}x"
              if one else f"{'':15s}")
    print(f"{s.label:35s} {s.workers:2d} {s.runs:5d} {s.wall:6.2f} {whole:7.2f} "
          f"{duration * per_whole:6.1f}x {s.marginal:7.2f} {duration * per:6.1f}x "
          f"{100 * duration * per / rtf_loop:5.0f} % {vs_one} {duration / s.per_run:6.1f}x "
          f"{1e3 * s.cpu / s.runs:7.1f} {s.cpu / s.wall:5.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=40,
                        help="cases of the reused-FMU sweeps (x 2 designs; default 40)")
    parser.add_argument("--old-cases", type=int, default=10,
                        help="cases of the fresh-FMU sweep (x 2 designs; default 10)")
    parser.add_argument("--loop-runs", type=int, default=10,
                        help="single runs that give the loop speed (default 10)")
    parser.add_argument("--duration", type=float, default=6.0, help="s per run (default 6)")
    parser.add_argument("--rounds", type=int, default=5,
                        help="rounds of the 1- and 2-worker sweeps timed back to back, for "
                             "ratios the machine's drift does not skew (default 5; 0: none)")
    args = parser.parse_args()
    d, n = args.duration, args.cases
    small = max(1, n // 6)
    load0 = os.getloadavg()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"Python {platform.python_version()}; load average {load0[0]:.2f} before")
    sweep.designs()  # the gains, once per process (what every sweep call then reuses)
    rtf_loop, loop_s = loop_rtf(args.loop_runs, d)
    print(f"single-run loop (orchestrator.master.run, meta wall_time, {args.loop_runs} runs of "
          f"the sweep's cases, {d:g} s each): RTF {rtf_loop:.1f}x ({1e3 * loop_s:.1f} ms/run)")
    print(f"sweeps of {n} cases x {len(DESIGNS)} designs, and of {small} x {len(DESIGNS)} for "
          "the marginal rate (the difference: workers' start-up cancelled out)")
    print(f"{'':35s} {'':2s} {'':5s} {'whole call':^21s} {'marginal':^29s} "
          f"{'vs 1 worker':^15s}")
    print(f"{'sweep':35s} {'w':>2s} {'runs':>5s} {'wall s':>6s} {'runs/s':>7s} "
          f"{'RTF/w':>7s} {'runs/s':>7s} {'RTF/w':>7s} {'vs loop':>7s} {'whole':>7s} "
          f"{'marg.':>7s} {'1 run':>7s} {'CPU ms':>7s} {'cores':>5s}")
    old = args.old_cases
    report(measure("fresh FMUs per case (reuse=False)", 1, max(1, old // 5), old, d,
                   reuse=False), d, rtf_loop, None)
    one = measure("reused FMUs, in process", 1, small, n, d)
    report(one, d, rtf_loop, None)
    pool = measure("reused FMUs, 2 local processes", 2, small, n, d, workers=2)
    report(pool, d, rtf_loop, one)
    both = dask_sweeps(small, n, d)
    dask = None
    if both is None:
        print("dask.distributed not installed: no Dask figures")
    else:
        dask_one, dask = both
        report(dask_one, d, rtf_loop, None)
        report(dask, d, rtf_loop, one)
        print(f"Dask 2x1 vs Dask 1x1 (the same path, 1 worker more): whole call "
              f"{dask.runs / dask.wall / (dask_one.runs / dask_one.wall):.2f}x, marginal "
              f"{dask.marginal / dask_one.marginal:.2f}x")
    if args.rounds > 0:
        interleaved(args.rounds, small, n, d, min(args.loop_runs, 6))
    bound = ", ".join(f"{name} {2 * one.cpu / one.runs / (s.cpu / s.runs):.2f}x"
                      for name, s in (("2 local processes", pool), ("Dask", dask))
                      if s is not None)
    print(f"2 workers vs 1 if the CPU per run stays as measured and 2 cores are free "
          f"(2 x CPU per run of 1 worker / CPU per run of 2): {bound}")
    print(f"load average {os.getloadavg()[0]:.2f} after.  RTF/w: real-time factor per worker; "
          "vs loop: marginal RTF per worker / single-run loop RTF; 1 run: RTF of one run_case "
          "(reset, set-up, loop, metrics) alone; CPU ms: CPU time per run of every process of "
          "the sweep (the same with 1 and 2 workers: nothing is done twice or waits spinning); "
          "cores: CPU time / wall time, the cores the sweep got (2 workers below 2: the "
          "machine was busy)")


if __name__ == "__main__":
    main()
