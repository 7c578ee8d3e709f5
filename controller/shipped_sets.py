"""Generate the design-time force sets shipped with the airframes.

    python -m controller.shipped_sets                 # (re)writes every shipped airframe's file
    python -m controller.shipped_sets --check         # exit 1 if a file is stale or missing
    python -m controller.shipped_sets paper_hexacopter  # one airframe

Each file, ``controller/airframe_sets/<airframe>.json``, holds the airframe's attainable force
set and S(0) as whole polytopes and the controller's single-failure parameters, for the
rotor numbers whose SHA-256 it records (``rotors_digest``: the numbers the sets depend on,
``controller.polytope_cache.SET_PARAMETERS``): an airframe with other rotors is never served
them, while a heavier vehicle with the same rotors is (``controller.polytope_cache``).

``--check`` asks, for each shipped facet, whether its offset is the one computed now for its
normal (:func:`controller.force_sets.facet_problem`), not whether the polytope is the same:
the refinement picks each next facet by the largest of several near-equal excesses, so
another library version or CPU can pick other normals (measured: the paper hexacopter's AFS
of one machine reaches 0.96 N beyond the other's, while the offsets of either's normals
agree to 1e-13 N).  The controller gets the shipped sets everywhere, so its results do not
depend on where it runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from controller.failures import airframe_without, failure_polytopes
from controller.fmu_parameters import failure_facets, failure_parameters
from controller.force_sets import facet_problem
from controller.polytope_cache import (
    POLYTOPE_KINDS,
    compute_polytope,
    polytope_doc,
    polytope_from_doc,
    rotors_digest,
    shipped_path,
)
from plant.airframe import Airframe, list_airframes, load_airframe

COMMAND = "python -m controller.shipped_sets"


def generate(af: Airframe) -> dict[str, Any]:
    """The shipped document of one airframe, computed now."""
    doc: dict[str, Any] = {"format": 2, "generated_by": COMMAND, "airframe": af.name,
                           "rotors_digest": rotors_digest(af)}
    for kind in POLYTOPE_KINDS:
        doc[kind] = polytope_doc(compute_polytope(kind, af))
    doc["failures"] = failure_parameters(failure_polytopes(af))
    return doc


def check(af: Airframe) -> list[str]:
    """What is wrong with the shipped file of ``af`` (empty: nothing): the airframe numbers it
    was made for, then every set's facets against the offsets computed now for their normals
    (:func:`controller.force_sets.facet_problem`)."""
    path = shipped_path(af.name)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        return [f"{path}: cannot read it ({e}); run {COMMAND} {af.name}"]
    if doc.get("rotors_digest") != rotors_digest(af):
        return [f"{path}: made for other rotor numbers; run {COMMAND} {af.name}"]
    problems = []
    for kind in POLYTOPE_KINDS:
        shipped = polytope_from_doc(doc[kind])
        problems.append(facet_problem(af, shipped.A, shipped.b,
                                      None if kind == "afs" else np.zeros(3), what=kind))
    try:
        sets = [(np.array(A).reshape(-1, 3), np.array(b))
                for A, b in failure_facets(doc["failures"], af.n_rotors)]
    except (KeyError, TypeError, ValueError) as e:
        sets = []
        problems.append(f"failures: unreadable parameters ({e})")
    for i, (A, b) in enumerate(sets):
        problems.append(facet_problem(airframe_without(af, [i]), A, b, np.zeros(3),
                                      what=f"failures: rotor {i + 1} lost"))
    return [f"{path}: {p}; run {COMMAND} {af.name}" for p in problems if p]


def main(argv: Sequence[str] | None = None) -> int:
    """The command: write the shipped airframes' set files, or --check them; the exit status."""
    ap = argparse.ArgumentParser(prog=COMMAND, description=__doc__.splitlines()[0])
    ap.add_argument("airframes", nargs="*", help="shipped airframe names (default: all)")
    ap.add_argument("--check", action="store_true", help="compare, write nothing")
    args = ap.parse_args(argv)
    names = args.airframes or list_airframes()
    failed = False
    for name in names:
        af = load_airframe(name)
        if args.check:
            problems = check(af)
            for p in problems:
                print(p, file=sys.stderr)
            failed |= bool(problems)
            print(f"{name}: {'stale' if problems else 'fresh'}")
            continue
        path = shipped_path(af.name)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(generate(af), indent=1) + "\n", encoding="utf-8")
        print(f"wrote {path}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
