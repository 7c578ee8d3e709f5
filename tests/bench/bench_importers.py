"""What replaying a scenario costs in each SSP runner, and how far it lands from ours.

    python tests/bench/bench_importers.py [--seconds 10] [--scenario hover_varying_orientation]

Exports the scenario (``fullpose export-ssp --scenario``) and plays the archive in every
runner found here: libcosim (libcosimpy), fmpy's ``simulate_ssp`` (with the recorded options
and a consistent first step), OMSimulator's command line (tests/tools/omsimulator.sh); and
runs ``fullpose run`` with Jacobi coupling, the reference.  Prints per runner: wall time,
microseconds per 2 ms step (whole loop: three FMUs and the exchange), the ratio to ours, and
the largest position difference to ours.  Asserts nothing.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from orchestrator.export.fmpy_ssp import simulate_with_fmpy
from orchestrator.master import run
from orchestrator.scenario.catalogue import load_scenario
from orchestrator.scenario_ssp import export_scenario_ssp

ROOT = Path(__file__).resolve().parents[2]


def libcosim(path: Path, steps: int) -> np.ndarray | None:
    try:
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
        from libcosimpy.CosimObserver import CosimObserver
    except ImportError:
        return None
    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_ssp_file(str(path))
    plant = ex.slave_index_from_instance_name("MultirotorPlant")
    refs = {v.name.decode(): v.reference for v in ex.slave_variables(plant)}
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    assert ex.simulate_until(steps * 2_000_000)  # ns
    return np.array(obs.last_real_values(plant, [refs[f"pos[{i}]"] for i in (1, 2, 3)]))


def omsimulator(path: Path, seconds: float, work: Path) -> np.ndarray | None:
    found = subprocess.run(["bash", str(ROOT / "tests" / "tools" / "omsimulator.sh")],
                           capture_output=True, text=True, check=False)
    if found.returncode != 0:
        return None
    out = work / "oms.csv"
    subprocess.run([str(Path(found.stdout.strip()) / "bin" / "OMSimulator"),
                    f"--stopTime={seconds}", f"--resultFile={out}", str(path)],
                   capture_output=True, check=True, cwd=work)
    with out.open() as f:
        rows = list(csv.reader(f))
    cols = [next(i for i, c in enumerate(rows[0]) if c.endswith(f"MultirotorPlant.pos[{k}]"))
            for k in (1, 2, 3)]
    return np.array([float(rows[-1][c]) for c in cols])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="hover_varying_orientation")
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    sc = replace(load_scenario(args.scenario), duration=args.seconds)
    steps = round(args.seconds / sc.step)
    work = Path(tempfile.mkdtemp(prefix="bench_importers_"))
    t0 = time.perf_counter()
    path = export_scenario_ssp(work / "s.ssp", sc)
    print(f"{args.scenario}, {args.seconds:g} s ({steps} steps): export "
          f"{time.perf_counter() - t0:.2f} s, {path.stat().st_size / 1e6:.1f} MB")
    t0 = time.perf_counter()
    r = run(replace(sc, coupling="jacobi"), progress=False)
    ours_wall = time.perf_counter() - t0
    ours = r.get("plant.pos")[-1]
    results = [("fullpose run (jacobi)", ours_wall, ours)]
    for name, fn in (("libcosim", lambda: libcosim(path, steps)),
                     ("OMSimulator CLI", lambda: omsimulator(path, args.seconds, work)),
                     ("fmpy simulate_ssp", lambda: _fmpy(path))):
        t0 = time.perf_counter()
        pos = fn()
        wall = time.perf_counter() - t0
        if pos is None:
            print(f"{name:24s} not found here")
            continue
        results.append((name, wall, pos))
    print(f"{'runner':24s} {'wall s':>8s} {'us/step':>9s} {'x ours':>7s} {'|dpos| at end m':>16s}")
    for name, wall, pos in results:
        print(f"{name:24s} {wall:8.2f} {wall / steps * 1e6:9.1f} {wall / ours_wall:7.1f} "
              f"{np.abs(pos - ours).max():16.3g}")
    sys.stdout.flush()
    os.system(f"rm -rf {work}")


def _fmpy(path: Path) -> np.ndarray:
    res = simulate_with_fmpy(path)
    return np.array([res[f"MultirotorPlant.pos[{i}]"][-1] for i in (1, 2, 3)])


if __name__ == "__main__":
    main()
