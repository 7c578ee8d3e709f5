"""The C allocation solver (fmu_src/common/wls.c) against piqp on generated problems.

Problems: min ||A x - b||^2 s.t. lb <= x <= ub, C x <= d.  piqp solves the same
QP as 1/2 x'Px + c'x with P = 2 A'A, c = -2 A'b (tolerances 1e-10; equal
bounds passed as equality rows, which piqp's box does not accept).

Acceptance, per feasible problem:
- status "optimal", x finite, iterations <= the cap (MAX_ITER);
- max violation of the bounds and of C x <= d at our x <= 1e-9 (absolute; the
  generated data are O(1)..O(100) in x and d);
- objective f = ||A x - b||^2 equal to the oracle's within 1e-6 relative to
  max(f_oracle, floor), floor = 1e-6 * ||b||^2 (f at x = 0, the natural scale
  of the objective; it only matters when the optimum is ~0, i.e. b reachable,
  where both solvers return rounding-level residuals).  The oracle value is
  the best objective among piqp's x and its "polished" versions (the exact
  minimiser on the face piqp's x lies on, by numpy least squares, kept only if
  feasible): every one is feasible, hence an upper bound of the optimum.  At
  1e7 weight ratios piqp's residual tolerances are relative to ||P|| ~ 1e11 and
  its objective can be ~1e-4 off; then piqp is re-run at 1e-13 (and with cost
  scaling) before comparing; "tight_oracle" in the printed stats counts those.
Per infeasible problem: our status "infeasible", piqp's PIQP_PRIMAL_INFEASIBLE,
x finite, within the bounds and minimising the largest row-normalised
violation (checked against a scipy HiGHS LP).

Categories (counts in CATEGORIES, 11,800 problems): well-posed, rank-deficient
A, redundant / degenerate rows, equal bounds, infeasible sets, 1e7 weight
ratios, the paper's guidance QP (eq. 17-23, polygon or polytope force
constraints), the inner allocation (24 actuator increments, 6 + 24 rows) and
A ending in a diagonal block with dense rows scaled over seven decades.
Further tests: the iteration cap, bad input, special infeasible sets, the
size caps, warm against cold start, the early exit, arbitrary working sets.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import piqp
import pytest

import controller.wls as wls

MAX_ITER = 200
OBJ_RTOL = 1e-6
VIOL_TOL = 1e-9
SQRT_1E7 = math.sqrt(1e7)


# --------------------------------------------------------------------------- #
# oracle


def piqp_solve(prob: dict, eps: float = 1e-10, scale_cost: bool = False):
    """piqp's status ("solved", "infeasible" or other) and x.  Equal bounds go
    to piqp as equality rows (its interior-point box does not accept lb == ub).
    A run stopped by piqp's iteration limit still counts as solved when its x is
    feasible (seen on zero-residual rank-deficient problems)."""
    A, b = prob["A"], prob["b"]
    n = A.shape[1]
    P = np.asfortranarray(2.0 * A.T @ A)
    c = -2.0 * A.T @ b
    solver = piqp.DenseSolver()
    s = solver.settings
    s.eps_abs = eps
    s.eps_rel = eps
    s.max_iter = 500
    if scale_cost:
        s.preconditioner_scale_cost = True
        s.preconditioner_iter = 50
    C, d = prob["C"], prob["d"]
    G = np.asfortranarray(C) if C.shape[0] else None
    h = d if C.shape[0] else None
    lb = prob["lb"] if prob["lb"] is not None else np.full(n, -np.inf)
    ub = prob["ub"] if prob["ub"] is not None else np.full(n, np.inf)
    eq = lb == ub
    Aeq = beq = None
    if np.any(eq):
        Aeq = np.asfortranarray(np.eye(n)[eq])
        beq = lb[eq].copy()
        lb, ub = np.where(eq, -np.inf, lb), np.where(eq, np.inf, ub)
    try:
        solver.setup(P, c, Aeq, beq, G, None, h, lb, ub)  # piqp >= 0.6: h_l, h_u
    except TypeError:
        solver.setup(P, c, Aeq, beq, G, h, lb, ub)  # piqp < 0.6: h
    status = solver.solve()
    x = np.array(solver.result.x)
    if status == piqp.PIQP_SOLVED:
        return "solved", x
    if status == piqp.PIQP_PRIMAL_INFEASIBLE:
        return "infeasible", None
    if status == piqp.PIQP_MAX_ITER_REACHED and np.all(np.isfinite(x)):
        if violation(prob, x) <= VIOL_TOL:
            return "solved", x
    return str(status), None


# Oracle runs, in order, until ours agrees: eps = 1e-10 first; at
# 1e7 weight ratios piqp's residuals (relative to ||P|| ~ 1e11) leave up to
# ~1e-4 relative error in the objective, so tighter runs follow.
ORACLE_RUNS = ({"eps": 1e-10}, {"eps": 1e-13}, {"eps": 1e-13, "scale_cost": True})


def polish(prob: dict, x_ref: np.ndarray, act_tol: float) -> np.ndarray | None:
    """Exact minimiser on the face piqp's x lies on (bounds and rows with
    slack below act_tol held at equality), by least squares on the KKT system;
    None when that point is not feasible."""
    A, b = prob["A"], prob["b"]
    n = A.shape[1]
    rows, rhs = [], []
    for j in range(n):
        for bound, sign in ((prob["lb"], -1.0), (prob["ub"], 1.0)):
            if bound is None or not np.isfinite(bound[j]):
                continue
            if abs(x_ref[j] - bound[j]) <= act_tol * max(1.0, abs(bound[j])):
                e = np.zeros(n)
                e[j] = sign
                rows.append(e), rhs.append(sign * bound[j])
    for i in range(prob["C"].shape[0]):
        ci = prob["C"][i]
        if prob["d"][i] - ci @ x_ref <= act_tol * max(1.0, np.linalg.norm(ci), abs(prob["d"][i])):
            rows.append(ci), rhs.append(prob["d"][i])
    N = np.array(rows).reshape(-1, n)
    k = N.shape[0]
    K = np.block([[2.0 * A.T @ A, N.T], [N, np.zeros((k, k))]])
    try:
        sol = np.linalg.lstsq(K, np.concatenate([2.0 * A.T @ b, rhs]), rcond=None)[0]
    except np.linalg.LinAlgError:
        return None
    x = sol[:n]
    return x if np.all(np.isfinite(x)) and violation(prob, x) <= VIOL_TOL else None


def oracle_objective(prob: dict, x_ref: np.ndarray, f_target: float | None = None) -> float:
    """Best objective among piqp's x and its polished versions (each feasible,
    so each an upper bound of the optimum).  Polishing is needed at 1e7
    weight ratios, where piqp's 1e-10 tolerances leave up to ~1e-4 relative
    error in the objective (its residuals are relative to ||P|| ~ 1e11).
    Stops early once within OBJ_RTOL of f_target (polishing costs time)."""

    def close(f: float) -> bool:
        scale = max(abs(f), obj_floor(prob))
        return f_target is not None and abs(f_target - f) <= OBJ_RTOL * scale

    f = objective(prob, x_ref)
    for act_tol in (1e-9, 1e-7, 1e-5, 1e-3, 1e-2, 1e-1):
        if close(f):
            break
        xp = polish(prob, x_ref, act_tol)
        if xp is not None:
            f = min(f, objective(prob, xp))
    return f


def violation(prob: dict, x: np.ndarray) -> float:
    v = 0.0
    if prob["lb"] is not None:
        v = max(v, float(np.max(prob["lb"] - x, initial=0.0)))
    if prob["ub"] is not None:
        v = max(v, float(np.max(x - prob["ub"], initial=0.0)))
    if prob["C"].shape[0]:
        v = max(v, float(np.max(prob["C"] @ x - prob["d"], initial=0.0)))
    return v


def objective(prob: dict, x: np.ndarray) -> float:
    r = prob["A"] @ x - prob["b"]
    return float(r @ r)


def ours(prob: dict, max_iter: int = MAX_ITER, working_set=None) -> wls.WlsResult:
    C = prob["C"] if prob["C"].shape[0] else None
    d = prob["d"] if prob["C"].shape[0] else None
    return wls.solve(prob["A"], prob["b"], prob["lb"], prob["ub"], C, d, max_iter, working_set)


# --------------------------------------------------------------------------- #
# generators (each returns A, b, lb, ub, C, d and whether it is feasible by
# construction)


def _problem(A, b, lb, ub, C, d, feasible=True) -> dict:
    n = A.shape[1]
    if C is None:
        C, d = np.zeros((0, n)), np.zeros(0)
    return {"A": A, "b": b, "lb": lb, "ub": ub, "C": C, "d": d, "feasible": feasible}


def _bounds(rng, x_f, p_inf=0.15, p_eq=0.0):
    n = x_f.size
    lb = x_f - rng.uniform(0.05, 2.0, n)
    ub = x_f + rng.uniform(0.05, 2.0, n)
    lb[rng.random(n) < p_inf] = -np.inf
    ub[rng.random(n) < p_inf] = np.inf
    eq = rng.random(n) < p_eq
    lb[eq] = ub[eq] = x_f[eq]
    return lb, ub


def _cons(rng, x_f, p, tight=0.1):
    n = x_f.size
    C = rng.standard_normal((p, n))
    sparse = rng.random((p, n)) < 0.3
    C[sparse] = 0.0
    C[np.all(C == 0.0, axis=1), 0] = 1.0
    slack = rng.uniform(0.0, 1.0, p)
    slack[rng.random(p) < tight] = 0.0
    return C, C @ x_f + slack


def _rhs(rng, A, x_f, spread=2.0):
    x_t = x_f + spread * rng.standard_normal(A.shape[1])
    return A @ x_t + 0.1 * rng.standard_normal(A.shape[0])


def gen_well_posed(rng):
    n = int(rng.integers(2, 33))
    m = int(rng.integers(n, min(48, n + 16) + 1))
    p = int(rng.integers(0, min(96, 3 * n) + 1))
    x_f = rng.standard_normal(n)
    A = rng.standard_normal((m, n))
    lb, ub = _bounds(rng, x_f)
    C, d = _cons(rng, x_f, p)
    return _problem(A, _rhs(rng, A, x_f), lb, ub, C, d)


def gen_rank_deficient(rng):
    n = int(rng.integers(2, 33))
    kind = rng.integers(0, 3)
    if kind == 0:  # fewer rows than variables
        m = int(rng.integers(1, n))
        A = rng.standard_normal((m, n))
    elif kind == 1:  # low rank
        m = int(rng.integers(1, 49))
        r = int(rng.integers(1, min(m, n) + 1))
        r = max(1, min(r, min(m, n) - 1)) if min(m, n) > 1 else 1
        A = rng.standard_normal((m, r)) @ rng.standard_normal((r, n))
    else:  # variables that do not appear in the objective
        m = int(rng.integers(n, min(48, n + 8) + 1))
        A = rng.standard_normal((m, n))
        A[:, rng.random(n) < 0.4] = 0.0
    p = int(rng.integers(0, min(96, 3 * n) + 1))
    x_f = rng.standard_normal(n)
    lb, ub = _bounds(rng, x_f, p_inf=0.3)
    C, d = _cons(rng, x_f, p)
    return _problem(A, _rhs(rng, A, x_f), lb, ub, C, d)


def gen_degenerate(rng):
    n = int(rng.integers(2, 25))
    m = int(rng.integers(n, min(48, n + 8) + 1))
    x_f = rng.standard_normal(n)
    A = rng.standard_normal((m, n))
    if rng.random() < 0.3:
        A[:, 0] = 0.0  # some rank deficiency too
    lb, ub = _bounds(rng, x_f)
    p0 = int(rng.integers(1, min(40, 2 * n) + 1))
    C, d = _cons(rng, x_f, p0, tight=0.7)  # many rows through x_f: degenerate vertex
    rows, rhs = [C], [d]
    k = int(rng.integers(1, 12))
    for _ in range(k):
        t = rng.integers(0, 5)
        i, j = rng.integers(0, p0, 2)
        if t == 0:  # exact duplicate
            rows.append(C[i : i + 1]), rhs.append(d[i : i + 1])
        elif t == 1:  # scaled duplicate
            s = rng.uniform(0.01, 100.0)
            rows.append(s * C[i : i + 1]), rhs.append(s * d[i : i + 1])
        elif t == 2:  # non-negative combination: redundant (tight where both are)
            y1, y2 = rng.uniform(0.1, 2.0, 2)
            rows.append((y1 * C[i] + y2 * C[j])[None]), rhs.append([y1 * d[i] + y2 * d[j]])
        elif t == 3:  # a bound written as a row
            v = int(rng.integers(0, n))
            e = np.zeros((1, n))
            if np.isfinite(ub[v]):
                e[0, v] = 1.0
                rows.append(e), rhs.append([ub[v]])
            elif np.isfinite(lb[v]):
                e[0, v] = -1.0
                rows.append(e), rhs.append([-lb[v]])
        else:  # equality as two inequalities
            rows.append(np.vstack([C[i], -C[i]])), rhs.append([C[i] @ x_f, -(C[i] @ x_f)])
    C = np.vstack(rows)[:96]
    d = np.concatenate([np.asarray(r, dtype=float) for r in rhs])[:96]
    perm = rng.permutation(C.shape[0])
    return _problem(A, _rhs(rng, A, x_f), lb, ub, C[perm], d[perm])


def gen_equal_bounds(rng):
    n = int(rng.integers(2, 33))
    m = int(rng.integers(max(1, n // 2), min(48, n + 8) + 1))
    x_f = rng.standard_normal(n)
    A = rng.standard_normal((m, n))
    lb, ub = _bounds(rng, x_f, p_eq=rng.uniform(0.1, 0.9))
    p = int(rng.integers(0, min(96, 2 * n) + 1))
    C, d = _cons(rng, x_f, p)
    return _problem(A, _rhs(rng, A, x_f), lb, ub, C, d)


def gen_infeasible(rng):
    n = int(rng.integers(2, 25))
    m = int(rng.integers(1, min(48, n + 8) + 1))
    x_f = rng.standard_normal(n)
    A = rng.standard_normal((m, n))
    lb, ub = _bounds(rng, x_f, p_inf=0.3)
    p = int(rng.integers(2, min(90, 3 * n) + 1))
    C, d = _cons(rng, x_f, p)
    delta = 10.0 ** rng.uniform(-3, 0)
    if rng.random() < 0.6:
        # Farkas: a non-negative combination of some rows, negated, beyond it
        k = int(rng.integers(1, min(p, 6) + 1))
        idx = rng.choice(p, k, replace=False)
        y = rng.uniform(0.2, 2.0, k)
        c_new = -(y @ C[idx])
        d_new = -(y @ d[idx]) - delta * np.linalg.norm(c_new)
        C, d = np.vstack([C, c_new]), np.append(d, d_new)
    else:
        # a row the box cannot reach: c'x <= d with d below min over the box
        lo = np.where(np.isfinite(lb), lb, x_f - 1.0)
        hi = np.where(np.isfinite(ub), ub, x_f + 1.0)
        lb, ub = lo, hi
        c_new = rng.standard_normal(n)
        box_min = np.sum(np.where(c_new > 0, c_new * lo, c_new * hi))
        C = np.vstack([C, c_new])
        d = np.append(d, box_min - delta * np.linalg.norm(c_new))
    perm = rng.permutation(C.shape[0])
    return _problem(A, _rhs(rng, A, x_f), lb, ub, C[perm], d[perm], feasible=False)


def gen_weights_1e7(rng):
    n = int(rng.integers(3, 25))
    m = int(rng.integers(n, min(48, n + 10) + 1))
    x_f = rng.standard_normal(n)
    A = rng.standard_normal((m, n))
    heavy = int(rng.integers(1, min(6, m) + 1))
    w = np.ones(m)
    w[:heavy] = SQRT_1E7 * rng.choice([1.0, 0.1, 0.01], heavy)
    w[heavy:] *= rng.choice([1.0, 10.0, 0.1], m - heavy)
    A = w[:, None] * A
    lb, ub = _bounds(rng, x_f)
    p = int(rng.integers(0, min(60, 3 * n) + 1))
    C, d = _cons(rng, x_f, p)
    return _problem(A, _rhs(rng, A, x_f), lb, ub, C, d)


def _rot(phi, theta, psi):
    cf, sf, ct, st, cp, sp = (
        np.cos(phi),
        np.sin(phi),
        np.cos(theta),
        np.sin(theta),
        np.cos(psi),
        np.sin(psi),
    )
    rz = np.array([[cp, -sp, 0], [sp, cp, 0], [0, 0, 1]])
    ry = np.array([[ct, 0, st], [0, 1, 0], [-st, 0, ct]])
    rx = np.array([[1, 0, 0], [0, cf, -sf], [0, sf, cf]])
    return rz @ ry @ rx


def _polygon(rng, k, radius):
    ang = np.sort(2 * np.pi * (np.arange(k) + rng.uniform(-0.3, 0.3, k)) / k)
    normals = np.column_stack([np.cos(ang), np.sin(ang)])
    offsets = radius * rng.uniform(0.7, 1.3, k)
    return normals, offsets


def gen_guidance(rng):
    """Eq. 17-23: u = [dfx, dfy, dfz, dphi, dtheta(, dpsi)], rows 3 + 5 (6)."""
    with_psi = rng.random() < 0.3
    nu = 6 if with_psi else 5
    mass, g = 3.0, 9.81
    gamma_opt = 1000.0
    wv = np.array([100.0, 100.0, 10.0])
    wu = np.array([1.0, 1.0, 1.0, 10.0, 10.0, 1.0])[:nu]
    eul = rng.uniform(-0.6, 0.6, 3)
    f_m = np.array([rng.normal(0, 5), rng.normal(0, 5), -mass * g + rng.normal(0, 5)])
    r = _rot(*eul)
    h = 1e-6
    cols = [r[:, 0], r[:, 1], r[:, 2]]
    for a in range(nu - 3):
        e = eul.copy()
        e[a] += h
        ep = e
        e2 = eul.copy()
        e2[a] -= h
        cols.append((_rot(*ep) @ f_m - _rot(*e2) @ f_m) / (2 * h))
    G = np.column_stack(cols)
    acc = rng.normal(0, 3.0, 3) * rng.choice([0.1, 1.0, 5.0])
    du_p = np.concatenate([np.zeros(3), rng.uniform(-0.5, 0.5, nu - 3)])
    A = np.vstack([math.sqrt(gamma_opt) * wv[:, None] * G, np.diag(wu)])
    b = np.concatenate([math.sqrt(gamma_opt) * wv * mass * acc, wu * du_p])
    lb = np.full(nu, -np.inf)
    ub = np.full(nu, np.inf)
    fz_min, fz_max = -4.6 * mass * g, -0.2 * mass * g
    lb[2], ub[2] = fz_min - f_m[2], fz_max - f_m[2]
    mu_max = np.deg2rad(60.0)
    lb[3:], ub[3:] = -mu_max - eul[: nu - 3], mu_max - eul[: nu - 3]
    if with_psi:
        lb[5], ub[5] = -np.inf, np.inf
    k = int(rng.integers(10, 41))
    radius = rng.uniform(8.0, 25.0)
    if rng.random() < 0.5:  # lateral polygon P_xy on (fx, fy)
        nrm, off = _polygon(rng, k, radius)
        C = np.zeros((k, nu))
        C[:, :2] = nrm
        d = off - nrm @ f_m[:2]
    else:  # 3-D polytope on (fx, fy, fz) around the hover force
        nrm = rng.standard_normal((k, 3))
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        center = np.array([0.0, 0.0, -2.0 * mass * g])
        off = nrm @ center + radius * rng.uniform(0.7, 1.3, k) * 2.0
        C = np.zeros((k, nu))
        C[:, :3] = nrm
        d = off - nrm @ f_m
    feasible = None  # decided by piqp (f_m may sit outside the set)
    return _problem(A, b, lb, ub, C, d, feasible)


def gen_allocation(rng):
    """Eq. 12-13: 4n = 24 actuator increments, 6 wrench rows + 24 preference rows."""
    n_act = 24
    scale = np.tile([0.05, 2.0, 2.0, 1.0], 6)  # d(wrench)/d(omega) is per rad/s
    B = rng.standard_normal((6, n_act)) * scale
    B[3:, :] *= 0.3
    w_rows = np.array([1.0, 1.0, 1.0, 100.0, 100.0, 100.0])
    s_pref = math.sqrt(0.1) * np.tile([1.0 / 50.0, 1.0, 1.0, 1.0], 6)
    A = np.vstack([w_rows[:, None] * B, np.diag(s_pref)])
    u_m = np.tile([100.0, 0.0, 0.0, 0.0], 6) + rng.normal(0, 1, n_act) * np.tile(
        [30.0, 0.4, 0.4, 0.4], 6
    )
    u_min = np.tile([10.0, -1.2, -1.2, -1.2], 6)
    u_max = np.tile([209.0, 1.2, 1.2, 1.2], 6)
    u_m = np.clip(u_m, u_min, u_max)
    u_pref = np.tile([98.0, 0.0, 0.0, 0.0], 6)
    dnu = rng.normal(0, 1, 6) * rng.choice([1.0, 10.0, 100.0])
    b = np.concatenate([w_rows * dnu, s_pref * (u_pref - u_m)])
    lb, ub = u_min - u_m, u_max - u_m
    fixed = rng.random(n_act) < 0.05  # a stuck actuator
    lb[fixed] = ub[fixed] = 0.0
    return _problem(A, b, lb, ub, None, None)


def gen_diagonal_tail(rng):
    """A = [M; D], D diagonal (preference or regularisation rows), M dense and scaled so
    that ||M D^-1|| spans 1 .. ~1e7: the solver's diagonal-tail step (dual form for small
    ||M D^-1||, primal beyond).  Fewer dense rows than variables (the dense rows can be met
    exactly: the dual form's hard case) or more; a few rows of C on some problems."""
    n = int(rng.integers(2, 21))
    m0 = int(rng.integers(1, min(9, 48 - n) + 1))
    x_f = rng.standard_normal(n)
    M = rng.standard_normal((m0, n)) * 10.0 ** rng.uniform(-1.0, 6.0)
    dg = rng.uniform(0.01, 1.0, n) * rng.choice([-1.0, 1.0], n)
    A = np.vstack([M, np.diag(dg)])
    lb, ub = _bounds(rng, x_f, p_eq=0.05)
    p = int(rng.integers(0, 4)) if rng.random() < 0.3 else 0
    C, d = _cons(rng, x_f, p) if p else (None, None)
    return _problem(A, _rhs(rng, A, x_f), lb, ub, C, d)


CATEGORIES = {
    "well_posed": (gen_well_posed, 2000),
    "rank_deficient": (gen_rank_deficient, 1500),
    "degenerate": (gen_degenerate, 1500),
    "equal_bounds": (gen_equal_bounds, 1000),
    "infeasible": (gen_infeasible, 1000),
    "weights_1e7": (gen_weights_1e7, 1000),
    "guidance": (gen_guidance, 1500),
    "allocation": (gen_allocation, 800),
    "diagonal_tail": (gen_diagonal_tail, 1500),
}
SEEDS = {name: 1000 + i for i, name in enumerate(CATEGORIES)}


def minimax_violation(prob: dict, x: np.ndarray) -> float:
    nrm = np.linalg.norm(prob["C"], axis=1)
    return float(np.max((prob["C"] @ x - prob["d"]) / nrm))


def minimax_lp(prob: dict) -> float:
    """min t s.t. C_i x / |C_i| - t <= d_i / |C_i|, lb <= x <= ub (scipy HiGHS)."""
    from scipy.optimize import linprog

    C, d = prob["C"], prob["d"]
    nrm = np.linalg.norm(C, axis=1)
    n = C.shape[1]
    lb = prob["lb"] if prob["lb"] is not None else np.full(n, -np.inf)
    ub = prob["ub"] if prob["ub"] is not None else np.full(n, np.inf)
    bounds = [
        (lo if np.isfinite(lo) else None, hi if np.isfinite(hi) else None)
        for lo, hi in zip(lb, ub, strict=True)
    ]
    res = linprog(
        np.r_[np.zeros(n), 1.0],
        A_ub=np.c_[C / nrm[:, None], -np.ones(len(d))],
        b_ub=d / nrm,
        bounds=[*bounds, (None, None)],
        method="highs",
    )
    assert res.status == 0, res.message
    return float(res.fun)


def obj_floor(prob: dict) -> float:
    return 1e-6 * float(prob["b"] @ prob["b"])


def best_oracle(prob: dict, f: float,
                first: tuple | None = None) -> tuple[float, float, str, int]:
    """(piqp's best objective, our relative gap to it, piqp's last status, the settings
    tried) over the oracle settings, stopping at the first that agrees; ``first`` is an
    answer already computed with the first settings."""
    f_ref, rel, ref_status, runs = math.inf, math.inf, "not run", 0
    for i, settings in enumerate(ORACLE_RUNS):
        runs += 1
        ref_status, x_ref = first if (i == 0 and first is not None) else piqp_solve(
            prob, **settings)
        if ref_status != "solved":
            continue
        f_ref = min(f_ref, oracle_objective(prob, x_ref, f))
        rel = abs(f - f_ref) / max(abs(f_ref), obj_floor(prob))
        if rel <= OBJ_RTOL:
            break
    return f_ref, rel, ref_status, runs


def check_problem(prob: dict) -> dict:
    """Solve with both; return a record (raises AssertionError on a failure)."""
    res = ours(prob)
    assert np.all(np.isfinite(res.x)), "non-finite x"
    assert res.iterations <= MAX_ITER
    ref_status, x_ref = piqp_solve(prob, **ORACLE_RUNS[0])
    feasible = prob["feasible"]
    if feasible is None:
        feasible = ref_status != "infeasible"
    if not feasible:
        assert ref_status == "infeasible", f"piqp says {ref_status} for an infeasible set"
        assert res.status == "infeasible", f"ours: {res.status}"
        if prob["lb"] is not None:
            assert np.all(res.x >= prob["lb"]) and np.all(res.x <= prob["ub"])
        if prob["C"].shape[0] and res.iterations < MAX_ITER:
            # documented x: least largest row-normalised violation within the bounds
            t_ours, t_lp = minimax_violation(prob, res.x), minimax_lp(prob)
            assert t_ours <= t_lp + 1e-9 * max(1.0, abs(t_lp)), f"minimax {t_ours} vs LP {t_lp}"
        return {"status": "infeasible", "iterations": res.iterations}
    assert res.status == "optimal", f"ours: {res.status} after {res.iterations}"
    viol = violation(prob, res.x)
    assert viol <= VIOL_TOL, f"violation {viol:.3e}"
    f = objective(prob, res.x)
    f_ref, rel, ref_status, runs = best_oracle(prob, f, (ref_status, x_ref))
    assert f_ref < math.inf, f"piqp: {ref_status}"
    assert rel <= OBJ_RTOL, f"objective {f!r} vs piqp {f_ref!r} (rel {rel:.2e})"
    return {
        "status": "optimal",
        "iterations": res.iterations,
        "rel": rel,
        "viol": viol,
        "oracle_runs": runs,
    }


@pytest.mark.parametrize("category", list(CATEGORIES))
def test_against_piqp(category):
    gen, count = CATEGORIES[category]
    rng = np.random.default_rng(SEEDS[category])
    failures = []
    stats = {
        "n": 0,
        "max_rel": 0.0,
        "max_viol": 0.0,
        "max_iter": 0,
        "infeasible": 0,
        "tight_oracle": 0,
    }
    t0 = time.perf_counter()
    for k in range(count):
        prob = gen(rng)
        try:
            rec = check_problem(prob)
        except AssertionError as exc:
            failures.append((k, str(exc)))
            continue
        stats["n"] += 1
        stats["max_iter"] = max(stats["max_iter"], rec["iterations"])
        if rec["status"] == "infeasible":
            stats["infeasible"] += 1
        else:
            stats["max_rel"] = max(stats["max_rel"], rec["rel"])
            stats["max_viol"] = max(stats["max_viol"], rec["viol"])
            stats["tight_oracle"] += rec["oracle_runs"] > 1
    print(f"\n{category}: {stats} in {time.perf_counter() - t0:.1f} s")
    assert not failures, f"{len(failures)} of {count} failed, first: {failures[:5]}"


# --------------------------------------------------------------------------- #
# iteration cap, bad input, warm start


def _mixed(rng, k):
    gens = [
        gen_well_posed,
        gen_rank_deficient,
        gen_degenerate,
        gen_weights_1e7,
        gen_guidance,
        gen_allocation,
        gen_infeasible,
        gen_equal_bounds,
    ]
    return gens[k % len(gens)](rng)


def test_iteration_cap():
    """Any cap: iterations <= cap, x finite and within the bounds; a solve that
    ends before the cap is the uncapped one; once feasible, a larger cap never
    gives a larger objective (phase 2 never increases it)."""
    rng = np.random.default_rng(4242)
    caps = (1, 2, 3, 5, 8, 13, 21, 34)
    hit = 0
    for k in range(400):
        prob = _mixed(rng, k)
        full = ours(prob, 1000)
        prev_f = math.inf
        for cap in caps:
            r = ours(prob, cap)
            assert np.all(np.isfinite(r.x))
            assert r.iterations <= cap
            if prob["lb"] is not None:
                assert np.all(r.x >= prob["lb"]) and np.all(r.x <= prob["ub"])
            if r.status == "max_iter":
                hit += 1
                assert r.iterations == cap
            else:
                assert r.status == full.status
                if r.iterations < cap or r.status != "infeasible":
                    np.testing.assert_array_equal(r.x, full.x)
                # (an infeasible set stays "infeasible" when the cap cuts the
                # search for the least-violation point short)
            if r.status != "infeasible" and r.max_violation <= VIOL_TOL:
                f = objective(prob, r.x)
                assert f <= prev_f + 1e-12 * max(1.0, prev_f), (k, cap, f, prev_f)
                assert f >= full.objective - 1e-9 * max(1.0, full.objective)
                prev_f = f
    assert hit > 500  # the cap really bit


def _bad_cases(A, b, lb, ub, C, d):
    def mod(name, idx, value):
        data = {
            "A": A.copy(),
            "b": b.copy(),
            "lb": lb.copy(),
            "ub": ub.copy(),
            "C": C.copy(),
            "d": d.copy(),
        }
        data[name][idx] = value
        return name, data

    return [
        mod("A", (0, 0), np.nan),
        mod("A", (1, 2), np.inf),
        mod("A", (0, 1), 1e200),
        mod("b", 0, np.nan),
        mod("b", 1, -np.inf),
        mod("lb", 0, np.nan),
        mod("ub", 2, np.nan),
        mod("lb", 1, np.inf),
        mod("ub", 1, -np.inf),
        mod("C", (0, 0), np.nan),
        mod("C", (0, 1), np.inf),
        mod("d", 0, np.nan),
        mod("d", 0, -np.inf),
    ]


def test_bad_input_keeps_previous_solution():
    rng = np.random.default_rng(5)
    A, b = rng.standard_normal((4, 3)), rng.standard_normal(4)
    lb, ub = -np.ones(3), np.ones(3)
    C, d = rng.standard_normal((2, 3)), np.ones(2)
    solver = wls.WlsSolver(3, 4, 2)
    good = solver.solve(A, b, lb, ub, C, d)
    assert good.status == "optimal"
    for name, data in _bad_cases(A, b, lb, ub, C, d):
        r = solver.solve(**data)
        assert r.status == "bad_input", name
        np.testing.assert_array_equal(r.x, good.x)
        np.testing.assert_array_equal(r.working_set, good.working_set)
    r = solver.solve(A, b, lb, ub, C, d, max_iter=0)
    assert r.status == "bad_input"
    # a fresh instance has x = 0
    for name, data in _bad_cases(A, b, lb, ub, C, d):
        r = wls.solve(**data)
        assert r.status == "bad_input", name
        np.testing.assert_array_equal(r.x, np.zeros(3))
    # and the data becoming good again solves normally
    assert solver.solve(A, b, lb, ub, C, d).status == "optimal"


def test_special_infeasible_sets():
    A, b = np.eye(2), np.array([3.0, -1.0])
    r = wls.solve(A, b, [0.0, 1.0], [1.0, 0.5])  # crossed bounds on x[1]
    assert r.status == "infeasible"
    assert np.all(np.isfinite(r.x)) and 0.0 <= r.x[0] <= 1.0 and 0.5 <= r.x[1] <= 1.0
    # a zero row with d < 0 cannot hold; x is the solution without it
    r = wls.solve(A, b, [-1, -1], [1, 1], C=[[0.0, 0.0], [1.0, 1.0]], d=[-1.0, -0.25])
    without = wls.solve(A, b, [-1, -1], [1, 1], C=[[1.0, 1.0]], d=[-0.25])
    assert r.status == "infeasible" and without.status == "optimal"
    np.testing.assert_allclose(r.x, without.x, atol=1e-12)
    np.testing.assert_allclose(without.x, [0.75, -1.0], atol=1e-12)
    # d = +inf disables a row
    r = wls.solve(A, b, None, None, C=[[1.0, 0.0], [0.0, 1.0]], d=[np.inf, 0.0])
    assert r.status == "optimal"
    np.testing.assert_allclose(r.x, [3.0, -1.0], atol=1e-12)


def test_sizes_beyond_caps():
    max_vars, max_rows, max_cons = wls.caps()
    assert max_vars >= 32 and max_rows >= 40 and max_cons >= 96
    with pytest.raises(ValueError):
        wls.WlsSolver(max_vars + 1, 3, 0)
    with pytest.raises(ValueError):
        wls.WlsSolver(3, max_rows + 1, 0)
    with pytest.raises(ValueError):
        wls.WlsSolver(3, 3, max_cons + 1)
    # the caps themselves work
    rng = np.random.default_rng(9)
    x_f = rng.standard_normal(max_vars)
    A = rng.standard_normal((max_rows, max_vars))
    C, d = _cons(rng, x_f, max_cons)
    prob = _problem(A, _rhs(rng, A, x_f), *_bounds(rng, x_f), C, d)
    check_problem(prob)


def _perturb(rng, prob, size):
    q = dict(prob)
    q["A"] = prob["A"] * (1.0 + size * rng.standard_normal(prob["A"].shape))
    q["b"] = prob["b"] + size * np.abs(prob["b"]).mean() * rng.standard_normal(prob["b"].shape)
    if prob["C"].shape[0]:
        q["d"] = prob["d"] + size * rng.standard_normal(prob["d"].shape)
    return q


@pytest.mark.parametrize("category", ["guidance", "allocation", "well_posed", "weights_1e7"])
def test_warm_start_beats_cold_start(category):
    """Warm start from the previous working set on a slightly perturbed problem:
    the same optimum (checked against piqp), in fewer iterations on average."""
    gen = CATEGORIES[category][0]
    rng = np.random.default_rng(77 + len(category))
    warm_it, cold_it, early = [], [], 0
    for _ in range(250):
        base = gen(rng)
        first = ours(base)
        if first.status != "optimal":
            continue
        prob = _perturb(rng, base, 1e-3)
        warm = ours(prob, working_set=first.working_set)
        cold = ours(prob)
        if cold.status == "optimal":
            assert warm.status == "optimal"
            check = check_problem(prob)  # cold vs piqp
            assert check["status"] == "optimal"
            scale = max(abs(cold.objective), obj_floor(prob))
            assert abs(warm.objective - cold.objective) <= OBJ_RTOL * scale
            assert violation(prob, warm.x) <= VIOL_TOL
        warm_it.append(warm.iterations)
        cold_it.append(cold.iterations)
        early += warm.iterations == 1
    print(
        f"\n{category}: warm {np.mean(warm_it):.2f} vs cold {np.mean(cold_it):.2f} iterations "
        f"(mean of {len(warm_it)}), warm early exits {early}"
    )
    assert np.mean(warm_it) < np.mean(cold_it)


def test_early_exit_on_optimal_working_set():
    """Re-solving from the optimal working set (and x, which a rank-deficient A
    needs to pin the point on its face) stops after one iteration."""
    rng = np.random.default_rng(31)
    for k in range(300):
        prob = _mixed(rng, k)
        first = ours(prob)
        if first.status != "optimal":
            continue
        C = prob["C"] if prob["C"].shape[0] else None
        d = prob["d"] if prob["C"].shape[0] else None
        again = wls.solve(
            prob["A"],
            prob["b"],
            prob["lb"],
            prob["ub"],
            C,
            d,
            working_set=first.working_set,
            x0=first.x,
        )
        assert again.status == "optimal"
        assert again.iterations == 1
        scale = max(abs(first.objective), obj_floor(prob))
        assert abs(again.objective - first.objective) <= 1e-9 * scale


def test_arbitrary_working_set_is_safe():
    """A wrong or inconsistent working set (random entries) only costs iterations."""
    rng = np.random.default_rng(12)
    for k in range(400):
        prob = _mixed(rng, k)
        n, p = prob["A"].shape[1], prob["C"].shape[0]
        ws = np.concatenate([rng.integers(-1, 2, n), rng.integers(0, 2, p)]).astype(np.int8)
        r = ours(prob, working_set=ws)
        cold = ours(prob)
        assert r.status == cold.status
        assert np.all(np.isfinite(r.x))
        if cold.status == "optimal":
            assert violation(prob, r.x) <= VIOL_TOL
            scale = max(abs(cold.objective), obj_floor(prob))
            assert abs(r.objective - cold.objective) <= OBJ_RTOL * scale


def test_solver_instance_follows_a_sequence():
    """WlsSolver keeps x and the working set: a drifting guidance problem stays
    optimal (vs piqp) with mostly one-iteration solves."""
    rng = np.random.default_rng(2024)
    base = gen_guidance(rng)
    n, m, p = base["A"].shape[1], base["A"].shape[0], base["C"].shape[0]
    solver = wls.WlsSolver(n, m, p)
    its = []
    prob = base
    for _ in range(300):
        prob = _perturb(rng, prob, 2e-3)
        r = solver.solve(prob["A"], prob["b"], prob["lb"], prob["ub"], prob["C"], prob["d"])
        its.append(r.iterations)
        assert r.status == "optimal"
        _, x_ref = piqp_solve(prob)
        f_ref = oracle_objective(prob, x_ref)
        assert r.objective <= f_ref + OBJ_RTOL * max(f_ref, obj_floor(prob))
    assert np.mean(its) < 2.0


def test_diagonal_tail_faces_with_facets_at_every_weight():
    """A face with an active facet on an A that ends in a diagonal block is solved by a QR
    without pivoting (its A_F Z has full rank); diagonal weights down at the rank cut-off
    (1e-13 of the dense rows, which cannot span the face alone) send it back to the
    pivoting QR.  Both against piqp."""
    rng = np.random.default_rng(5)
    for weight in (1.0, 1e-3, 1e-13):
        for _ in range(60):
            n, m0 = 5, 3
            dense = rng.standard_normal((m0, n)) * 50.0
            diag = np.diag(rng.uniform(0.5, 2.0, n) * weight)
            A = np.vstack([dense, diag])
            b = rng.standard_normal(m0 + n) * 10.0
            C = rng.standard_normal((4, n))
            C /= np.linalg.norm(C, axis=1, keepdims=True)
            d = C @ rng.uniform(-1.0, 1.0, n) + rng.uniform(0.01, 0.1, 4)  # a feasible point
            # bounds far out: a flat direction (weights 1e-13) stays bounded for piqp
            check_problem(_problem(A, b, np.full(n, -1e3), np.full(n, 1e3), C, d))


def _same(a: wls.WlsResult, b: wls.WlsResult) -> None:
    assert (a.status, a.iterations, a.phase1_iterations) == (b.status, b.iterations,
                                                             b.phase1_iterations)
    assert np.array_equal(a.x, b.x)
    assert np.array_equal(a.working_set, b.working_set)


def test_kept_rows_change_nothing():
    """keep_rows (C unchanged since the last solve: the controller's constant force set)
    gives bit for bit the full pass's solve along a drifting guidance problem whose C stays
    put; a disabled row (d = inf), a bad d, and a new C each take the full pass."""
    rng = np.random.default_rng(77)
    prob = gen_guidance(rng)
    n, m, p = prob["A"].shape[1], prob["A"].shape[0], prob["C"].shape[0]
    full, kept = wls.WlsSolver(n, m, p), wls.WlsSolver(n, m, p)
    first = (prob["A"], prob["b"], prob["lb"], prob["ub"], prob["C"], prob["d"])
    _same(kept.solve(*first), full.solve(*first))
    for k in range(200):
        prob = _perturb(rng, prob, 5e-3)
        d = prob["d"].copy()
        if k % 50 == 25:
            d[int(rng.integers(p))] = np.inf
        if k == 120:
            d[0] = 1e200  # beyond the solver's magnitude limit: bad input either way
        r_full = full.solve(prob["A"], prob["b"], prob["lb"], prob["ub"], prob["C"], d)
        kept.set_data(prob["A"], prob["b"], prob["lb"], prob["ub"], None, d)
        kept.keep_rows()
        r_kept = kept.solve_stored(MAX_ITER)
        _same(r_kept, r_full)
        assert r_full.status == ("bad_input" if k == 120 else "optimal")
    # a new C through set_data cancels a keep_rows given before it (the rows' norms change:
    # kept ones would scale them wrongly, which shows in the last bits at least)
    C2 = prob["C"] * (1.0 + 0.05 * rng.standard_normal(prob["C"].shape))
    args = (prob["A"], prob["b"], prob["lb"], prob["ub"], C2, prob["d"])
    kept.keep_rows()
    _same(kept.solve(*args), full.solve(*args))


# --------------------------------------------------------------------------- #
# randomized campaign: huge warm starts, tiny-norm rows, badly scaled columns
#
# Each problem is a feasible one from the generators above, transformed without changing
# its solution set: the solver's start point set to ~1e15 (fp_wls_set_start), or rows of C
# and their d scaled by 1e-170 or 1e-300 (rescaled variables: the column-scaled campaign
# below).  piqp solves the untransformed problem.  Ours must either agree (the objective within
# OBJ_RTOL of piqp's, as check_problem) with a violation of at most VIOL_TOL relative to the
# data (each bound relative to max(1, |bound|), each row relative to ||C_i|| max(1, |x|_inf)
# + |d_i|), or report a status other than "optimal"; x is never NaN or inf.  Non-optimal
# statuses are counted and printed, not failures.

CAMPAIGN = {
    "huge_warm_start": 300,
    "tiny_rows_1e-170": 200,
    "tiny_rows_1e-300": 200,
}
CAMPAIGN_GENS = (gen_well_posed, gen_degenerate, gen_equal_bounds, gen_weights_1e7,
                 gen_guidance, gen_allocation, gen_rank_deficient)


def _relative_violation(prob: dict, x: np.ndarray) -> float:
    v = 0.0
    if prob["lb"] is not None:
        lb, ub = prob["lb"], prob["ub"]
        fin = np.isfinite(lb)
        if fin.any():
            v = max(v, float(np.max((lb[fin] - x[fin]) / np.maximum(1.0, np.abs(lb[fin])))))
        fin = np.isfinite(ub)
        if fin.any():
            v = max(v, float(np.max((x[fin] - ub[fin]) / np.maximum(1.0, np.abs(ub[fin])))))
    C, d = prob["C"], prob["d"]
    if C.shape[0]:
        on = np.isfinite(d)
        scale = np.linalg.norm(C, axis=1) * max(1.0, float(np.max(np.abs(x)))) + np.abs(d)
        scale = np.where(scale > 0, scale, 1.0)
        r = (C @ x - d) / scale
        v = max(v, float(np.max(r[on], initial=0.0)))
    return max(v, 0.0)


def _transform(rng, prob: dict, kind: str):
    """(problem given to ours, map from its x to the original x, start point or None)."""
    q = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in prob.items()}
    n = prob["A"].shape[1]
    if kind == "huge_warm_start":
        x0 = 1e15 * rng.standard_normal(n) * rng.choice([1.0, 1e-3, 10.0])
        return q, lambda y: y, x0
    if kind.startswith("tiny_rows"):
        tiny = float(kind.split("_")[-1])
        p = q["C"].shape[0]
        if p == 0:  # guidance / allocation without rows: give it one redundant row
            c = rng.standard_normal(n)
            x_any = np.clip(np.zeros(n), q["lb"] if q["lb"] is not None else -np.inf,
                            q["ub"] if q["ub"] is not None else np.inf)
            q["C"], q["d"] = c[None, :], np.array([c @ x_any + 1e3])
            prob["C"], prob["d"] = q["C"].copy(), q["d"].copy()
            p = 1
        rows = rng.random(p) < 0.5
        rows[rng.integers(p)] = True
        q["C"][rows] *= tiny
        q["d"][rows] *= tiny
        return q, lambda y: y, None
    raise ValueError(kind)


