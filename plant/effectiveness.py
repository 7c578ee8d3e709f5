"""Effectiveness matrices and rotor kinematics, computed by the C core.

Thin numpy wrappers over ``libfp_multirotor`` (the same code the FMUs run):
nothing here re-implements the model.  Conventions are those of
``fmu_src/common/multirotor.h``: R_Mi^B = Rz(gamma) Rx(alpha) Ry(beta), thrust
along the rotor's -z axis, reaction torque c_i k_d omega^2 along the thrust.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from plant.native import multirotor

Array = NDArray[np.float64]


def _dp(a: NDArray[np.float64]) -> ctypes._Pointer[ctypes.c_double]:
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def _vec(values: object, n: int, name: str) -> Array:
    a = np.ascontiguousarray(np.asarray(values, dtype=np.float64).reshape(-1))
    if a.size != n:
        raise ValueError(f"{name} must have {n} elements, got {a.size}")
    return a


@dataclass(frozen=True)
class RotorSet:
    """Geometry and limits of n rotors (SI units, radians)."""

    k_t: float
    k_d: float
    positions: Array  # (n, 3) body FRD
    spins: NDArray[np.int32]  # (n,) +-1
    gamma: Array  # (n,)
    alpha_limits: Array  # (n, 2)
    beta_limits: Array  # (n, 2)
    omega_limits: tuple[float, float]
    native: bytes = field(repr=False, compare=False)
    """The C core's ``FpRotorSet`` of these rotors (``plant.Airframe.rotor_set``)."""

    @property
    def n(self) -> int:
        """Number of rotors."""
        return int(self.positions.shape[0])

    def native_buffer(self) -> ctypes.Array[ctypes.c_char]:
        """The rotor set as the C core's ``FpRotorSet`` (made from the airframe's
        ``FpAirframe`` by ``fp_rotor_set_from_airframe``), for the host libraries."""
        return ctypes.create_string_buffer(self.native, len(self.native))

    def _buffer(self) -> ctypes.Array[ctypes.c_char]:
        return self.native_buffer()

    def B(self) -> Array:
        """Paper eq. (3): 6 x 3n map from per-rotor body forces to [f_b; tau_b]."""
        out = np.zeros((6, 3 * self.n))
        if multirotor().fp_effectiveness_b_api(self._buffer(), _dp(out)) != 0:
            raise ValueError("effectiveness B failed")
        return out

    def B1(self) -> Array:
        """The force rows of B (3 x 3n)."""
        return self.B()[:3]

    def B2(self) -> Array:
        """The torque rows of B (3 x 3n)."""
        return self.B()[3:]

    def B_prime(self, alpha: object, beta: object) -> Array:
        """Paper eq. (9)-(10): B'(lambda), 6 x 3n, with F_i = [0, 0, -k_t omega_i^2]."""
        a = _vec(alpha, self.n, "alpha")
        b = _vec(beta, self.n, "beta")
        out = np.zeros((6, 3 * self.n))
        if multirotor().fp_effectiveness_bprime_api(self._buffer(), _dp(a), _dp(b), _dp(out)) != 0:
            raise ValueError("effectiveness B' failed")
        return out

    def B_second(self, alpha: object, beta: object, omega: object) -> Array:
        """Paper eq. (12)-(13): B''(u_a) = d(B'(lambda) F(omega))/du_a, 6 x 3n.

        Columns are ordered [alpha_1, beta_1, omega_1, ..., alpha_n, beta_n, omega_n].
        """
        a, b, w = (_vec(x, self.n, nm) for x, nm in ((alpha, "alpha"), (beta, "beta"),
                                                     (omega, "omega")))
        out = np.zeros((6, 3 * self.n))
        if multirotor().fp_effectiveness_b2prime_api(self._buffer(), _dp(a), _dp(b), _dp(w),
                                               _dp(out)) != 0:
            raise ValueError("effectiveness B'' failed")
        return out

    def wrench(
        self, alpha: object, beta: object, omega: object, efficiency: object = None
    ) -> tuple[Array, Array]:
        """Body force and torque of the rotors at the given actuator state."""
        a, b, w = (_vec(x, self.n, nm) for x, nm in ((alpha, "alpha"), (beta, "beta"),
                                                     (omega, "omega")))
        eff = None if efficiency is None else _vec(efficiency, self.n, "efficiency")
        f = np.zeros(3)
        t = np.zeros(3)
        multirotor().fp_rotor_wrench_api(self._buffer(), _dp(a), _dp(b), _dp(w),
                                   None if eff is None else _dp(eff), _dp(f), _dp(t))
        return f, t

    def preferred_config(self, wrench: object) -> tuple[Array, Array, Array]:
        """Minimum-norm per-rotor split of a body wrench as (alpha, beta, omega).

        Raises ValueError naming the rotor and limit when the split is not feasible.
        """
        w = _vec(wrench, 6, "wrench")
        a, b, o = np.zeros(self.n), np.zeros(self.n), np.zeros(self.n)
        why = ctypes.create_string_buffer(256)
        status = multirotor().fp_preferred_config_api(self._buffer(), _dp(w), _dp(a), _dp(b),
                                                      _dp(o), why, len(why))
        if status != 0:
            raise ValueError(why.value.decode())
        return a, b, o


def rotor_rotation(alpha: float, beta: float, gamma: float) -> Array:
    """R_Mi^B(alpha, beta, gamma) = Rz(gamma) Rx(alpha) Ry(beta)."""
    out = np.zeros(9)
    multirotor().fp_rotor_rotation_api(alpha, beta, gamma, _dp(out))
    return out.reshape(3, 3)


def thrust_direction(alpha: float, beta: float, gamma: float) -> Array:
    """Unit thrust direction of a rotor in the body frame (-R_Mi^B e_z)."""
    out = np.zeros(3)
    multirotor().fp_thrust_direction_api(alpha, beta, gamma, _dp(out))
    return out
