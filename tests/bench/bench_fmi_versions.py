"""What a step costs on the FMI 2.0 and the FMI 3.0 FMUs of the same models.

    python tests/bench/bench_fmi_versions.py [--seconds 20] [--scenario hover_varying_orientation]
                                             [--repeat 5]

Runs the scenario with ``fmi = 2`` and ``fmi = 3`` (native engine, timing outputs off),
alternating, ``--repeat`` times each; prints per version the loop's wall time per 2 ms step
(both FMUs and the exchange: mean and best of the repeats), the ratio FMI 3.0 / FMI 2.0, and
whether the two recordings are bit-identical.  Asserts nothing.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from orchestrator.master import run
from orchestrator.scenario.catalogue import load_scenario


def main() -> None:
    """Parse the options, run, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--scenario", default="hover_varying_orientation")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    base = replace(load_scenario(args.scenario), duration=args.seconds)
    steps = base.n_steps
    cost: dict[int, list[float]] = {2: [], 3: []}
    last = {}
    for _ in range(args.repeat):
        for fmi in (2, 3):
            r = run(replace(base, fmi=fmi), progress=False)
            cost[fmi].append(1e6 * float(r.meta["wall_time"]) / steps)
            last[fmi] = r
    same = bool(np.array_equal(last[2].data, last[3].data, equal_nan=True))
    print(f"{args.scenario}, {args.seconds:g} s ({steps} steps), {args.repeat} runs each")
    print(f"{'FMI':>4} {'mean us/step':>13} {'best us/step':>13}")
    for fmi in (2, 3):
        print(f"{fmi:>4} {np.mean(cost[fmi]):13.2f} {np.min(cost[fmi]):13.2f}")
    print(f"FMI 3.0 / FMI 2.0: {np.mean(cost[3]) / np.mean(cost[2]):.3f} (mean), "
          f"{np.min(cost[3]) / np.min(cost[2]):.3f} (best)")
    print(f"recordings bit-identical: {same}")


if __name__ == "__main__":
    main()
