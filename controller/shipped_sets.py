"""Generate the design-time force sets shipped with the airframes.

    python -m controller.shipped_sets                 # (re)writes every shipped airframe's file
    python -m controller.shipped_sets --check         # exit 1 if a file is stale or missing
    python -m controller.shipped_sets paper_hexacopter  # one airframe

Each file, ``controller/airframe_sets/<airframe>.json``, holds the airframe's attainable force
set and S(0) as whole polytopes and the controller's single-failure parameters, for the
airframe numbers whose SHA-256 it records (``airframe_digest``): an airframe with any other
number is never served them (``controller.polytope_cache``).  ``--check`` recomputes each set
and asks whether the shipped one is a valid result for it (:func:`_valid`), not whether it is
the same bytes or even the same polytope: the refinement picks each next facet by the largest
of several near-equal excesses, so another library version or CPU can pick another facet
(measured: the paper hexacopter's AFS of one machine reaches 0.96 N beyond the other's, within
their 2.5 N approximation gaps).  The controller gets the shipped sets everywhere, so its
results do not depend on where it runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from controller.failures import failure_polytopes
from controller.fmu_parameters import FAIL_FACETS, failure_parameters
from controller.force_sets import REL_TOL, Polytope, beyond_facet, reach_beyond
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


def _valid(what: str, A: np.ndarray, b: np.ndarray, fresh: Polytope, gap: float) -> str | None:
    """Why the shipped set {A f <= b} is not a valid result of the algorithm for the set
    computed now (None: it is).  The sandwich refinement's choice of facets can follow
    round-off (another library version or CPU picks another of two near-equal facets), so
    two valid results differ within their approximation gaps; what must hold exactly is:

    * it bounds every force the actuators produce: each attainable force found now (the
      fresh inner points) satisfies every shipped facet (within REL_TOL of the set's size);
    * it is no looser than certified: it reaches at most ``gap`` (its Hausdorff distance to
      the true set) beyond the fresh outer set, which contains the true set."""
    tol = REL_TOL * fresh.scale
    out = fresh.inner_points @ A.T - b
    if out.size and float(out.max()) > tol:
        k, j = np.unravel_index(int(np.argmax(out)), out.shape)
        return (f"{what}: an attainable force found now, {np.round(fresh.inner_points[k], 4)}"
                f" N, lies {out[k, j]:.3g} N beyond facet {j} of the shipped set "
                f"(tolerance {tol:.2g} N)")
    excess, at = reach_beyond(A, b, fresh.A, fresh.b)
    if excess > gap + tol:
        where = beyond_facet(excess, at, fresh.A, fresh.b, "the fresh one")
        return f"{what}: the shipped set {where}, more than its approximation gap {gap:.3g} N"
    return None


def _failure_sets(params: dict[str, Any], n_rotors: int
                  ) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """(A, b) of each rotor's failure set from the controller's parameters (None: empty)."""
    out: list[tuple[np.ndarray, np.ndarray] | None] = []
    for i in range(n_rotors):
        n = int(params[f"fail_poly_n[{i + 1}]"])
        rows = range(i * FAIL_FACETS + 1, i * FAIL_FACETS + n + 1)
        A = np.array([[float(params[f"fail_poly_A[{r},{j}]"]) for j in (1, 2, 3)]
                      for r in rows]).reshape(-1, 3)
        b = np.array([float(params[f"fail_poly_b[{r}]"]) for r in rows])
        out.append((A, b) if n else None)
    return out


def _valid_failures(shipped: dict[str, Any], af: Airframe) -> str | None:
    fresh = failure_polytopes(af)
    if shipped.keys() != failure_parameters(fresh).keys():
        return "failures: the parameter names differ"
    try:
        sets = _failure_sets(shipped, af.n_rotors)
    except (KeyError, TypeError, ValueError) as e:
        return f"failures: unreadable parameters ({e})"
    for i, (mine, now) in enumerate(zip(sets, fresh, strict=True)):
        what = f"failures: rotor {i + 1} lost"
        if (mine is None) != (now is None):
            return f"{what}: the shipped set is {'empty' if mine is None else 'not empty'}, " \
                   f"the fresh one {'empty' if now is None else 'not empty'}"
        if mine is not None and now is not None:
            # (the parameters carry no gap: the fresh set's, from the same algorithm)
            why = _valid(what, mine[0], mine[1], now, now.gap)
            if why:
                return why
    return None


def check(af: Airframe) -> list[str]:
    """What is wrong with the shipped file of ``af`` against a fresh computation (empty:
    valid): the airframe numbers it was made for, then each set as :func:`_valid` says."""
    path = shipped_path(af.name)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        return [f"{path}: cannot read it ({e}); run {COMMAND} {af.name}"]
    if doc.get("airframe_digest") != airframe_digest(af):
        return [f"{path}: made for other airframe numbers; run {COMMAND} {af.name}"]
    problems = []
    for kind in POLYTOPE_KINDS:
        shipped = polytope_from_doc(doc[kind])
        why = _valid(kind, shipped.A, shipped.b, compute_polytope(kind, af), shipped.gap)
        if why:
            problems.append(f"{path}: {why}; run {COMMAND} {af.name}")
    why = _valid_failures(doc["failures"], af)
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
