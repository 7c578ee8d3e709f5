"""Attitude conventions of the plant: NED world, FRD body, R = Rz(psi) Ry(theta) Rx(phi)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def euler_to_quat(phi: float, theta: float, psi: float) -> list[float]:
    """[w, x, y, z] of R = Rz(psi) Ry(theta) Rx(phi) (body FRD -> world NED)."""
    cr, sr = math.cos(phi / 2), math.sin(phi / 2)
    cp, sp = math.cos(theta / 2), math.sin(theta / 2)
    cy, sy = math.cos(psi / 2), math.sin(psi / 2)
    return [cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy]


def quat_to_euler(q: Sequence[float] | np.ndarray) -> tuple[float, float, float]:
    """(phi, theta, psi) of a unit quaternion [w, x, y, z]."""
    w, x, y, z = (float(v) for v in q)
    phi = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    theta = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    psi = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return phi, theta, psi


def rotation(phi: float, theta: float, psi: float) -> np.ndarray:
    """Body -> world rotation matrix."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return np.array([[ct * cp, sf * st * cp - cf * sp, cf * st * cp + sf * sp],
                     [ct * sp, sf * st * sp + cf * cp, cf * st * sp - sf * cp],
                     [-st, sf * ct, cf * ct]])


def body_rates_to_euler_rates(phi: float, theta: float, p: float, q: float,
                              r: float) -> tuple[float, float, float]:
    """Euler-angle rates of body rates (p, q, r) at roll phi, pitch theta."""
    cf, sf, ct, tt = math.cos(phi), math.sin(phi), math.cos(theta), math.tan(theta)
    return (p + sf * tt * q + cf * tt * r, cf * q - sf * r, (sf * q + cf * r) / ct)


def wrap_pi(a: float) -> float:
    """The angle wrapped into [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi
