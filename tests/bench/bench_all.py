"""Every benchmark the README quotes, in one run (prints figures, asserts nothing).

1. the main job as the user waits for it (``bench_main_job.py``): ``fullpose run`` wall time
   with its breakdown, the loop and the FMUs' own compute, the results formats;
2. sweeps (``bench_sweep.py``): runs/s and real-time factor per worker, 1 and 2 local
   workers and a local Dask cluster, against the single run's loop speed;
3. the controller (``bench_controller.py``): the controller sample inside the FMU against the
   build of an earlier commit, and both QPs against DAQP and piqp on the same recorded
   problems.

Usage: python tests/bench/bench_all.py [--old-commit COMMIT] [--quick]

``--old-commit`` (default: the commit before issue 16's work, see ``OLD_COMMIT``) is built
once into ``build/bench-old/`` by ``build_old_controller.sh`` for the controller comparison.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
OLD_COMMIT = "06d7094626d2e5c60f8da9f84e9b237f1967810c"
"""The last commit before the work on the controller's speed (issue 16)."""


def _run(title: str, cmd: list[str]) -> None:
    print(f"\n######## {title}: {' '.join(cmd[1:])}", flush=True)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=ROOT)
    print(f"######## {title}: {time.perf_counter() - t0:.0f} s"
          + ("" if res.returncode == 0 else f", FAILED (exit {res.returncode})"), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old-commit", default=OLD_COMMIT)
    ap.add_argument("--quick", action="store_true", help="fewer repeats (a smoke run)")
    args = ap.parse_args()
    py = sys.executable
    _run("main job", [py, str(HERE / "bench_main_job.py"),
                      "--repeat", "2" if args.quick else "5"])
    if (HERE / "bench_sweep.py").exists():
        _run("sweeps", [py, str(HERE / "bench_sweep.py")])
    old = ROOT / "build" / "bench-old" / args.old_commit[:12]
    old_fmu = old / "FullPoseController.fmu"
    builder = HERE / "build_old_controller.sh"
    if not old_fmu.exists() and builder.exists():
        print(f"\nbuilding the controller FMU of {args.old_commit[:12]} into {old} ...",
              flush=True)
        subprocess.run(["bash", str(builder), args.old_commit, str(old)], cwd=ROOT,
                       check=False, env={**os.environ, "PYTHON": sys.executable})
    cmd = [py, str(HERE / "bench_controller.py")]
    if old_fmu.exists():
        cmd += ["--old-fmu", str(old_fmu)]
    _run("controller and QPs", cmd)


if __name__ == "__main__":
    main()
