"""Generate the design-time force sets shipped with the airframes.

    python -m controller.shipped_sets                 # (re)writes every shipped airframe's file
    python -m controller.shipped_sets --check         # exit 1 if a file is stale or missing
    python -m controller.shipped_sets paper_hexacopter  # one airframe

Each file, ``controller/airframe_sets/<airframe>.json``, holds the airframe's attainable force
set and S(0) as whole polytopes and the controller's single-failure parameters, for the
airframe numbers whose SHA-256 it records (``airframe_digest``): an airframe with any other
number is never served them (``controller.polytope_cache``).  ``--check`` recomputes and
compares as sets, within :data:`controller.force_sets.REL_TOL` of the set's size
(:func:`controller.force_sets.same_polytope`), not bytes: other library versions move the
numbers by round-off.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from typing import Any

from controller.failures import failure_polytopes
from controller.fmu_parameters import failure_parameters
from controller.force_sets import REL_TOL, Polytope, same_polytope
from controller.polytope_cache import (
    POLYTOPE_KINDS,
    airframe_digest,
    compute_polytope,
    polytope_doc,
    polytope_from_doc,
    shipped_path,
)
from plant.airframe import Airframe, list_airframes, load_airframe

COMMAND = "python -m controller.shipped_sets"


def generate(af: Airframe) -> dict[str, Any]:
    """The shipped document of one airframe, computed now."""
    doc: dict[str, Any] = {"format": 1, "generated_by": COMMAND, "airframe": af.name,
                           "airframe_digest": airframe_digest(af)}
    for kind in POLYTOPE_KINDS:
        doc[kind] = polytope_doc(compute_polytope(kind, af))
    doc["failures"] = failure_parameters(failure_polytopes(af))
    return doc


def _same(kind: str, a: Polytope, b: Polytope) -> str | None:
    same, reason = same_polytope(a.A, a.b, b.A, b.b, rtol=REL_TOL,
                                 names=("the shipped set", "the fresh one"))
    return None if same else f"{kind}: {reason}"


def _same_params(shipped: dict[str, Any], fresh: dict[str, Any], scale: float) -> str | None:
    if shipped.keys() != fresh.keys():
        return "failures: the parameter names differ"
    for k, v in fresh.items():
        w = shipped[k]
        if isinstance(v, int) and not isinstance(v, bool):
            if v != w:
                return f"failures: {k} = {w}, fresh {v}"
        elif not math.isclose(float(w), float(v), rel_tol=1e-6, abs_tol=1e-6 * scale):
            return f"failures: {k} = {w!r}, fresh {v!r}"
    return None


def check(af: Airframe) -> list[str]:
    """What differs between the shipped file of ``af`` and a fresh computation (empty: fresh).

    The failure sets are compared by parameter with a relative tolerance of 1e-6 of the set's
    size: their facets are listed in canonical order, so equal sets give equal rows."""
    path = shipped_path(af.name)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        return [f"{path}: cannot read it ({e}); run {COMMAND} {af.name}"]
    if doc.get("airframe_digest") != airframe_digest(af):
        return [f"{path}: made for other airframe numbers; run {COMMAND} {af.name}"]
    problems = []
    scale = 1.0
    for kind in POLYTOPE_KINDS:
        fresh = compute_polytope(kind, af)
        scale = max(scale, fresh.scale)
        why = _same(kind, polytope_from_doc(doc[kind]), fresh)
        if why:
            problems.append(f"{path}: {why}; run {COMMAND} {af.name}")
    why = _same_params(doc["failures"], failure_parameters(failure_polytopes(af)), scale)
    if why:
        problems.append(f"{path}: {why}; run {COMMAND} {af.name}")
    return problems


def main(argv: Sequence[str] | None = None) -> int:
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
