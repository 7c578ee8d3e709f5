"""Benchmark of the controller's own force-set derivation (prints figures, asserts nothing).

Per airframe (the shipped ones and the other kinds of tests/helpers/airframe_kinds.py):
- derive: S(0) and every single-rotor failure set derived by the controller's C code
  (fmu_src/controller/derive_sets.c through libfp_controller), timed inside C, median of
  ``--repeats``;
- init: what an importer waits for, the controller FMU's fmi2ExitInitializationMode with
  only the airframe's parameters set (the derivation, the checks and the rest of the
  initialization), median over fresh instances;
- design: the scipy design tool's S(0) alone (controller.force_sets, a finer servo grid),
  timed once, as the peer; and how far the two sets reach beyond each other (N, support
  functions by scipy's LP) against the design tool's own approximation gap (the distance
  between its inner and outer hulls).

    python tests/bench/bench_derive_sets.py [--repeats 20]
    PYTHONPATH=. FULLPOSE_BUILD_DIR=<cmake build dir> python tests/bench/bench_derive_sets.py
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from helpers.airframe_kinds import KINDS, load_kind

import plant
from controller import controller_fmu
from controller.derived_sets import controller_sets
from controller.force_sets import feasible_force_set
from controller.polytope import set_support
from orchestrator.sim.fmu import FmuInstance


def init_seconds(af: plant.Airframe, repeats: int) -> float:
    """Median time of the controller FMU's exit from initialization mode."""
    times = []
    for _ in range(repeats):
        c = FmuInstance(controller_fmu(), "ctrl")
        try:
            names = {v.name for v in c.md.modelVariables if v.causality == "parameter"}
            c.slave.setupExperiment(startTime=0.0)
            c.set_many({k: v for k, v in af.fmu_parameters().items() if k in names})
            alpha, beta, omega = af.hover_trim()
            pad = np.zeros(8 - af.n_rotors)
            c.write(c.signal("omega"), np.concatenate([omega, pad]))
            c.write(c.signal("alpha"), np.concatenate([alpha, pad]))
            c.write(c.signal("beta"), np.concatenate([beta, pad]))
            c.slave.enterInitializationMode()
            t0 = time.perf_counter()
            c.slave.exitInitializationMode()
            times.append(time.perf_counter() - t0)
        finally:
            c.close()
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        airframes = [plant.load_airframe(n) for n in plant.list_airframes()]
        airframes += [load_kind(k, Path(folder)) for k in KINDS]
        print(f"{'airframe':26s} {'rotors':>6s} {'servos':>6s} {'S(0) facets':>11s} "
              f"{'derive ms':>9s} {'init ms':>8s} {'design S(0) ms':>14s} {'ratio':>6s} "
              f"{'C beyond N':>10s} {'design beyond N':>15s} {'design gap N':>12s}")
        for af in airframes:
            derive = statistics.median(controller_sets(af).seconds
                                       for _ in range(args.repeats))
            sets = controller_sets(af)
            init = init_seconds(af, max(3, args.repeats // 4))
            t0 = time.perf_counter()
            p = feasible_force_set(af)
            design = time.perf_counter() - t0
            beyond_c = max(set_support(sets.s0.A, sets.s0.b, a) - b for a, b in zip(
                p.A, p.b, strict=True))
            beyond_d = max(set_support(p.A, p.b, a) - b for a, b in zip(
                sets.s0.A, sets.s0.b, strict=True))
            print(f"{af.name:26s} {af.n_rotors:6d} {'yes' if af.tilting else 'no':>6s} "
                  f"{len(sets.s0.b):11d} {derive * 1e3:9.2f} {init * 1e3:8.2f} "
                  f"{design * 1e3:14.0f} {design / derive:5.0f}x "
                  f"{max(0.0, beyond_c):10.3f} {max(0.0, beyond_d):15.3f} {p.gap:12.3f}")


if __name__ == "__main__":
    main()