@pytest.mark.parametrize("kind", list(CAMPAIGN))
def test_campaign_against_piqp(kind):
    rng = np.random.default_rng(7000 + list(CAMPAIGN).index(kind))
    failures, statuses, agree = [], {}, 0
    t0 = time.perf_counter()
    for k in range(CAMPAIGN[kind]):
        prob = CAMPAIGN_GENS[k % len(CAMPAIGN_GENS)](rng)
        q, back, x0 = _transform(rng, prob, kind)
        n, m, p = q["A"].shape[1], q["A"].shape[0], q["C"].shape[0]
        solver = wls.WlsSolver(n, m, p)
        solver.set_data(q["A"], q["b"], q["lb"], q["ub"], q["C"] if p else None,
                        q["d"] if p else None)
        if x0 is not None:
            solver.set_x(x0)
        res = solver.solve_stored(MAX_ITER)
        statuses[res.status] = statuses.get(res.status, 0) + 1
        if not np.all(np.isfinite(res.x)):
            failures.append((k, f"non-finite x with status {res.status}"))
            continue
        if res.status != "optimal":
            continue
        x = back(res.x)
        viol = _relative_violation(q, res.x)  # relative to the data the solver was given
        if viol > VIOL_TOL:
            failures.append((k, f"optimal with relative violation {viol:.3e}"))
            continue
        f = objective(prob, x)
        f_ref, rel, _, _ = best_oracle(prob, f)
        if f_ref == math.inf:
            continue  # no oracle answer: nothing to compare
        if rel > OBJ_RTOL:
            failures.append((k, f"optimal but objective {f!r} vs piqp {f_ref!r} "
                                f"(rel {rel:.2e})"))
            continue
        agree += 1
    kinds: dict[str, int] = {}
    for _, why in failures:
        key = why.split(" with ")[0].split(" but ")[0] + (" (violation)" if "violation" in why
                                                          else " (objective)" if "objective"
                                                          in why else "")
        kinds[key] = kinds.get(key, 0) + 1
    print(f"\n{kind}: statuses {statuses}, agreeing {agree}, failures {len(failures)} "
          f"{kinds} in {time.perf_counter() - t0:.1f} s")
    assert not failures, f"{len(failures)} of {CAMPAIGN[kind]} failed, first: {failures[:5]}"


# --------------------------------------------------------------------------- #
# column-scaled campaign: the same problems with their variables rescaled
#
# SCALED_PROBLEMS problems from the generators (the feasible kinds and infeasible sets, in
# turn), each handed to the solver with its variables rescaled, x = S z, s_j = 10^(k u_j),
# u_j ~ U(-1, 1) drawn once per problem, at k = 3, 6 and 9: the solver gets A S, b, lb / s,
# ub / s, C S, d, the very same problem.  piqp solves the unscaled one.  Counted per scale,
# and each count must be zero:
# - "suboptimal": "optimal" with an objective above piqp's by more than OBJ_RTOL relative
#   (as check_problem: relative to max(f, obj_floor)) where piqp is right (solved, and its
#   x or a polished version of it feasible within VIOL_TOL);
# - "false_infeasible": a feasible problem (by construction, or per piqp) called infeasible;
# - "violating": "optimal" with x = S z breaking a bound or a row of the unscaled problem by
#   more than VIOL_TOL relative to its data (_relative_violation);
# - "not_optimal": any other status on a feasible problem; "missed_infeasible": an
#   infeasible set not called infeasible; "non_finite": x not finite;
# - "minimax_worse" (at MINIMAX_DECADES): an infeasible set's x, documented as the least
#   largest violation of the rows as given (C S, each row over its norm) within the bounds,
#   above that least value by more than 1e-6 relative (and 1e-9 absolute).  The reference is
#   HiGHS on that LP posed in the unscaled variables (C x - |C_i S| t <= d): posed in the
#   scaled ones its own tolerances are too coarse to referee beyond 1e+-3.  At 1e+-9 the
#   row weights |C_i S| span some 18 decades; there the count is printed, not asserted.
# Two more transforms of the same problems, with the same counts (minimax not refereed):
# "common", every variable in one unit 10^(k u), u ~ U(-1, 1) per problem (S = s I: the
# solver removes no common factor of its columns, see wls.c, and its tolerances have a floor
# of 1), and "weight", the objective weighted by 10^(k u) (A and b times it: the same
# minimiser, and no unit of x at all).
SCALED_DECADES = (3, 6, 9)
SCALED_PROBLEMS = 1500
MINIMAX_DECADES = (3, 6)
SCALED_GENS = (*CAMPAIGN_GENS, gen_infeasible)
SCALED_COUNTS = ("suboptimal", "false_infeasible", "violating", "not_optimal",
                 "missed_infeasible", "non_finite", "minimax_worse")


