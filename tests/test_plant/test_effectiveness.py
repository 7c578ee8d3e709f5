"""The C core's rotor kinematics and effectiveness matrices against numpy/scipy."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import plant
from plant.effectiveness import rotor_rotation, thrust_direction

AIRFRAMES = ["paper_hexacopter", "fixed_tilt_hexarotor", "quadrotor"]


def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def numpy_rotor_rotation(alpha, beta, gamma):
    # intrinsic z-x-y: Rz(gamma) Rx(alpha) Ry(beta), computed by scipy
    return Rotation.from_euler("ZXY", [gamma, alpha, beta]).as_matrix()


def numpy_B(af):
    r = af.k_d / af.k_t
    cols = []
    for d, c in zip(af.positions, af.spins, strict=True):
        cols.append(np.vstack([np.eye(3), skew(d) + r * c * np.eye(3)]))
    return np.hstack(cols)


def numpy_B_prime(af, alpha, beta):
    r = af.k_d / af.k_t
    cols = []
    for i, (d, c) in enumerate(zip(af.positions, af.spins, strict=True)):
        R = numpy_rotor_rotation(alpha[i], beta[i], af.gamma[i])
        cols.append(np.vstack([np.eye(3), skew(d) + r * c * np.eye(3)]) @ R)
    return np.hstack(cols)


@pytest.mark.parametrize("seed", range(20))
def test_rotor_rotation_matches_scipy(seed):
    rng = np.random.default_rng(seed)
    a, b, g = rng.uniform(-np.pi, np.pi, 3)
    R = rotor_rotation(a, b, g)
    np.testing.assert_allclose(R, numpy_rotor_rotation(a, b, g), atol=1e-14)
    # thrust along the rotor's -z axis
    np.testing.assert_allclose(thrust_direction(a, b, g), -R[:, 2], atol=1e-14)


def test_zero_tilt_thrust_points_up_in_frd():
    np.testing.assert_allclose(thrust_direction(0.0, 0.0, 1.234), [0, 0, -1], atol=1e-15)
    # positive alpha tilts the thrust towards the mounted +y axis (rotation about x)
    t = thrust_direction(0.3, 0.0, 0.0)
    assert t[1] > 0 and t[2] < 0 and abs(t[0]) < 1e-15


@pytest.mark.parametrize("name", AIRFRAMES)
def test_B_matches_numpy(name):
    af = plant.load_airframe(name)
    rs = af.rotor_set()
    np.testing.assert_allclose(rs.B(), numpy_B(af), atol=1e-15)
    np.testing.assert_allclose(rs.B1(), numpy_B(af)[:3], atol=1e-15)
    np.testing.assert_allclose(rs.B2(), numpy_B(af)[3:], atol=1e-15)


@pytest.mark.parametrize("name", AIRFRAMES)
@pytest.mark.parametrize("seed", range(5))
def test_B_prime_and_wrench_match_numpy(name, seed):
    af = plant.load_airframe(name)
    rs = af.rotor_set()
    rng = np.random.default_rng(seed)
    n = af.n_rotors
    alpha = rng.uniform(-0.7, 0.7, n)
    beta = rng.uniform(-0.7, 0.7, n)
    omega = rng.uniform(50, 200, n)
    Bp = rs.B_prime(alpha, beta)
    np.testing.assert_allclose(Bp, numpy_B_prime(af, alpha, beta), atol=1e-14)
    # eq. (11) with F_i = [0, 0, -k_t omega_i^2] (thrust along -z_M)
    F = np.concatenate([[0.0, 0.0, -af.k_t * w**2] for w in omega])
    f_b, tau_b = rs.wrench(alpha, beta, omega)
    np.testing.assert_allclose(np.concatenate([f_b, tau_b]), Bp @ F, rtol=1e-12, atol=1e-14)
    # and B (eq. 3) applied to the per-rotor body forces gives the same wrench
    u = np.concatenate([af.k_t * w**2 * thrust_direction(a, b, g)
                        for a, b, g, w in zip(alpha, beta, af.gamma, omega, strict=True)])
    np.testing.assert_allclose(rs.B() @ u, Bp @ F, rtol=1e-12, atol=1e-14)


def test_efficiency_scales_one_rotor():
    af = plant.load_airframe("paper_hexacopter")
    rs = af.rotor_set()
    zero = np.zeros(6)
    omega = np.full(6, 100.0)
    eff = np.ones(6)
    eff[2] = 0.25
    f_full, _ = rs.wrench(zero, zero, omega)
    f_eff, _ = rs.wrench(zero, zero, omega, eff)
    assert f_eff[2] - f_full[2] == pytest.approx(0.75 * af.k_t * 100.0**2, rel=1e-12)


@pytest.mark.parametrize("name", AIRFRAMES)
def test_hover_trim_reproduces_weight(name):
    af = plant.load_airframe(name)
    alpha, beta, omega = af.hover_trim()
    Bp = numpy_B_prime(af, alpha, beta)
    F = np.concatenate([[0.0, 0.0, -af.k_t * w**2] for w in omega])
    np.testing.assert_allclose(Bp @ F, [0, 0, -af.mass * af.gravity, 0, 0, 0], atol=1e-9)
    assert np.all(omega <= af.omega_max)


def test_tilted_hover_trim_uses_servos():
    af = plant.load_airframe("paper_hexacopter")
    euler = np.array([0.3, -0.2, 0.5])
    alpha, beta, omega = af.hover_trim(euler)
    R = Rotation.from_euler("ZYX", euler[::-1]).as_matrix()  # Rz(psi) Ry(theta) Rx(phi)
    f_b = R.T @ np.array([0.0, 0.0, -af.mass * af.gravity])
    Bp = numpy_B_prime(af, alpha, beta)
    F = np.concatenate([[0.0, 0.0, -af.k_t * w**2] for w in omega])
    np.testing.assert_allclose(Bp @ F, np.concatenate([f_b, np.zeros(3)]), atol=1e-9)
    assert np.abs(alpha).max() > 0.1


def test_infeasible_trim_is_reported():
    quad = plant.load_airframe("quadrotor")
    with pytest.raises(ValueError, match="cannot produce"):
        quad.hover_trim([0.3, 0.0, 0.0])
