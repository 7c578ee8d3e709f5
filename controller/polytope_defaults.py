"""Generate the controller FMU's default feasible-force polytope as C source.

    python -m controller.polytope_defaults          # (re)writes the header below
    python -m controller.polytope_defaults --check  # exit 1 if the file on disk is stale

The header is fmu_src/controller/default_polytope.h.

The polytope is S(tau = 0) of the paper hexacopter (paper eq. 6), computed by
:func:`controller.force_sets.feasible_force_set` with its defaults, written as an
H-representation {f_b : A f_b <= b} (body FRD, N; rows of A are unit normals).  Numbers are
printed with "%.17g", so a regenerated file is byte-identical to the committed one as long as
the computation is (same platform and library versions; the computation itself is
deterministic).  ``--check`` compares bytes and, when they differ, also says whether only
floating-point noise (relative 1e-9) or the polytope itself changed.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from controller.force_sets import DEFAULT_GRID, MAX_FACETS, Polytope, feasible_force_set

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


def parse(text: str) -> tuple[np.ndarray, np.ndarray]:
    """(A, b) read back from a header text (for diagnostics and tests)."""
    def block(name: str) -> np.ndarray:
        m = re.search(rf"{name}\[[^\]]*\] = \{{([^}}]*)\}}", text)
        if m is None:
            raise ValueError(f"{name} not found")
        return np.array([float(x) for x in m.group(1).replace("\n", " ").split(",") if x.strip()])

    return block("fp_default_polytope_A").reshape(-1, 3), block("fp_default_polytope_b")


def check(path: Path = HEADER, fresh: str | None = None) -> tuple[bool, str]:
    """(up to date, message): compares the file with a fresh computation byte for byte."""
    text = render(compute()) if fresh is None else fresh
    if not path.is_file():
        return False, f"{path} is missing: run {COMMAND}"
    old = path.read_text(encoding="utf-8")
    if old == text:
        return True, f"{path} is up to date"
    why = "the polytope changed"
    try:
        (A0, b0), (A1, b1) = parse(old), parse(text)
        if A0.shape == A1.shape and np.allclose(A0, A1, rtol=1e-9, atol=1e-12) and \
                np.allclose(b0, b1, rtol=1e-9, atol=1e-9):
            why = "numbers differ only by floating-point noise (platform or library versions)"
    except ValueError:
        why = "the file is not in the generated format"
    return False, f"{path} is stale ({why}): run {COMMAND}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog=COMMAND, description="Write the controller FMU's default S(0) polytope "
        f"({AIRFRAME}) as C source, or check that the committed file is fresh.")
    parser.add_argument("--check", action="store_true",
                        help="do not write; exit 1 if the file differs from a fresh computation")
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