def _feasible_oracle(prob: dict, x_ref: np.ndarray) -> float:
    """The best objective among piqp's x and its polished versions that are feasible within
    VIOL_TOL (inf when none is: piqp is not right on this problem)."""
    f = objective(prob, x_ref) if violation(prob, x_ref) <= VIOL_TOL else math.inf
    for act_tol in (1e-9, 1e-7, 1e-5, 1e-3, 1e-2, 1e-1):
        xp = polish(prob, x_ref, act_tol)
        if xp is not None:
            f = min(f, objective(prob, xp))
    return f


_SCALED_BASE: list[tuple[dict, np.ndarray, bool, float]] = []


def _scaled_base(count: int) -> list[tuple[dict, np.ndarray, bool, float]]:
    """(problem, exponents u, feasible, piqp's objective or inf) for the first count problems
    (computed once per session; the scales share them)."""
    if len(_SCALED_BASE) < count:
        rng = np.random.default_rng(7100)
        _SCALED_BASE.clear()
        for k in range(count):
            prob = SCALED_GENS[k % len(SCALED_GENS)](rng)
            u = rng.uniform(-1.0, 1.0, prob["A"].shape[1])
            status, x_ref = piqp_solve(prob, **ORACLE_RUNS[0])
            feasible = prob["feasible"]
            if feasible is None:
                feasible = status != "infeasible"
            f_ref = _feasible_oracle(prob, x_ref) if status == "solved" else math.inf
            _SCALED_BASE.append((prob, u, bool(feasible), f_ref))
    return _SCALED_BASE[:count]


