"""The force sets the controller FMU derives from its airframe parameters, through the very
C code it runs (``fmu_src/controller/derive_sets.c``, via ``libfp_controller``).

At initialization the controller computes S(0) and the set after losing each rotor itself
(docs/controller.md, "Force sets from the airframe"); this module asks the same function for
the same sets, so that figures, results folders and tests see exactly what the controller
flies with.  The scipy design tool (:mod:`controller.force_sets`) is its independent oracle.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from controller.fmu_parameters import (
    FAIL_FACETS,
    POLY_FACETS,
    facets_of,
    failure_facets,
)
from controller.native import solver
from plant import Airframe

Array = NDArray[np.float64]


class DerivationError(RuntimeError):
    """The C derivation failed (a cap or an iteration limit; the message says which)."""


@dataclass(frozen=True)
class DerivedSet:
    """One polytope {f : A f <= b} (unit normals, N) and how it was found."""

    A: Array
    b: Array
    dimension: int
    """Dimension of the set's affine hull (3: full; 1: a segment, e.g. vertical rotors)."""
    lp_solves: int
    seconds: float
    """Wall time of the derivation."""


@dataclass(frozen=True)
class ControllerSets:
    """S(0) and, per rotor, the set after losing it (None: no force at zero torque)."""

    s0: DerivedSet
    failures: tuple[DerivedSet | None, ...]

    @property
    def seconds(self) -> float:
        """Time of all the derivations together."""
        return self.s0.seconds + sum(f.seconds for f in self.failures if f is not None)


def derive_force_set(airframe: Airframe, lost: tuple[int, ...] = (),
                     cap: int | None = None) -> DerivedSet | None:
    """S(0) of ``airframe`` without the rotors ``lost`` (1-based), as the controller FMU
    derives it; None when no combination of actuator states gives zero torque."""
    cap = cap if cap is not None else (POLY_FACETS if not lost else FAIL_FACETS)
    mask = 0
    for i in lost:
        if not 1 <= i <= airframe.n_rotors:
            raise ValueError(f"rotor {i} is not one of the airframe's 1..{airframe.n_rotors}")
        mask |= 1 << (i - 1)
    A = np.zeros((cap, 3))
    b = np.zeros(cap)
    info = (ctypes.c_int32 * 5)()
    ns = ctypes.c_double()
    why = ctypes.create_string_buffer(200)
    lib = solver()
    status = lib.fp_derive_force_set_api(
        airframe.rotor_set().native_buffer(), mask, cap,
        A.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
        b.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), info, ctypes.byref(ns), why, 200)
    if status != 0:
        raise DerivationError("fp_derive_force_set_api: out of memory")
    if info[0] == 1:
        return None
    if info[0] != 0:
        raise DerivationError(f"{airframe.name}: deriving the force set without rotors "
                              f"{list(lost)} failed: {why.value.decode()}")
    n = int(info[1])
    return DerivedSet(A=A[:n].copy(), b=b[:n].copy(), dimension=int(info[2]),
                      lp_solves=int(info[3]), seconds=ns.value * 1e-9)


def controller_sets(airframe: Airframe) -> ControllerSets:
    """S(0) and every single-failure set of ``airframe``, as the controller derives them."""
    return ControllerSets(
        s0=_required(derive_force_set(airframe), airframe),
        failures=tuple(derive_force_set(airframe, (i + 1,))
                       for i in range(airframe.n_rotors)))


def _required(s: DerivedSet | None, airframe: Airframe) -> DerivedSet:
    if s is None:
        raise DerivationError(f"{airframe.name}: no force at zero torque at all (S(0) is "
                              "empty): the rotors cannot balance their torques")
    return s


def flown_sets(airframe: Airframe) -> dict[str, object]:
    """The force sets a run's controller flies with, as JSON-ready data: the design-time
    sets passed for a shipped airframe's rotors (``source`` "design"), else the ones the
    controller derives itself (``source`` "derived", through the same C code):
    ``{"source", "s0": {"A", "b"}, "failures": [{"A", "b"} or None per rotor]}``."""
    from controller.polytope_cache import design_set_parameters

    params = design_set_parameters(airframe)
    if params:
        A, b = facets_of(params, "poly", 0, int(params["poly_n"]))
        return {"source": "design", "s0": {"A": A, "b": b},
                "failures": [{"A": fa, "b": fb} if fb else None
                             for fa, fb in failure_facets(params, airframe.n_rotors)]}
    sets = controller_sets(airframe)
    return {"source": "derived", "s0": {"A": sets.s0.A.tolist(), "b": sets.s0.b.tolist()},
            "failures": [None if f is None else {"A": f.A.tolist(), "b": f.b.tolist()}
                         for f in sets.failures]}
