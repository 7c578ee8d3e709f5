"""Rotor failures: the airframe without a rotor, and S(0) for each single-rotor loss.

The controller FMU takes, for every rotor i, the feasible force set of the vehicle
that has lost rotor i (``fail_poly_*`` parameters, at most ``FAIL_FACETS`` facets
each) and switches to it when its ``rotor_health[i]`` input says the rotor is lost.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

import numpy as np

from controller.fmu_parameters import FAIL_FACETS
from controller.force_sets import feasible_force_set
from controller.polytope import EmptyForceSetError, Polytope
from plant import Airframe


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


def hover_possible(poly: Polytope | None, af: Airframe) -> bool:
    """Whether the hover force of af lies in poly (None: no set, no hover)."""
    return poly is not None and bool(poly.contains(np.array([0.0, 0.0, -af.mass * af.gravity])))
