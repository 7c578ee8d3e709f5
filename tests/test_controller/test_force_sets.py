"""Attainable and feasible force sets (controller/force_sets.py) against independent oracles.

Oracles used here, none of which goes through controller.force_sets:
- real actuator states (alpha, beta, omega) evaluated by the C core's B'(lambda) and its
  rotor-wrench function (a different entry point than the B / thrust-direction pair the
  polytope is built from), with zero torque obtained by a small LP on the thrusts;
- nonlinear maximisation (SLSQP) over real actuator states with the torque as an equality;
- linear programs written here over a sampled actuator model (9 x 9 servo grid).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog, minimize
from scipy.spatial import ConvexHull

import plant
from controller.force_sets import (
    MAX_FACETS,
    attainable_force_set,
    feasible_force_set,
    hover_force,
    is_feasible,
)
from controller.plots_force_sets import plot_force_sets
from controller.polytope import EmptyForceSetError, canonical_facets, same_polytope
from plant.effectiveness import thrust_direction

AIRFRAMES = ["paper_hexacopter", "fixed_tilt_hexarotor", "quadrotor"]
ROOT = Path(__file__).resolve().parents[2]
# the header in this checkout (the installed package has no fmu_src/)

_CACHE: dict[tuple[str, str], object] = {}


def s0_of(name):
    key = (name, "S0")
    if key not in _CACHE:
        _CACHE[key] = feasible_force_set(name)
    return _CACHE[key]


def afs_of(name):
    key = (name, "AFS")
    if key not in _CACHE:
        _CACHE[key] = attainable_force_set(name)
    return _CACHE[key]


def fibonacci(n):
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5.0**0.5) * k
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


# ---------------------------------------------------------------------------
# Independent oracles


def unit_wrenches(af, alpha, beta):
    """6 x n: body wrench per newton of thrust of each rotor at the given tilts (C: B')."""
    bp = af.rotor_set().B_prime(alpha, beta)
    return -bp[:, 2::3]  # F_i = [0, 0, -T]


def random_states(af, rng, count, torque=(0.0, 0.0, 0.0)):
    """Real actuator states with the given body torque: random tilts, LP on the thrusts."""
    n = af.n_rotors
    t_min, t_max = af.k_t * af.omega_min**2, af.k_t * af.omega_max**2
    states = []
    while len(states) < count:
        alpha = rng.uniform(af.alpha_limits[:, 0], af.alpha_limits[:, 1])
        beta = rng.uniform(af.beta_limits[:, 0], af.beta_limits[:, 1])
        w = unit_wrenches(af, alpha, beta)
        res = linprog(-rng.uniform(-0.3, 1.0, n), A_eq=w[3:], b_eq=torque,
                      bounds=[(t_min, t_max)] * n, method="highs")
        if res.status != 0:
            continue
        thrust = np.clip(res.x, t_min, t_max)
        omega = np.sqrt(thrust / af.k_t)
        states.append((alpha, beta, omega))
    return states


def sampled_model(af, grid=9):
    """LP data of the sampled actuator model: per generator force, torque, rotor index."""
    t_max = af.k_t * af.omega_max**2
    B = af.rotor_set().B()
    cols, owner = [], []
    for i in range(af.n_rotors):
        ga = np.unique(np.linspace(*af.alpha_limits[i], grid))
        gb = np.unique(np.linspace(*af.beta_limits[i], grid))
        for a in ga:
            for b in gb:
                u = np.zeros(3 * af.n_rotors)
                u[3 * i:3 * i + 3] = t_max * thrust_direction(a, b, af.gamma[i])
                cols.append(B @ u)
                owner.append(i)
    W = np.array(cols).T
    S = np.zeros((af.n_rotors, W.shape[1]))
    S[owner, np.arange(W.shape[1])] = 1.0
    return W[:3], W[3:], S


def lp_support(F, M, S, c, torque=True, fz=None):
    """max c . f over the sampled model (optionally with zero torque and fixed f_z)."""
    A_eq, b_eq = [], []
    if torque:
        A_eq.append(M)
        b_eq.append(np.zeros(3))
    if fz is not None:
        A_eq.append(F[2:3])
        b_eq.append([fz])
    kw = {"A_eq": np.vstack(A_eq), "b_eq": np.concatenate(b_eq)} if A_eq else {}
    res = linprog(-(c @ F), A_ub=S, b_ub=np.ones(S.shape[0]), bounds=(0, None),
                  method="highs", **kw)
    assert res.status == 0, res.message
    return -res.fun, F @ res.x


def nonlinear_max(af, c, alpha0, beta0, thrust0, fz=None):
    """max c . f_b over real actuator states with zero torque (and optionally f_bz), SLSQP."""
    n = af.n_rotors
    rs = af.rotor_set()
    t_max = af.k_t * af.omega_max**2

    def wrench(x):
        a, b, t = x[:n], x[n:2 * n], x[2 * n:]
        return rs.wrench(a, b, np.sqrt(np.maximum(t, 0.0) / af.k_t))

    cons = [{"type": "eq", "fun": lambda x: wrench(x)[1]}]
    if fz is not None:
        cons.append({"type": "eq", "fun": lambda x: wrench(x)[0][2:] - fz})
    bounds = list(af.alpha_limits) + list(af.beta_limits) + [(0.0, t_max)] * n
    x0 = np.concatenate([alpha0, beta0, thrust0])
    res = minimize(lambda x: -float(c @ wrench(x)[0]), x0, method="SLSQP", bounds=bounds,
                   constraints=cons, options={"maxiter": 300, "ftol": 1e-12})
    f, tau = wrench(np.clip(res.x, [b[0] for b in bounds], [b[1] for b in bounds]))
    return f, tau


# ---------------------------------------------------------------------------
# (1) real actuator states with zero torque lie inside; hover is feasible


@pytest.mark.parametrize("name", AIRFRAMES)
def test_real_zero_torque_states_are_inside_s0(name):
    af = plant.load_airframe(name)
    s0 = s0_of(name)
    rs = af.rotor_set()
    rng = np.random.default_rng(7)
    for alpha, beta, omega in random_states(af, rng, 60):
        f, tau = rs.wrench(alpha, beta, omega)
        assert np.max(np.abs(tau)) <= 1e-9 * s0.scale
        assert s0.violation(f) <= 1e-9 * s0.scale, (f, s0.violation(f))


@pytest.mark.parametrize("name", AIRFRAMES)
def test_real_states_are_inside_afs(name):
    af = plant.load_airframe(name)
    afs = afs_of(name)
    rs = af.rotor_set()
    rng = np.random.default_rng(11)
    for _ in range(200):
        alpha = rng.uniform(af.alpha_limits[:, 0], af.alpha_limits[:, 1])
        beta = rng.uniform(af.beta_limits[:, 0], af.beta_limits[:, 1])
        # thrusts biased towards the limits, where the boundary is
        omega = af.omega_max * np.sqrt(rng.beta(0.5, 0.5, af.n_rotors))
        f, _ = rs.wrench(alpha, beta, omega)
        assert afs.contains(f), (f, afs.violation(f))


@pytest.mark.parametrize("name", AIRFRAMES)
def test_hover_force_is_inside(name):
    h = hover_force(name)
    assert s0_of(name).contains(h)
    assert afs_of(name).contains(h)
    assert is_feasible(s0_of(name), h)
    af = plant.load_airframe(name)
    assert np.allclose(h, [0.0, 0.0, -af.mass * af.gravity])


def test_facets_are_not_beaten_by_nonlinear_maximisation():
    """Per facet, SLSQP over real zero-torque actuator states stays below b (outer bound),
    and gets close to it (the bound is tight: the relaxation is exact for this airframe)."""
    name = "paper_hexacopter"
    af = plant.load_airframe(name)
    s0 = s0_of(name)
    a0, b0, w0 = af.hover_trim()
    t0 = af.k_t * w0**2
    slack = []
    for c, b in zip(s0.A, s0.b, strict=True):
        f, tau = nonlinear_max(af, c, a0, b0, t0)
        if np.max(np.abs(tau)) > 1e-7:
            continue  # SLSQP did not converge to a zero-torque state: no information
        assert c @ f <= b + 1e-6 * s0.scale, (c, c @ f, b)
        slack.append(b - c @ f)
    assert len(slack) >= 0.8 * s0.n_facets
    # local maximisation from hover finds the facet value for most facets
    assert np.median(slack) <= 1e-3 * s0.scale


# ---------------------------------------------------------------------------
# (2) AFS and S(0) of the paper hexacopter coincide


def test_afs_coincides_with_s0_for_paper_hexacopter():
    """Paper section IV: the AFS 'almost coincides' with S(0).  In the convex relaxation they
    are equal: rotors i and i+3 sit at opposite positions with identical admissible sets and
    opposite spins, so replacing both forces by their mean keeps f_b and cancels their torque.
    Measured with LPs written here: support functions agree to ~1e-10 of the force scale."""
    af = plant.load_airframe("paper_hexacopter")
    F, M, S = sampled_model(af)
    scale = 6 * af.k_t * af.omega_max**2
    dirs = fibonacci(150)
    h_s0, p_s0, h_afs, p_afs = [], [], [], []
    for c in dirs:
        v, p = lp_support(F, M, S, c, torque=True)
        h_s0.append(v)
        p_s0.append(p)
        v, p = lp_support(F, M, S, c, torque=False)
        h_afs.append(v)
        p_afs.append(p)
    diff = np.array(h_afs) - np.array(h_s0)
    assert diff.min() >= -1e-7 * scale  # S(0) inside the AFS
    assert diff.max() <= 1e-6 * scale
    ratio = ConvexHull(p_s0).volume / ConvexHull(p_afs).volume
    assert ratio >= 1.0 - 1e-5

    # the polytopes agree with that: each one's attainable points lie in the other's outer
    # H-representation, and their volumes (different facet sets) agree within 3 %
    s0, afs = s0_of("paper_hexacopter"), afs_of("paper_hexacopter")
    assert np.all(afs.contains(s0.inner_points))
    assert np.all(s0.contains(afs.inner_points, tol=1e-7 * s0.scale))
    assert abs(s0.volume / afs.volume - 1.0) <= 0.03
    for p in (s0, afs):
        assert p.inner_volume / p.volume >= 0.85


def test_nonzero_torque_set_is_smaller_and_sound():
    name = "paper_hexacopter"
    af = plant.load_airframe(name)
    tau = np.array([0.3, -0.2, 0.05])
    st = feasible_force_set(name, torque=tau)
    afs = afs_of(name)
    assert st.volume < afs.volume
    assert np.all(afs.contains(st.inner_points))
    rs = af.rotor_set()
    for alpha, beta, omega in random_states(af, np.random.default_rng(3), 30, tau):
        f, t = rs.wrench(alpha, beta, omega)
        assert np.allclose(t, tau, atol=1e-9)
        assert st.contains(f), st.violation(f)
    with pytest.raises(EmptyForceSetError):
        feasible_force_set(name, torque=[100.0, 0.0, 0.0])


# ---------------------------------------------------------------------------
# (3) bounded, non-empty, within the facet cap


@pytest.mark.parametrize("name", AIRFRAMES)
@pytest.mark.parametrize("which", ["AFS", "S0"])
def test_polytope_is_valid(name, which):
    p = afs_of(name) if which == "AFS" else s0_of(name)
    assert 4 <= p.n_facets <= MAX_FACETS
    assert p.A.shape == (p.n_facets, 3) and p.b.shape == (p.n_facets,)
    assert np.all(np.isfinite(p.A)) and np.all(np.isfinite(p.b))
    np.testing.assert_allclose(np.linalg.norm(p.A, axis=1), 1.0, rtol=0, atol=1e-12)
    assert not p.A.flags.writeable and not p.b.flags.writeable
    # bounded and non-empty: every axis LP over the H-representation is finite
    for c in np.vstack([np.eye(3), -np.eye(3)]):
        res = linprog(-c, A_ub=p.A, b_ub=p.b, bounds=(None, None), method="highs")
        assert res.status == 0, res.message
        assert abs(res.fun) <= 2.0 * p.scale
    assert np.all(p.contains(p.vertices, tol=1e-7 * p.scale))
    assert np.all(p.contains(p.inner_points))
    assert p.z_range[0] < -5.0 and p.z_range[1] <= 1e-9
    assert 0.0 <= p.gap <= 0.15 * p.scale


def test_dimensions():
    assert s0_of("paper_hexacopter").dimension == 3
    assert s0_of("fixed_tilt_hexarotor").dimension == 3
    assert s0_of("quadrotor").dimension == 1
    assert afs_of("quadrotor").dimension == 1


def test_fixed_tilt_sets_are_exact():
    """Fixed rotors have no sampling: AFS is a zonotope (a parallelepiped here, rotors i and
    i+3 pointing the same way) and the approximation is exact."""
    for p in (afs_of("fixed_tilt_hexarotor"), s0_of("fixed_tilt_hexarotor")):
        assert p.gap <= 1e-9 * p.scale
        assert p.n_facets == 6


# ---------------------------------------------------------------------------
# (4) deterministic


def test_deterministic_bit_identical():
    a = feasible_force_set("paper_hexacopter")
    b = s0_of("paper_hexacopter")
    assert a.A.tobytes() == b.A.tobytes()
    assert a.b.tobytes() == b.b.tobytes()
    assert a.vertices.tobytes() == b.vertices.tobytes()
    q1, q2 = attainable_force_set("quadrotor"), afs_of("quadrotor")
    assert q1.A.tobytes() == q2.A.tobytes() and q1.b.tobytes() == q2.b.tobytes()


# ---------------------------------------------------------------------------
# (5b) canonical facet order, and polytopes compared as sets


def _rounded_key(A, b):
    """The documented order, written out independently: unit normal to 9 decimals, offset."""
    return [(*(round(float(x), 9) + 0.0 for x in a / np.linalg.norm(a)), float(c))
            for a, c in zip(A, b, strict=True)]


def _shuffled(A, b, rng, rel=1e-12):
    """The same facets permuted, each row (a_i, b_i) scaled by a positive factor and moved by
    relative round-off ``rel`` (what another library version may produce)."""
    perm = rng.permutation(len(b))
    k = rng.uniform(0.5, 2.0, len(b))[:, None]
    A2 = k * A[perm] * (1.0 + rel * rng.standard_normal(A.shape))
    b2 = k[:, 0] * b[perm] * (1.0 + rel * rng.standard_normal(len(b)))
    return A2, b2


@pytest.mark.parametrize("name", AIRFRAMES)
def test_facets_come_in_canonical_order(name):
    p = s0_of(name)
    key = _rounded_key(p.A[p.n_flat:], p.b[p.n_flat:])
    assert key == sorted(key)
    flat = _rounded_key(p.A[:p.n_flat], p.b[:p.n_flat])
    assert all(flat[j] >= flat[j + 1] for j in range(0, p.n_flat, 2))  # larger normal first
    # round-off and a permutation of the input do not change the order
    rng = np.random.default_rng(7)
    A2, b2 = _shuffled(p.A[p.n_flat:], p.b[p.n_flat:], rng)
    norms = np.linalg.norm(A2, axis=1)
    A3, b3 = canonical_facets(A2 / norms[:, None], b2 / norms)
    np.testing.assert_allclose(A3, p.A[p.n_flat:], rtol=0, atol=1e-11)
    np.testing.assert_allclose(b3, p.b[p.n_flat:], rtol=1e-11)


@pytest.mark.parametrize("name", AIRFRAMES)
def test_same_polytope_ignores_order_round_off_and_redundant_facets(name):
    p = s0_of(name)
    A2, b2 = _shuffled(p.A, p.b, np.random.default_rng(1))
    same, why = same_polytope(p.A, p.b, A2, b2)
    assert same, why
    # a redundant facet (a facet moved outward) and a duplicate do not change the set
    A3, b3 = np.vstack([A2, p.A[:1], p.A[:1]]), np.concatenate([b2, p.b[:1] + 1.0, p.b[:1]])
    assert same_polytope(A3, b3, p.A, p.b)[0]


def test_same_polytope_reports_a_moved_facet():
    """Moving one (non-redundant) facet outward by delta: the moved set reaches exactly delta
    beyond that facet of the original, and the message says so; inward: the other way."""
    p = s0_of("paper_hexacopter")
    delta = 1e-6 * p.scale  # far above round-off, far below anything physical
    k = int(np.argmin(p.A[:, 2]))  # the facet of the largest upward thrust: never redundant
    b2 = p.b.copy()
    b2[k] += delta
    same, why = same_polytope(p.A, b2, p.A, p.b, names=("moved", "original"))
    assert not same
    m = re.fullmatch(r"moved reaches (\S+) N beyond facet (\d+) of original .*", why)
    assert m is not None, why
    assert int(m.group(2)) == k and float(m.group(1)) == pytest.approx(delta, rel=1e-3)
    b2[k] -= 2.0 * delta
    same, why = same_polytope(p.A, b2, p.A, p.b, names=("moved", "original"))
    assert not same and why.startswith(f"original reaches {delta:.3g} N beyond facet {k} ")
    # an empty set differs from a non-empty one
    b_empty = p.b.copy()
    b_empty[k] = -p.b[int(np.argmax(p.A[:, 2]))] - 1.0  # below the set's lowest f_z
    assert same_polytope(p.A, b_empty, p.A, p.b) == \
        (False, "the first set is empty, the other is not")


# ---------------------------------------------------------------------------
# (6) the hover slice P_xy against a direct LP at fixed f_z


def test_hover_slice_against_direct_lp():
    name = "paper_hexacopter"
    af = plant.load_airframe(name)
    s0 = s0_of(name)
    fz = hover_force(name)[2]
    A_xy, b_xy = s0.slice_z(fz)
    assert A_xy.shape[0] <= s0.n_facets
    assert np.all(A_xy @ np.zeros(2) <= b_xy)  # (0, 0) inside
    poly = s0.slice_polygon(fz)
    F, M, S = sampled_model(af)
    ratios = []
    for ang in np.radians(np.arange(0, 360, 10)):
        c2 = np.array([np.cos(ang), np.sin(ang)])
        lp, _ = lp_support(F, M, S, np.array([c2[0], c2[1], 0.0]), fz=fz)
        outer = float(np.max(poly @ c2))
        assert outer >= lp - 1e-7 * s0.scale
        ratios.append(outer / lp)
    # the outer polygon exceeds the attainable one by at most 8 % (measured: <= 5 %)
    assert max(ratios) <= 1.08
    # nonlinear check with real actuator states: max f_x at hover stays inside the slice
    a0, b0, w0 = af.hover_trim()
    for c in (np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0])):
        f, tau = nonlinear_max(af, c, a0, b0, af.k_t * w0**2, fz=fz)
        assert np.max(np.abs(tau)) <= 1e-7 and abs(f[2] - fz) <= 1e-7
        assert c[:2] @ f[:2] <= np.max(poly @ c[:2]) + 1e-6
        assert c[:2] @ f[:2] >= 0.9 * np.max(poly @ c[:2])