def _column_scaled(prob: dict, s: np.ndarray) -> dict:
    q = dict(prob)
    q["A"] = prob["A"] * s
    q["C"] = prob["C"] * s
    if prob["lb"] is not None:
        q["lb"], q["ub"] = prob["lb"] / s, prob["ub"] / s
    return q


def _least_scaled_violation(prob: dict, s: np.ndarray) -> float | None:
    """min over the bounds of max_i (C_i x - d_i) / |C_i S| (HiGHS, in the unscaled x); None
    when HiGHS does not solve it."""
    from scipy.optimize import linprog

    C, d = prob["C"], prob["d"]
    n = C.shape[1]
    lb = prob["lb"] if prob["lb"] is not None else np.full(n, -np.inf)
    ub = prob["ub"] if prob["ub"] is not None else np.full(n, np.inf)
    bounds = [(lo if np.isfinite(lo) else None, hi if np.isfinite(hi) else None)
              for lo, hi in zip(lb, ub, strict=True)]
    res = linprog(np.r_[np.zeros(n), 1.0], A_ub=np.c_[C, -np.linalg.norm(C * s, axis=1)],
                  b_ub=d, bounds=[*bounds, (None, None)], method="highs",
                  options={"primal_feasibility_tolerance": 1e-10,
                           "dual_feasibility_tolerance": 1e-10})
    return float(res.fun) if res.status == 0 else None


