"""Generate the controller FMU's default single-rotor-failure polytopes as C source.

    python -m controller.failure_defaults          # (re)writes the header below
    python -m controller.failure_defaults --check  # exit 1 if the file on disk is stale

The header is fmu_src/controller/default_fail_polytopes.h: for the paper hexacopter and
each rotor i, S(tau = 0) of the vehicle without rotor i (controller.failures), at most
FAIL_FACETS facets each, numbers printed with "%.17g" (deterministic computation).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from controller.failures import FAIL_FACETS, MAX_ROTORS, failure_polytopes, hover_possible
from plant import load_airframe

AIRFRAME = "paper_hexacopter"
COMMAND = "python -m controller.failure_defaults"
HEADER = (Path(__file__).resolve().parents[1] / "fmu_src" / "controller"
          / "default_fail_polytopes.h")


def _numbers(values: np.ndarray) -> str:
    return ",\n".join(f"    {float(v):.17g}" for v in values.reshape(-1))


def render() -> str:
    af = load_airframe(AIRFRAME)
    polys = failure_polytopes(af)
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
 * Freshness: {COMMAND} --check (tests/test_failures.py runs the check).
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the header is stale")
    parser.add_argument("--output", type=Path, default=HEADER, help=f"default: {HEADER}")
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        current = args.output.read_text() if args.output.is_file() else ""
        if current != text:
            print(f"{args.output} is stale: run {COMMAND}", file=sys.stderr)
            return 1
        print(f"{args.output} is fresh")
        return 0
    args.output.write_text(text)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
