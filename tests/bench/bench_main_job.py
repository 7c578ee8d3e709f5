"""Benchmark: the main job as the user waits for it (prints figures, asserts nothing).

``fullpose run SCENARIO`` (default options: results, metrics and every figure) timed as a
user's shell times it, process start included, ``--repeat`` times; then, in this process, the
same run with each phase timed (``RunOutput.timings``), the FMUs' own compute inside the loop
(both FMUs time themselves), each figure drawn alone, and the results formats written side by
side (``results.parquet``, ``--csv``, and the npz of earlier versions as the peer).

Usage: python tests/bench/bench_main_job.py [--scenario hover_varying_orientation] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _stats(xs: list[float]) -> str:
    return (f"mean {statistics.fmean(xs):.2f} s, min {min(xs):.2f}, max {max(xs):.2f} "
            f"(n = {len(xs)})")


def user_wall(scenario: str, repeat: int, extra: list[str]) -> list[float]:
    """Wall time of the ``fullpose`` command, process start to exit."""
    out: list[float] = []
    exe = Path(sys.executable).with_name("fullpose")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "orchestrator.cli"]
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeat):
            t0 = time.perf_counter()
            subprocess.run([*cmd, "run", scenario, "--out", f"{tmp}/r{i}", *extra], check=True,
                           stdout=subprocess.DEVNULL)
            out.append(time.perf_counter() - t0)
    return out


def start_up() -> list[float]:
    """Process start and the imports of the ``fullpose`` command (no command run)."""
    out = []
    for _ in range(5):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import orchestrator.cli"], check=True)
        out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="hover_varying_orientation")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}, {sys.platform}")
    print(f"\n== `fullpose run {args.scenario}` (results, metrics, all figures) ==")
    full = user_wall(args.scenario, args.repeat, [])
    print(f"user wall, default            {_stats(full)}")
    bare = user_wall(args.scenario, args.repeat, ["--no-plots"])
    print(f"user wall, --no-plots         {_stats(bare)}")
    boot = start_up()
    print(f"process start + imports       {_stats(boot)}")

    from orchestrator.output.plots import RUN_FIGURES, figure_inputs, render_png
    from orchestrator.runner import prepare, run_scenario

    sc = prepare(args.scenario)
    with tempfile.TemporaryDirectory() as tmp:
        out = run_scenario(sc, Path(tmp) / "r", progress=False)
    t = out.timings
    meta = out.result.meta
    fmu = meta["fmu_time"]["plant"] + meta["fmu_time"]["controller"]
    print("\n== one run in this process, by phase (s) ==")
    for k in ("setup", "loop", "metrics", "results", "json", "figures", "publish"):
        print(f"  {k:28s} {t.get(k, 0.0):6.3f}")
    print(f"  {'total':28s} {sum(t.values()):6.3f}")
    print(f"  FMU compute inside the loop  {fmu:6.3f} (plant {meta['fmu_time']['plant']:.3f}, "
          f"controller {meta['fmu_time']['controller']:.3f})")
    print(f"  loop / FMU compute           {t['loop'] / fmu:6.2f}x")
    print(f"  user wall (mean) / FMU       {statistics.fmean(full) / fmu:6.2f}x "
          "(target: within 2x and <= 2.5 s)")

    print("\n== each figure drawn alone in this process (CPU s, then wall s) ==")
    af, afs, s0 = figure_inputs(out.result, sc.airframe)
    for name in (*RUN_FIGURES, "force_set"):
        render_png(name, out.result, af, afs, s0)  # fonts and caches warm
        c0, w0 = time.process_time(), time.perf_counter()
        png = render_png(name, out.result, af, afs, s0)
        print(f"  {name:28s} {time.process_time() - c0:6.3f} {time.perf_counter() - w0:6.3f}"
              f"  ({len(png) / 1e3:.0f} kB)")

    r = out.result
    print(f"\n== results formats: {r.data.shape[0]} rows x {r.data.shape[1]} columns "
          f"({meta['duration']:g} s) ==")
    with tempfile.TemporaryDirectory() as tmp:
        for label, write, name, read in (
                ("results.parquet (default)", r.write_parquet, "r.parquet", True),
                ("results.csv (--csv)", r.write_csv, "r.csv", True),
                ("npz of earlier versions", r.write_npz, "r.npz", True)):
            # (timing on: the FMUs' compute times are in the file, noise a coder cannot
            # shrink; see docs/orchestrator.md for the size without them)
            path = Path(tmp) / name
            t0 = time.perf_counter()
            write(path)
            wt = time.perf_counter() - t0
            t0 = time.perf_counter()
            back = type(r).read(path) if read else None
            rt = time.perf_counter() - t0
            same = back is not None and all(
                np.array_equal(back.data[:, i], r.stored(c) if name.endswith("parquet")
                               else r.data[:, i], equal_nan=True)
                for i, c in enumerate(r.columns))
            print(f"  {label:28s} write {wt:5.2f} s, {path.stat().st_size / 1e6:6.1f} MB, "
                  f"read {rt:5.2f} s, {'reads back what it claims' if same else 'DIFFERS'}")


if __name__ == "__main__":
    main()
