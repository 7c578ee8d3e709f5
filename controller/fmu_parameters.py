"""Design results as controller FMU parameters: the one conversion of each kind.

The design tools produce polytopes (``controller.force_sets``, ``controller.failures``) and
first-order blocks (``controller.hinf``, ``controller.baseline``); the controller FMU takes
them as flat, 1-based variables (``poly_A[i,j]``, ``fail_poly_b[row]``, ``K_pos_D[axis]``).
Every road to the FMU (scenario runs, live sessions, sweeps, the SSP export, the generated C
defaults) converts through these functions, so the variable layout is written once.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from controller.polytope import Polytope

Parameters = dict[str, float | int]

MAX_ROTORS = 8
"""Rotor slots of both FMUs (their per-rotor vectors have 8 elements)."""
POLY_FACETS = 64
"""Facet cap of S(0) (the FMU's ``poly_A`` has 64 rows)."""
FAIL_FACETS = 32
"""Facet cap of each single-failure polytope (``fail_poly_A`` holds 8 x 32 rows)."""
SAT_FLAG_SHIFT = {"motor": 0, "alpha": 8, "beta": 16}
"""Bit of rotor 1 in the ``sat_flags`` output per actuator kind (rotor i: shift + i - 1)."""
LOOPS = ("pos", "vel", "att", "rate")
"""The four blocks of the cascade, in the FMU's names ``K_<loop>_<A|B|C|D>[axis]``."""


def _facets(params: Parameters, prefix: str, poly: Polytope, first_row: int) -> None:
    for k in range(len(poly.b)):
        row = first_row + k + 1
        for j in range(3):
            params[f"{prefix}_A[{row},{j + 1}]"] = float(poly.A[k, j])
        params[f"{prefix}_b[{row}]"] = float(poly.b[k])


def s0_parameters(poly: Polytope) -> Parameters:
    """``poly_n``, ``poly_A[i,j]``, ``poly_b[i]``: S(0) for the controller."""
    if len(poly.b) > POLY_FACETS:
        raise ValueError(f"S(0) has {len(poly.b)} facets; the controller FMU holds "
                         f"{POLY_FACETS}")
    params: Parameters = {"poly_n": len(poly.b)}
    _facets(params, "poly", poly, 0)
    return params


def failure_parameters(polys: Sequence[Polytope | None]) -> Parameters:
    """``fail_poly_n``, ``fail_poly_A``, ``fail_poly_b``: S(0) after losing rotor i, for each
    rotor (None: the set is empty); the slots of absent rotors are empty too."""
    if len(polys) > MAX_ROTORS:
        raise ValueError(f"{len(polys)} rotors; the controller FMU has {MAX_ROTORS} slots")
    params: Parameters = {}
    for i, poly in enumerate(polys):
        n = 0 if poly is None else len(poly.b)
        if n > FAIL_FACETS:
            raise ValueError(f"the set without rotor {i + 1} has {n} facets; the controller "
                             f"FMU holds {FAIL_FACETS} per rotor")
        params[f"fail_poly_n[{i + 1}]"] = n
        if poly is not None:
            _facets(params, "fail_poly", poly, i * FAIL_FACETS)
    for i in range(len(polys), MAX_ROTORS):
        params[f"fail_poly_n[{i + 1}]"] = 0
    return params


def facets_of(params: Mapping[str, float | int], prefix: str, first_row: int,
              n: int) -> tuple[list[list[float]], list[float]]:
    """(A, b) of the n facets from row first_row + 1 on of the ``PREFIX_A``, ``PREFIX_b``
    parameters: the inverse of :func:`s0_parameters` (prefix ``poly``, first_row 0) and
    :func:`failure_parameters` (``fail_poly``, rotor i's rows from i * FAIL_FACETS)."""
    rows = range(first_row + 1, first_row + n + 1)
    return ([[float(params[f"{prefix}_A[{r},{j}]"]) for j in (1, 2, 3)] for r in rows],
            [float(params[f"{prefix}_b[{r}]"]) for r in rows])


def failure_facets(params: Mapping[str, float | int],
                   n_rotors: int) -> list[tuple[list[list[float]], list[float]]]:
    """(A, b) of each rotor's failure set in the ``fail_poly_*`` parameters (no rows: a
    loss without a set)."""
    return [facets_of(params, "fail_poly", i * FAIL_FACETS, int(params[f"fail_poly_n[{i + 1}]"]))
            for i in range(n_rotors)]


def block_parameters(blocks: Mapping[str, Sequence[float]]) -> dict[str, float]:
    """``K_<loop>_<A|B|C|D>[axis]`` for blocks given as ``{loop: (A, B, C, D)}``, the same
    block on all three axes."""
    unknown = sorted(set(blocks) - set(LOOPS))
    if unknown:
        raise ValueError(f"unknown loop(s) {unknown}; the controller's are {', '.join(LOOPS)}")
    out: dict[str, float] = {}
    for loop, values in blocks.items():
        for name, v in zip("ABCD", values, strict=True):
            for i in range(3):
                out[f"K_{loop}_{name}[{i + 1}]"] = float(v)
    return out