def test_slice_clamps_an_empty_plane():
    s0 = s0_of("paper_hexacopter")
    z_lo, z_hi = s0.z_range
    with pytest.raises(EmptyForceSetError):
        s0.slice_z(z_hi + 1.0, clamp=False)
    with pytest.raises(EmptyForceSetError):
        s0.slice_z(z_lo - 1.0, clamp=False)
    A_xy, b_xy = s0.slice_z(z_lo - 1.0)  # clamped to the bottom: a face, non-empty
    res = linprog([0.0, 0.0], A_ub=A_xy, b_ub=b_xy + 1e-9, bounds=(None, None), method="highs")
    assert res.status == 0
    assert s0.clamp_z(z_hi + 5.0) == z_hi


# ---------------------------------------------------------------------------
# (7) the quadrotor has no lateral force in S(0)


def test_quadrotor_s0_has_no_lateral_force():
    s0 = s0_of("quadrotor")
    for c in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]):
        res = linprog(-np.array(c, float), A_ub=s0.A, b_ub=s0.b, bounds=(None, None),
                      method="highs")
        assert res.status == 0
        assert -res.fun <= 1e-9
    assert np.max(np.abs(s0.vertices[:, :2])) <= 1e-9
    fz = hover_force("quadrotor")[2]
    assert np.max(np.abs(s0.slice_polygon(fz))) <= 1e-9
    assert not s0.contains([1e-6, 0.0, fz])
    af = plant.load_airframe("quadrotor")
    np.testing.assert_allclose(s0.z_range[0], -4 * af.k_t * af.omega_max**2, rtol=1e-9)


