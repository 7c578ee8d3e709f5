"""Benchmark: the orchestrator on the paper's scenarios (prints figures, asserts nothing).

For each scenario, in one process: the real-time factor end to end (FMU loading,
initialization, the 500 Hz loop and in-memory recording of every signal; file
writing and plots reported separately), and the master's overhead as a ratio of
the FMUs' own compute time, which both FMUs measure themselves in the same run
(``timing`` on).  Both step engines: the C kernel (default) and the pure-Python
loop (reference).

Usage: python tests/bench/bench_orchestrator.py [--duration 100]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from orchestrator.master import run
from orchestrator.runner import prepare

PAPER = ["hover_varying_orientation", "translation_frequency_sweep", "full_pose_with_disturbances"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=None, help="override (s)")
    args = parser.parse_args()
    print(f"{'scenario':30s} {'engine':7s} {'RTF end-to-end':>15s} {'RTF loop':>9s} "
          f"{'FMU us/step':>12s} {'master us/step':>15s} {'overhead':>9s}")
    for name in PAPER:
        sc = prepare(name, duration=args.duration)
        for engine in ("native", "python"):
            t0 = time.perf_counter()
            result = run(sc, timing=True, progress=False, engine=engine)
            total = time.perf_counter() - t0
            meta = result.meta
            steps = round(meta["duration"] / meta["step"])
            fmu = meta["fmu_time"]["plant"] + meta["fmu_time"]["controller"]
            master = meta["wall_time"] - fmu
            print(f"{name:30s} {engine:7s} {meta['duration'] / total:14.0f}x "
                  f"{meta['duration'] / meta['wall_time']:8.0f}x {1e6 * fmu / steps:12.2f} "
                  f"{1e6 * master / steps:15.2f} {100 * master / fmu:8.1f}%")
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            result.write_parquet(Path(tmp) / "r.parquet")
            t_parquet = time.perf_counter() - t0
            t0 = time.perf_counter()
            result.write_csv(Path(tmp) / "r.csv")
            t_csv = time.perf_counter() - t0
        print(f"{'':30s} writing {result.data.shape[0]} x {result.data.shape[1]} values: "
              f"parquet {t_parquet:.2f} s, csv {t_csv:.2f} s")


if __name__ == "__main__":
    main()
