"""The plant as Model Exchange against its co-simulation: the closed-loop figures of
docs/fmus.md, "Model Exchange".

    python tests/bench/bench_model_exchange.py [--seconds 10] [--rtol 1e-6 1e-8 1e-10]

For the hover (started 0.3 m and a few degrees off the reference, so that the loop has a
transient) and the paper's first scenario (hover_varying_orientation): the co-simulation
controller (FMI 2.0, 2 ms) flies the co-simulation plant (RK4, 0.5 ms), then the Model
Exchange plant integrated by CVode between its samples at each relative tolerance
(tests/helpers/me_master.py).  Prints per run the largest position difference from the
co-simulation loop and when, the largest Euler-angle difference, CVode's steps and
derivative evaluations (the solver restarts at every sample: the commands step there), the
state events, and the wall time of both loops.  Asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: the shared helpers

from helpers.me_master import H, closed_loop

from orchestrator.sim.start_values import Pose

CASES = (("hover", Pose.of((0.3, -0.2, -2.7), (0.05, -0.03, 0.1))),
         ("hover_varying_orientation", None))


def main() -> None:
    """Parse the options, fly, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rtol", type=float, nargs="+", default=[1e-6, 1e-8, 1e-10])
    args = ap.parse_args()
    print(f"{'scenario':28} {'rtol':>7} {'max |dpos| m':>13} {'at s':>7} {'max |deuler|':>13} "
          f"{'CVode steps':>11} {'f evals':>8} {'events':>6} {'wall ME/CS s':>13}")
    for scenario, pose in CASES:
        cs = closed_loop("cs", scenario, args.seconds, pose=pose)
        for rtol in args.rtol:
            me = closed_loop("me", scenario, args.seconds, pose=pose, rtol=rtol)
            d = np.linalg.norm(me.pos - cs.pos, axis=1)
            e = np.abs(me.euler - cs.euler).max()
            print(f"{scenario:28} {rtol:7.0e} {d.max():13.3g} {d.argmax() * H:7.3f} {e:13.3g} "
                  f"{me.steps:11d} {me.rhs:8d} {me.events:6d} {me.wall:6.2f}/{cs.wall:.2f}")


if __name__ == "__main__":
    main()