# ---------------------------------------------------------------------------
# (8) the figure


def test_plot_is_written(tmp_path):
    name = "paper_hexacopter"
    out = plot_force_sets(name, tmp_path / "fig3.png", afs=afs_of(name), s0=s0_of(name))
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 50_000
    out_q = plot_force_sets("quadrotor", tmp_path / "quad.png", afs=afs_of("quadrotor"),
                            s0=s0_of("quadrotor"))
    assert out_q.stat().st_size > 20_000


# ---------------------------------------------------------------------------
# (9) a failure of the numerics: one line naming the airframe, never Qhull's report


def test_a_qhull_failure_is_one_line_naming_the_airframe(tmp_path, monkeypatch, capsys):
    """Qhull's error (here planted; 1e150 rpm gave one before the airframe checks refused such
    speeds) is pages of options and input: the user sees its first line, with the airframe's
    file and name, and `fullpose force-set` exits 2."""
    from helpers.airframe_kinds import write_kind
    from scipy.spatial import QhullError

    import controller.force_sets as fs
    from orchestrator.cli import main

    report = ("QH6154 Qhull precision error: Initial simplex is flat (facet 1 is coplanar "
              "with the interior point)\n\nWhile executing:  | qhull H\nOptions selected for "
              "Qhull 2020.2.r 2020/08/31:\n" + "  run-id 617027435  Halfspace\n" * 60)

    def flat(*args, **kwargs):
        raise QhullError(report)

    monkeypatch.setattr(fs, "intersection", flat)
    monkeypatch.setenv("FULLPOSE_CACHE_DIR", str(tmp_path / "cache"))  # computed, not cached
    path = write_kind("tilting_quadrotor", tmp_path)
    with pytest.raises(fs.ForceSetError) as err:
        fs.feasible_force_set(path)
    assert str(err.value) == (
        f"{path}: the feasible force set S(tau) of airframe 'tilting_quadrotor' could not be "
        "computed (QH6154 Qhull precision error: Initial simplex is flat (facet 1 is coplanar "
        "with the interior point))")
    assert main(["force-set", "--airframe", str(path)]) == 2
    out = capsys.readouterr()
    assert out.err.splitlines() == [
        f"fullpose: error: {path}: the attainable force set of airframe 'tilting_quadrotor' "
        "could not be computed (QH6154 Qhull precision error: Initial simplex is flat (facet 1 "
        "is coplanar with the interior point))"]
