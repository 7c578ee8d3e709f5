"""Rotor failures: the airframe without a rotor, and S(0) for each single-rotor loss.

The controller FMU takes, for every rotor i, the feasible force set of the vehicle
that has lost rotor i (``fail_poly_*`` parameters, at most ``FAIL_FACETS`` facets
each) and switches to it when its ``rotor_health[i]`` input says the rotor is lost.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

import numpy as np

from controller.force_sets import EmptyForceSetError, Polytope, feasible_force_set
from plant import Airframe

FAIL_FACETS = 32
"""Facet cap of each single-failure polytope (the FMU's fail_poly_A holds 8 x 32 rows)."""

MAX_ROTORS = 8


def airframe_without(af: Airframe, lost: Iterable[int]) -> Airframe:
    """The airframe with rotors ``lost`` (0-based) removed: a lost rotor gives no force."""
    drop = set(lost)
    keep = [k for k in range(af.n_rotors) if k not in drop]
    if not keep:
        raise ValueError("an airframe needs at least one rotor")
    return dataclasses.replace(
        af, name=f"{af.name} without rotor(s) {sorted(i + 1 for i in drop)}",
        positions=af.positions[keep], spins=af.spins[keep], gamma=af.gamma[keep],
        alpha_limits=af.alpha_limits[keep], beta_limits=af.beta_limits[keep])


def failure_polytopes(af: Airframe, n_directions: int = FAIL_FACETS) -> list[Polytope | None]:
    """S(0) of the airframe after losing rotor i, for each rotor (None: the set is empty)."""
    out: list[Polytope | None] = []
    for i in range(af.n_rotors):
        try:
            out.append(feasible_force_set(airframe_without(af, [i]), n_directions=n_directions))
        except EmptyForceSetError:
            out.append(None)
    return out


def failure_parameters(af: Airframe) -> dict[str, float | int]:
    """Controller FMU parameter values (fail_poly_n, fail_poly_A, fail_poly_b) for ``af``."""
    params: dict[str, float | int] = {}
    for i, poly in enumerate(failure_polytopes(af)):
        n = 0 if poly is None else len(poly.b)
        params[f"fail_poly_n[{i + 1}]"] = n
        for k in range(n):
            row = i * FAIL_FACETS + k + 1
            assert poly is not None
            for j in range(3):
                params[f"fail_poly_A[{row},{j + 1}]"] = float(poly.A[k, j])
            params[f"fail_poly_b[{row}]"] = float(poly.b[k])
    for i in range(af.n_rotors, MAX_ROTORS):
        params[f"fail_poly_n[{i + 1}]"] = 0
    return params


def hover_possible(poly: Polytope | None, af: Airframe) -> bool:
    return poly is not None and bool(poly.contains(np.array([0.0, 0.0, -af.mass * af.gravity])))