def scaled_campaign(decades: int, count: int,
                    kind: str = "columns") -> tuple[dict[str, int], dict]:
    """The counts (SCALED_COUNTS) at columns scaled by 10^(+-decades) (kind "columns"; or
    "common", "weight": see above), and figures: "gaps" (the relative objective gaps of the
    suboptimal answers), "examples" (the first few failures)."""
    counts = dict.fromkeys(SCALED_COUNTS, 0)
    figures: dict = {"gaps": [], "examples": [], "agree": 0, "infeasible": 0, "minimax": 0}
    for k, (prob, u, feasible, f_ref) in enumerate(_scaled_base(count)):
        s = 10.0 ** (decades * (u if kind == "columns" else np.full_like(u, u[0])))
        if kind == "weight":
            q, s = dict(prob, A=prob["A"] * s[0], b=prob["b"] * s[0]), np.ones_like(u)
        else:
            q = _column_scaled(prob, s)
        res = ours(q)
        if not np.all(np.isfinite(res.x)):
            counts["non_finite"] += 1
            figures["examples"].append((k, "non-finite x"))
            continue
        if not feasible:
            if res.status != "infeasible":
                counts["missed_infeasible"] += 1
                figures["examples"].append((k, f"infeasible set answered {res.status}"))
                continue
            figures["infeasible"] += 1
            if kind == "columns" and res.iterations < MAX_ITER:
                t_ref = _least_scaled_violation(prob, s)
                if t_ref is not None:
                    figures["minimax"] += 1
                    t = minimax_violation(q, res.x)
                    if t - t_ref > max(1e-6 * abs(t_ref), 1e-9):
                        counts["minimax_worse"] += 1
                        figures["examples"].append((k, f"minimax {t:.6g} vs LP {t_ref:.6g}"))
            continue
        if res.status == "infeasible":
            counts["false_infeasible"] += 1
            figures["examples"].append((k, "feasible problem called infeasible"))
            continue
        if res.status != "optimal":
            counts["not_optimal"] += 1
            figures["examples"].append((k, f"status {res.status}"))
            continue
        x = s * res.x
        viol = _relative_violation(prob, x)
        if viol > VIOL_TOL:
            counts["violating"] += 1
            figures["examples"].append((k, f"optimal with relative violation {viol:.2e}"))
            continue
        if f_ref == math.inf:
            continue  # piqp is not right here: nothing to compare
        f = objective(prob, x)
        rel = (f - f_ref) / max(abs(f_ref), obj_floor(prob))
        if rel > OBJ_RTOL:  # confirm with piqp's tighter runs before counting
            f_best, _, _, _ = best_oracle(prob, f)
            rel = (f - min(f_ref, f_best)) / max(abs(f_ref), obj_floor(prob))
        if rel > OBJ_RTOL:
            counts["suboptimal"] += 1
            figures["gaps"].append(rel)
            figures["examples"].append((k, f"optimal {rel:.2e} above piqp's objective"))
            continue
        figures["agree"] += 1
    return counts, figures


