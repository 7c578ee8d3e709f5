"""Generate the controller FMU's default single-rotor-failure polytopes as C source.

    python -m controller.failure_defaults          # (re)writes the header below
    python -m controller.failure_defaults --check  # exit 1 if the file on disk is stale

The header is fmu_src/controller/default_fail_polytopes.h: for the paper hexacopter and
each rotor i, S(tau = 0) of the vehicle without rotor i (controller.failures), at most
FAIL_FACETS facets each in canonical order, numbers printed with "%.17g" (deterministic
computation).  ``--check`` checks like ``python -m controller.polytope_defaults --check``:
the text outside the numbers must be the template's and each rotor's facets at the offsets
computed now for their normals (:func:`controller.force_sets.facet_problem`), never byte for
byte nor against a fresh polytope (another platform can pick other normals by round-off).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from controller.failures import airframe_without, failure_polytopes, hover_possible
from controller.fmu_parameters import FAIL_FACETS, MAX_ROTORS
from controller.force_sets import Polytope, facet_problem
from controller.polytope_defaults import check_header, read_array, skeleton
from plant import load_airframe
from plant.airframe import Airframe

AIRFRAME = "paper_hexacopter"
COMMAND = "python -m controller.failure_defaults"
HEADER = (Path(__file__).resolve().parents[1] / "fmu_src" / "controller"
          / "default_fail_polytopes.h")


def _numbers(values: np.ndarray) -> str:
    return ",\n".join(f"    {float(v):.17g}" for v in values.reshape(-1))


def render(polys: Sequence[Polytope | None] | None = None) -> str:
    """The header text; ``polys`` (one per rotor) defaults to a fresh computation."""
    af = load_airframe(AIRFRAME)
    polys = failure_polytopes(af) if polys is None else polys
    counts = [0 if p is None else len(p.b) for p in polys] + [0] * (MAX_ROTORS - len(polys))
    A = np.zeros((MAX_ROTORS * FAIL_FACETS, 3))
    b = np.zeros(MAX_ROTORS * FAIL_FACETS)
    notes = []
    for i, p in enumerate(polys):
        if p is not None:
            A[i * FAIL_FACETS:i * FAIL_FACETS + len(p.b)] = p.A
            b[i * FAIL_FACETS:i * FAIL_FACETS + len(p.b)] = p.b
        notes.append(f" * rotor {i + 1}: {counts[i]} facets, hover "
                     f"{'possible' if hover_possible(p, af) else 'IMPOSSIBLE'}")
    return f"""\
/*
 * GENERATED FILE - do not edit.  Regenerate with:   {COMMAND}
 * Freshness: {COMMAND} --check (tests/test_multirotor_classes.py runs the check).
 *
 * Default single-rotor-failure polytopes of the FullPoseController: for the airframe
 * "{AIRFRAME}" and each rotor i, S(tau = 0) of the vehicle that has lost rotor i, as
 * {{f_b : A f_b <= b}} (body FRD, N), rows i * FP_FAIL_POLYTOPE_FACETS ... of the arrays.
{chr(10).join(notes)}
 */
#ifndef FP_DEFAULT_FAIL_POLYTOPES_H
#define FP_DEFAULT_FAIL_POLYTOPES_H

/* Facets per single-failure polytope (capacity of fail_poly_A / fail_poly_b per rotor). */
#define FP_FAIL_POLYTOPE_FACETS {FAIL_FACETS}

static const int fp_default_fail_n[{MAX_ROTORS}] = {{{", ".join(str(c) for c in counts)}}};

static const double fp_default_fail_A[{MAX_ROTORS * FAIL_FACETS} * 3] = {{
{_numbers(A)}
}};

static const double fp_default_fail_b[{MAX_ROTORS * FAIL_FACETS}] = {{
{_numbers(b)}
}};

#endif
"""


def parse(text: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per rotor slot (MAX_ROTORS of them) the (A, b) of its polytope, read from a header."""
    counts = read_array(text, "fp_default_fail_n").astype(int)
    A = read_array(text, "fp_default_fail_A").reshape(-1, 3)
    b = read_array(text, "fp_default_fail_b")
    if counts.size != MAX_ROTORS or b.size != MAX_ROTORS * FAIL_FACETS or len(A) != b.size \
            or np.any(counts < 0) or np.any(counts > FAIL_FACETS):
        raise ValueError("array sizes or facet counts do not fit FP_FAIL_POLYTOPE_FACETS")
    rows = [slice(i * FAIL_FACETS, i * FAIL_FACETS + int(n)) for i, n in enumerate(counts)]
    return [(A[r], b[r]) for r in rows]


def compare(old: str, fresh: str, airframe: Airframe | str = AIRFRAME) -> tuple[bool, str]:
    """(same, reason): a header text against a fresh rendering's template, each rotor's
    polytope against the airframe without that rotor, computed now (facet by facet)."""
    af = load_airframe(airframe) if isinstance(airframe, str) else airframe
    try:
        if skeleton(old) != skeleton(fresh):
            return False, "its text is not the generator's (template changed or file edited)"
        problems = []
        for i, (A0, b0) in enumerate(parse(old)):
            if i >= af.n_rotors:
                if len(b0):
                    problems.append(f"rotor slot {i + 1}: {len(b0)} facets, no such rotor")
                continue
            why = facet_problem(airframe_without(af, [i]), A0, b0, np.zeros(3),
                                what=f"rotor {i + 1}")
            if why:
                problems.append(why)
    except ValueError as exc:
        return False, f"it is not in the generated format ({exc})"
    if problems:
        return False, "; ".join(problems)
    return True, "every rotor's facets at the offsets computed now"


def check(path: Path = HEADER, fresh: str | None = None,
          airframe: Airframe | str = AIRFRAME) -> tuple[bool, str]:
    """(up to date, message): the file against a fresh rendering's template and the
    airframe's failure sets computed now (:func:`compare`)."""
    return check_header(path, render() if fresh is None else fresh,
                        lambda old, new: compare(old, new, airframe), COMMAND)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if the header is stale (polytopes compared as sets)")
    parser.add_argument("--output", type=Path, default=HEADER, help=f"default: {HEADER}")
    args = parser.parse_args(argv)
    if args.check:
        ok, message = check(args.output)
        print(message, file=sys.stdout if ok else sys.stderr)
        return 0 if ok else 1
    args.output.write_text(render(), encoding="utf-8")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
