"""Digest of every shipped scenario's results: one SHA-256 per scenario over all signals
at all steps (each column's float64 bytes, columns sorted by name), so a refactoring can
show that behaviour is bit-identical.  Prints ``name digest rows columns``.

    python tests/tools/scenario_digests.py [--engine native|python] [NAME ...]
"""

from __future__ import annotations

import argparse
import hashlib

import numpy as np

from orchestrator.master import run
from orchestrator.scenario.catalogue import load_scenario, scenario_names


def digest(name: str, engine: str) -> tuple[str, int, int]:
    result = run(load_scenario(name), progress=False, engine=engine)
    h = hashlib.sha256()
    for i in sorted(range(len(result.columns)), key=lambda i: result.columns[i]):
        h.update(result.columns[i].encode())
        h.update(np.ascontiguousarray(result.data[:, i], dtype="<f8").tobytes())
    return h.hexdigest(), result.data.shape[0], result.data.shape[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("names", nargs="*")
    ap.add_argument("--engine", default="native", choices=("native", "python"))
    args = ap.parse_args()
    for name in args.names or scenario_names():
        d, rows, cols = digest(name, args.engine)
        print(f"{name:42s} {d} {rows} {cols}", flush=True)


if __name__ == "__main__":
    main()