@pytest.mark.parametrize("decades", SCALED_DECADES)
def test_column_scaled_campaign(decades):
    """python -m pytest -s -k column_scaled tests/test_controller/test_wls_piqp.py prints the
    counts per scale (docs/robustness.md quotes them)."""
    t0 = time.perf_counter()
    counts, fig = scaled_campaign(decades, SCALED_PROBLEMS)
    gaps = np.array(fig["gaps"])
    print(f"\ncolumns scaled by 1e+-{decades}, {SCALED_PROBLEMS} problems: {counts}; agreeing "
          f"with piqp {fig['agree']}, infeasible sets found {fig['infeasible']} (minimax "
          f"refereed {fig['minimax']}); suboptimal by > 50 % {int(np.sum(gaps > 0.5))}, worst "
          f"{gaps.max() if gaps.size else 0.0:.3g} ({time.perf_counter() - t0:.1f} s)")
    if decades not in MINIMAX_DECADES:
        counts.pop("minimax_worse")
    assert not any(counts.values()), f"{counts}, first: {fig['examples'][:5]}"


@pytest.mark.parametrize("kind, decades", [("common", 9), ("weight", 12)])
def test_common_factor_campaign(kind, decades):
    """The campaign's problems with every variable in one unit (up to 1e+-9 apart) or the
    objective weighted by up to 1e+-12: the same counts, all zero."""
    counts, fig = scaled_campaign(decades, SCALED_PROBLEMS, kind)
    print(f"\n{kind} factor 1e+-{decades}: {counts}; agreeing with piqp {fig['agree']}, "
          f"infeasible sets found {fig['infeasible']}")
    counts.pop("minimax_worse")
    assert not any(counts.values()), f"{counts}, first: {fig['examples'][:5]}"


