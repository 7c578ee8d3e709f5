"""Generate the controller FMU's default feasible-force polytope as C source.

    python -m controller.polytope_defaults          # (re)writes the header below
    python -m controller.polytope_defaults --check  # exit 1 if the file on disk is stale

The header is fmu_src/controller/default_polytope.h.

The polytope is S(tau = 0) of the paper hexacopter (paper eq. 6), computed by
:func:`controller.force_sets.feasible_force_set` with its defaults, written as an
H-representation {f_b : A f_b <= b} (body FRD, N; rows of A are unit normals) with its facets in
the canonical order of :func:`controller.force_sets.canonical_facets`, numbers printed with
"%.17g" (they round-trip).  ``--check`` does not compare bytes, nor even the polytope with a
fresh one: another platform or library version can pick other facet normals by round-off.
It requires the text outside the numbers to be the template's, the facet count to match the
arrays, every facet's offset to be the one computed now for its normal
(:func:`controller.force_sets.facet_problem`, within :data:`controller.force_sets.REL_TOL`
of the set's size) and the f_bz range to be the file's polytope's; otherwise it says what
differs.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from controller.force_sets import (
    DEFAULT_GRID,
    MAX_FACETS,
    REL_TOL,
    Polytope,
    facet_problem,
    feasible_force_set,
    z_extremes,
)
from plant.airframe import Airframe

AIRFRAME = "paper_hexacopter"
COMMAND = "python -m controller.polytope_defaults"
HEADER = Path(__file__).resolve().parents[1] / "fmu_src" / "controller" / "default_polytope.h"


def _numbers(values: np.ndarray, per_line: int) -> str:
    items = [f"{float(v):.17g}" for v in values.reshape(-1)]
    lines = [", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line)]
    return ",\n".join(f"    {line}" for line in lines)


def render(poly: Polytope) -> str:
    """The header text for a polytope (deterministic)."""
    m = poly.n_facets
    if m > MAX_FACETS:
        raise ValueError(f"{m} facets exceed the cap {MAX_FACETS}")
    z_lo, z_hi = poly.z_range
    return f"""\
/*
 * GENERATED FILE - do not edit.  Regenerate with:   {COMMAND}
 * Freshness: {COMMAND} --check (tests/test_force_sets.py runs the check).
 *
 * Default feasible-force polytope of the FullPoseController: S(tau = 0) (paper eq. 6) of the
 * airframe "{poly.airframe}", as the outer H-representation {{f_b : A f_b <= b}}.
 * f_b is the body force in FRD (N); rows of A are unit normals, b is in N; A is row-major,
 * FP_DEFAULT_POLYTOPE_FACETS x 3.  The guidance allocation slices it at f_bz_ref
 * (P_xy, paper eq. 22-23) or uses it jointly in (fx, fy, fz).
 * Method: controller/force_sets.py (support functions of the convexified admissible set,
 * {DEFAULT_GRID}x{DEFAULT_GRID} servo grid, Lagrange-dual outer bounds, sandwich refinement).
 * Approximation: Hausdorff gap to the inner hull {poly.gap:.3g} N \
(relative {100 * poly.relative_gap:.2g} %).
 * Volume {poly.volume:.6g} N^3; f_bz range [{z_lo:.6g}, {z_hi:.6g}] N.
 */
#ifndef FP_DEFAULT_POLYTOPE_H
#define FP_DEFAULT_POLYTOPE_H

/* Capacity of the controller's polytope parameters (facets). */
#define FP_POLYTOPE_MAX_FACETS {MAX_FACETS}

/* Facets of the default polytope (<= FP_POLYTOPE_MAX_FACETS). */
#define FP_DEFAULT_POLYTOPE_FACETS {m}

static const double fp_default_polytope_A[FP_DEFAULT_POLYTOPE_FACETS * 3] = {{
{_numbers(poly.A, 3)}
}};

static const double fp_default_polytope_b[FP_DEFAULT_POLYTOPE_FACETS] = {{
{_numbers(poly.b, 3)}
}};

/* Range of f_bz over the polytope (N): clamp f_bz_ref into it before slicing. */
static const double fp_default_polytope_fz_range[2] = {{{z_lo:.17g}, {z_hi:.17g}}};