def _support(c: np.ndarray, C: np.ndarray, d: np.ndarray) -> wls.WlsResult:
    """max c'f over {C f <= d} as the controller finds it (force_sets.c, polytope_support):
    min (c'f - 1e9)^2 + 1e-12 |f|^2 s.t. C f <= d."""
    A = np.vstack([c, 1e-6 * np.eye(3)])
    return wls.solve(A, [1e9, 0.0, 0.0, 0.0], None, None, C, d, 200)


def test_support_of_a_polytope_with_rounding_noise():
    """The controller's support problem on a derived force set whose facets carry 1e-17 where
    a zero was meant: the answer is the set's support (an LP's) within 1e-6 N and feasible
    within 1e-6, as with the noise removed.  (The column balance counts such entries as
    nothing; counted as entries they pulled a column 50 binary orders off and the support
    off by 0.03 N.)"""
    from scipy.optimize import linprog

    sets = json.loads((Path(__file__).resolve().parents[2] / "controller" / "airframe_sets"
                       / "fixed_tilt_hexarotor.json").read_text())
    for key in ("afs", "s0"):
        C, d = np.array(sets[key]["A"]), np.array(sets[key]["b"])
        assert np.any((np.abs(C) > 0) & (np.abs(C) < 1e-15))  # the noise is there
        for clean in (False, True):
            Cq = np.where(np.abs(C) < 1e-12, 0.0, C) if clean else C
            for axis in range(3):
                for sign in (-1.0, 1.0):
                    c = np.zeros(3)
                    c[axis] = sign
                    r = _support(c, Cq, d)
                    lp = linprog(-c, A_ub=Cq, b_ub=d, bounds=[(None, None)] * 3, method="highs")
                    assert r.status == "optimal" and lp.status == 0
                    assert abs(c @ r.x - (-lp.fun)) <= 1e-6, (key, clean, axis, sign)
                    assert np.max(Cq @ r.x - d) <= 1e-6


def test_caches_follow_the_data():
    """Between solves an instance keeps the zeros of its scaled copy of a diagonal tail, the
    column balance (while C is kept) and the rows' norms.  A sequence that switches A between
    a diagonal tail and a dense block of the same shape, and rescales A's columns by powers
    of 2 (moving the exponents), with C kept throughout, gives bit for bit what fresh
    instances give from the same start and working set."""
    rng = np.random.default_rng(99)
    n, m0, p = 6, 3, 8
    kept = wls.WlsSolver(n, m0 + n, p)
    C = rng.standard_normal((p, n))
    d = C @ rng.uniform(-0.5, 0.5, n) + rng.uniform(0.1, 1.0, p)
    lb, ub = -np.ones(n), np.ones(n)
    kept.set_data(np.vstack([rng.standard_normal((m0, n)), np.eye(n)]), np.zeros(m0 + n),
                  lb, ub, C, d)
    prev = kept.solve_stored(MAX_ITER)
    for k in range(80):
        tail = rng.standard_normal((n, n)) if k % 3 == 0 else np.diag(rng.uniform(0.1, 1.0, n))
        A = np.vstack([10.0 * rng.standard_normal((m0, n)), tail])
        if k % 4 == 1:
            A = A * 2.0 ** rng.integers(-12, 13, n)
        b = rng.standard_normal(m0 + n) * 5.0
        kept.set_data(A, b, lb, ub, None, d)
        kept.keep_rows()
        r_kept = kept.solve_stored(MAX_ITER)
        fresh = wls.WlsSolver(n, m0 + n, p)
        fresh.set_data(A, b, lb, ub, C, d)
        fresh.set_x(prev.x)
        fresh.working_set = prev.working_set
        _same(r_kept, fresh.solve_stored(MAX_ITER))
        prev = r_kept