#endif /* FP_DEFAULT_POLYTOPE_H */
"""


def compute() -> Polytope:
    return feasible_force_set(AIRFRAME)


def read_array(text: str, name: str) -> np.ndarray:
    """The numbers of the C array ``name`` in a generated header."""
    m = re.search(rf"{name}\[[^\]]*\] = \{{([^}}]*)\}}", text)
    if m is None:
        raise ValueError(f"{name} not found")
    return np.array([float(x) for x in m.group(1).replace("\n", " ").split(",") if x.strip()])


def parse(text: str) -> tuple[np.ndarray, np.ndarray]:
    """(A, b) read back from a header text (for the check and tests)."""
    A = read_array(text, "fp_default_polytope_A").reshape(-1, 3)
    return A, read_array(text, "fp_default_polytope_b")


def skeleton(text: str) -> str:
    """A generated text without its numbers: array contents dropped, other numbers as '#'."""
    text = re.sub(r"= \{[^}]*\}", "= {}", text)
    return re.sub(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", "#", text)


def _define(text: str, name: str) -> int:
    m = re.search(rf"^#define {name} (\d+)$", text, re.MULTILINE)
    if m is None:
        raise ValueError(f"{name} not found")
    return int(m.group(1))


def compare(old: str, fresh: str, airframe: Airframe | str = AIRFRAME) -> tuple[bool, str]:
    """(same, reason): a header text against a fresh rendering's template, its polytope
    against the airframe's S(0) computed now (facet by facet, whatever the normals)."""
    try:
        if skeleton(old) != skeleton(fresh):
            return False, "its text is not the generator's (template changed or file edited)"
        A0, b0 = parse(old)
        if _define(old, "FP_POLYTOPE_MAX_FACETS") != _define(fresh, "FP_POLYTOPE_MAX_FACETS"):
            return False, "FP_POLYTOPE_MAX_FACETS differs"
        if _define(old, "FP_DEFAULT_POLYTOPE_FACETS") != len(b0) or A0.shape != (len(b0), 3):
            return False, "FP_DEFAULT_POLYTOPE_FACETS does not match its arrays"
        why = facet_problem(airframe, A0, b0, np.zeros(3), what="the file's polytope")
        if why:
            return False, why
        z0 = read_array(old, "fp_default_polytope_fz_range")
        z = np.array(z_extremes(A0, b0))
        size = float(np.max(np.abs(z)))
        if z0.shape != z.shape or not np.allclose(z0, z, rtol=0.0, atol=REL_TOL * size):
            return False, f"the f_bz range {z0} is not its polytope's {z}"
    except ValueError as exc:
        return False, f"it is not in the generated format ({exc})"
    return True, f"every facet at the offset computed now ({len(b0)} facets)"


def check_header(path: Path, fresh: str, compare: Callable[[str, str], tuple[bool, str]],
                 command: str) -> tuple[bool, str]:
    """(up to date, message): a generated file against a fresh rendering, by ``compare``."""
    if not path.is_file():
        return False, f"{path} is missing: run {command}"
    ok, why = compare(path.read_text(encoding="utf-8"), fresh)
    if ok:
        return True, f"{path} is up to date ({why})"
    return False, f"{path} is stale: {why}: run {command}"


def check(path: Path = HEADER, fresh: str | None = None,
          airframe: Airframe | str = AIRFRAME) -> tuple[bool, str]:
    """(up to date, message): the file against a fresh rendering's template and the
    airframe's S(0) computed now (:func:`compare`)."""
    return check_header(path, render(compute()) if fresh is None else fresh,
                        lambda old, new: compare(old, new, airframe), COMMAND)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog=COMMAND, description="Write the controller FMU's default S(0) polytope "
        f"({AIRFRAME}) as C source, or check that the committed file is fresh.")
    parser.add_argument("--check", action="store_true",
                        help="do not write; exit 1 if the file is not a fresh computation's "
                        "polytope (compared as a set, see above)")
    parser.add_argument("--output", type=Path, default=HEADER, help=f"default: {HEADER}")
    args = parser.parse_args(argv)
    text = render(compute())
    if args.check:
        ok, message = check(args.output, text)
        print(message, file=sys.stdout if ok else sys.stderr)
        return 0 if ok else 1
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text, encoding="utf-8")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
