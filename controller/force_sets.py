"""Attainable force set (AFS) and feasible force set S(tau) as bounded H-representations.

Paper section II-B, eq. (5)-(6): with u = [f_b1; ...; f_bn] the stacked per-rotor body forces,

    AFS     = { B1 u : u in U }
    S(tau)  = { B1 u : u in U, B2 u = tau }        (S(0): forces needing no torque)

where U = U_1 x ... x U_n and U_i = { T t_i(alpha, beta) : T in [k_t w_min^2, k_t w_max^2],
(alpha, beta) in the servo box } is what rotor i can produce.  Every model quantity (B, the
thrust directions t_i) comes from the C core through :mod:`plant.effectiveness`; nothing here
re-implements the rotor kinematics.

Method (deterministic; no randomness anywhere)
----------------------------------------------
* U_i is not convex (a spherical patch of thrust directions times a thrust interval).  Like the
  paper, which treats S(0) as a polyhedron, we work with its convex hull: the sets below are
  the *convex relaxation* of eq. (5)-(6).  Every force that real actuator states produce lies
  inside; not every point inside is exactly reachable (the inner allocation absorbs that).
* Inner model (for linear programs): conv U_i is sampled by a fixed ``grid x grid`` lattice of
  (alpha, beta) over the servo box (one point for a fixed rotor), scaled by T_max, plus the
  same directions at T_min (or the origin, written as sum(lambda) <= 1, when T_min = 0).
* Support function of the sampled set, h(c) = max c . f, by one HiGHS LP per direction c
  (variables: the convex weights lambda; equality B2 u = tau).  The LP maximisers are genuine
  points of the (relaxed) set: they form the *inner* V-representation.
* Outer bound per direction, by weak Lagrange duality with the LP's multipliers y:
  h_true(c) <= y . tau + sum_i max_{u_i in U_i} (B1_i^T c - B2_i^T y) . u_i, each rotor term
  maximised over the *continuous* servo box (bounded L-BFGS-B on the C thrust direction,
  started from every grid local maximum close to the best grid value).  So
  {f : c_j . f <= b_j} contains every force of real actuator states, not only of the sampled
  ones (tests/test_controller/test_force_sets.py checks this against nonlinear maximisation).
  For the AFS
  (no equality) the bound is the exact support function and its maximisers are real
  actuator states.
* Directions: a sandwich (Kamenev-style) refinement, seeded with the 6 axes and the 8 cube
  diagonals.  Each step takes the facet of the inner hull beyond which the outer polytope
  (built from the bounds b_j) sticks out most, and adds its normal as a new direction.  The
  excess is measured relative to the force magnitude, |v| + FLOOR * scale, so that slices at
  every thrust level get about the same relative accuracy rather than the large high-thrust
  cap taking most facets (for the paper hexacopter this halves the error of the hover slice
  for a slightly larger absolute gap).  Directions are added until ``n_directions`` of them
  are non-redundant (default and cap: :data:`MAX_FACETS` = 64); redundant facets (removing
  them does not enlarge the polytope, checked by LP) are dropped, so the count is <= the cap.
* Degenerate sets (e.g. the quadrotor: S(0) is a vertical segment) are detected by LPs along
  the directions the LP maximisers do not span; such a set is written with explicit pairs of
  opposite facets (an equality as two inequalities) plus facets in its affine hull, so the
  H-representation stays bounded and exact in the flat directions.
* An empty S(tau) raises :class:`EmptyForceSetError`; an LP or Qhull failure raises
  :class:`ForceSetError` (a RuntimeError), one line naming the airframe's file: Qhull's own
  report (pages of options and input) never reaches the user.
* Facets are returned in a canonical order (:func:`canonical_facets`: sorted by normal, then
  offset), so round-off differences between library versions do not permute them; compare
  two polytopes as sets with :func:`same_polytope` (support LPs, tolerance scaled to the set),
  never row by row.

Rows of ``A`` are unit vectors (body FRD, dimensionless), ``b`` is in newtons.  The paper
hexacopter's S(0) (64 facets) is about 1.5 s.  It is the oracle of the controller FMU's own
derivation (:mod:`controller.derived_sets`); :mod:`controller.plots_force_sets` draws Fig. 3.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from controller.polytope import (
    LP_OPTIONS,
    REL_TOL,
    EmptyForceSetError,
    Polytope,
    canonical_facets,
    dedupe,
    frozen,
    intersection,
    outer_vertices,
    z_extremes,
)
from plant.airframe import ROTOR_THRUST_LIMITS, Airframe, load_airframe
from plant.effectiveness import thrust_direction

Array = NDArray[np.float64]

MAX_FACETS = 64
"""Cap on the number of facets of every polytope (the controller FMU's parameter size)."""

DEFAULT_GRID = 17
"""Samples per servo axis in the inner model (5 deg steps over the paper's +-40 deg)."""


FLOOR = 0.05
"""Floor of the relative error measure of the direction refinement, times the force scale."""


class ForceSetError(RuntimeError):
    """A force set the numerics (an LP, Qhull) could not compute, with the airframe named."""


# ---------------------------------------------------------------------------
# Actuator model (all kinematics through the C core)


@dataclass(frozen=True)
class _Rotor:
    """Admissible forces of one rotor: T t(alpha, beta), box limits, thrust range."""

    gamma: float
    alpha: tuple[float, float]
    beta: tuple[float, float]
    t_min: float
    t_max: float
    grid_alpha: Array  # (na,)
    grid_beta: Array  # (nb,)
    directions: Array  # (na*nb, 3) unit thrust directions on the grid, alpha-major

    @property
    def fixed(self) -> bool:
        return self.grid_alpha.size == 1 and self.grid_beta.size == 1

    def direction(self, alpha: float, beta: float) -> Array:
        return thrust_direction(alpha, beta, self.gamma)

    def generators(self) -> Array:
        """Points whose convex hull is the inner model of conv U_i (origin implicit)."""
        pts = [self.t_max * self.directions]
        if self.t_min > 0.0:
            pts.append(self.t_min * self.directions)
        return np.vstack(pts)

    def support(self, d: Array) -> tuple[float, Array]:
        """max over the continuous box and thrust range of d . u, and the maximising u."""
        table = self.directions @ d
        k = int(np.argmax(table))
        best_s = float(table[k])
        best_ab = (float(self.grid_alpha[k // self.grid_beta.size]),
                   float(self.grid_beta[k % self.grid_beta.size]))
        if not self.fixed:
            for ab in self._starts(table, float(np.linalg.norm(d))):
                s, a_b = self._refine(d, ab)
                if s > best_s:
                    best_s, best_ab = s, a_b
        t = self.t_max if best_s >= 0.0 else self.t_min
        return t * best_s, t * self.direction(*best_ab)

    def _starts(self, table: Array, dnorm: float) -> list[tuple[float, float]]:
        """Grid local maxima close enough to the best node to hide the continuous maximum."""
        na, nb = self.grid_alpha.size, self.grid_beta.size
        t2 = table.reshape(na, nb)
        pad = np.pad(t2, 1, mode="constant", constant_values=-np.inf)
        local = ((t2 >= pad[:-2, 1:-1]) & (t2 >= pad[2:, 1:-1])
                 & (t2 >= pad[1:-1, :-2]) & (t2 >= pad[1:-1, 2:]))
        step = max(_step(self.grid_alpha), _step(self.grid_beta))
        margin = dnorm * step * step
        idx = np.flatnonzero(local.reshape(-1) & (table >= table.max() - margin))
        idx = idx[np.argsort(-table[idx], kind="stable")][:4]
        return [(float(self.grid_alpha[k // nb]), float(self.grid_beta[k % nb])) for k in idx]

    def _refine(self, d: Array, start: tuple[float, float]) -> tuple[float, tuple[float, float]]:
        from scipy.optimize import minimize

        def neg(x: Array) -> float:
            return -float(d @ self.direction(float(x[0]), float(x[1])))

        res = minimize(neg, np.array(start), method="L-BFGS-B",
                       bounds=[self.alpha, self.beta],
                       options={"ftol": 1e-15, "gtol": 1e-11, "maxiter": 200})
        x = np.clip(res.x, [self.alpha[0], self.beta[0]], [self.alpha[1], self.beta[1]])
        a, b = float(x[0]), float(x[1])
        return float(d @ self.direction(a, b)), (a, b)


def _step(grid: Array) -> float:
    return float(grid[1] - grid[0]) if grid.size > 1 else 0.0


def _axis_grid(lo: float, hi: float, n: int) -> Array:
    return np.array([lo]) if hi <= lo else np.linspace(lo, hi, n)


def _rotors(af: Airframe, grid: int) -> list[_Rotor]:
    rotors = []
    t_min, t_max = af.k_t * af.omega_min**2, af.k_t * af.omega_max**2
    for i in range(af.n_rotors):
        a_lo, a_hi = (float(x) for x in af.alpha_limits[i])
        b_lo, b_hi = (float(x) for x in af.beta_limits[i])
        ga, gb = _axis_grid(a_lo, a_hi, grid), _axis_grid(b_lo, b_hi, grid)
        dirs = np.array([thrust_direction(float(a), float(b), float(af.gamma[i]))
                         for a in ga for b in gb])
        rotors.append(_Rotor(float(af.gamma[i]), (a_lo, a_hi), (b_lo, b_hi), t_min, t_max,
                             ga, gb, dirs))
    return rotors


# ---------------------------------------------------------------------------
# Support-function oracles


@dataclass
class _Oracle:
    """Support of the set in direction c: (inner value, inner point, outer bound)."""

    rotors: list[_Rotor]
    b1: list[Array]  # per rotor 3x3 blocks of B1
    b2: list[Array]  # per rotor 3x3 blocks of B2
    torque: Array | None  # None: the AFS (no torque equality)
    scale: float
    cache: dict[bytes, tuple[float, Array, Array]] = field(default_factory=dict)
    bounds: dict[bytes, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        gens = [r.generators() for r in self.rotors]
        self._sizes = [g.shape[0] for g in gens]
        # force and torque of each generator point (columns = LP variables)
        self._F = np.hstack([b1 @ g.T for b1, g in zip(self.b1, gens, strict=True)])
        self._M = np.hstack([b2 @ g.T for b2, g in zip(self.b2, gens, strict=True)])
        n, nv = len(self.rotors), self._F.shape[1]
        rows = np.zeros((n, nv))
        start = 0
        for i, s in enumerate(self._sizes):
            rows[i, start:start + s] = 1.0
            start += s
        self._sum_rows = rows
        self._pinned = self.rotors[0].t_min > 0.0  # sum(lambda) = 1 instead of <= 1

    def _lp(self, c: Array) -> tuple[float, Array, Array]:
        """max c . f over the sampled (inner) set: value, maximiser, equality multipliers."""
        from scipy.optimize import linprog

        n = len(self.rotors)
        kw: dict[str, object] = {}
        if self._pinned:
            kw["A_eq"] = np.vstack([self._M, self._sum_rows]) if self.torque is not None \
                else self._sum_rows
            kw["b_eq"] = np.concatenate([self.torque, np.ones(n)]) if self.torque is not None \
                else np.ones(n)
        else:
            kw["A_ub"], kw["b_ub"] = self._sum_rows, np.ones(n)
            if self.torque is not None:
                kw["A_eq"], kw["b_eq"] = self._M, self.torque
        res = linprog(-(c @ self._F), bounds=(0.0, None), method="highs-ds",
                      options=LP_OPTIONS, **kw)
        if res.status == 2:
            raise EmptyForceSetError(
                f"S(tau) is empty for tau = {self.torque} N m: no admissible rotor forces "
                "produce this torque")
        if res.status != 0:
            raise RuntimeError(f"force-set LP failed ({res.status}): {res.message}")
        y = np.zeros(3)
        if self.torque is not None:
            y = -np.asarray(res.eqlin.marginals[:3], dtype=float)
        return -float(res.fun), self._F @ res.x, y

    def support(self, c: Array) -> tuple[float, Array, Array]:
        """(inner value, inner point, dual multipliers), cached per direction."""
        key = c.tobytes()
        if key not in self.cache:
            if self.torque is None:
                value, point = self.exact_afs(c)
                self.cache[key] = (value, point, np.zeros(3))
            else:
                self.cache[key] = self._lp(c)
        return self.cache[key]

    def exact_afs(self, c: Array) -> tuple[float, Array]:
        total, point = 0.0, np.zeros(3)
        for r, b1 in zip(self.rotors, self.b1, strict=True):
            s, u = r.support(b1.T @ c)
            total += s
            point = point + b1 @ u
        return total, point

    def outer_bound(self, c: Array) -> float:
        """Upper bound of max c . f over the continuous (relaxed) set, by weak duality."""
        key = c.tobytes()
        if key not in self.bounds:
            value, _, y = self.support(c)
            total = value
            if self.torque is not None:
                total = float(y @ self.torque)
                for r, b1, b2 in zip(self.rotors, self.b1, self.b2, strict=True):
                    total += r.support(b1.T @ c - b2.T @ y)[0]
                # never below the attained inner value (guards LP round-off)
                total = max(total, value)
            self.bounds[key] = total
        return self.bounds[key]


def _make_oracle(af: Airframe, torque: Array | None, grid: int) -> _Oracle:
    if grid < 2:
        raise ValueError(f"grid must be >= 2 samples per servo axis, got {grid}")
    rotors = _rotors(af, grid)
    B = af.rotor_set().B()
    n = af.n_rotors
    b1 = [np.ascontiguousarray(B[:3, 3 * i:3 * i + 3]) for i in range(n)]
    b2 = [np.ascontiguousarray(B[3:, 3 * i:3 * i + 3]) for i in range(n)]
    scale = sum(r.t_max * float(np.linalg.norm(m, 2)) for r, m in zip(rotors, b1, strict=True))
    if not scale > 0.0:
        raise ValueError(f"{af.name}: rotors produce no force (T_max = 0)")
    return _Oracle(rotors, b1, b2, torque, scale)


# ---------------------------------------------------------------------------
# Geometry helpers


def _unit(v: ArrayLike) -> Array:
    a = np.asarray(v, dtype=float)
    return a / np.linalg.norm(a)


def _seed_directions() -> list[Array]:
    axes = [np.array(v, dtype=float) for v in
            ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))]
    diag = [_unit((sx, sy, sz)) for sz in (1, -1) for sy in (1, -1) for sx in (1, -1)]
    return axes + diag


def _affine_hull(oracle: _Oracle) -> tuple[Array, Array, Array]:
    """(p0, Q, W): the set lies in p0 + span(Q); W spans the flat (zero-width) directions."""
    tol = REL_TOL * oracle.scale
    pts = [oracle.support(c)[1] for c in _seed_directions()[:6]]
    for _ in range(4):
        P = np.array(pts)
        p0 = P.mean(axis=0)
        _, s, vt = np.linalg.svd(P - p0)
        k = int(np.sum(s > tol))
        if k == 3:
            return p0, np.eye(3), np.zeros((3, 0))
        Q, W = vt[:k].T, vt[k:].T
        wide = False
        for w in W.T:
            hi, p_hi, _ = oracle.support(np.ascontiguousarray(w))
            lo, p_lo, _ = oracle.support(np.ascontiguousarray(-w))
            if hi + lo > tol:
                pts += [p_hi, p_lo]
                wide = True
        if not wide:
            return p0, Q, W
    raise RuntimeError("could not determine the affine hull of the force set")


def _circle(k: int) -> list[Array]:
    return [np.array([math.cos(2 * math.pi * j / k), math.sin(2 * math.pi * j / k)])
            for j in range(k)]


def _sandwich(oracle: _Oracle, p0: Array, Q: Array, budget: int,
              label: str = "force set") -> list[Array]:
    """Directions (in the reduced coordinates of span Q) chosen by the sandwich scheme.

    Directions are added until ``budget`` of them are non-redundant (facets made redundant
    by later ones do not count), or the outer and inner polytopes meet.  A progress bar
    (facets found of ``budget``) shows on a terminal and stays quiet in pipes.
    """
    from tqdm import tqdm

    with tqdm(total=budget, desc=label, unit="facet", leave=False, disable=None) as bar:
        return _sandwich_steps(oracle, p0, Q, budget, bar)


def _sandwich_steps(oracle: _Oracle, p0: Array, Q: Array, budget: int,
                    bar: Any) -> list[Array]:
    from scipy.spatial import ConvexHull, QhullError

    k = Q.shape[1]
    if k == 0:
        return []
    if k == 1:
        return [np.array([1.0]), np.array([-1.0])][:budget]
    seeds = _seed_directions() if k == 3 else _circle(8)
    dirs = [s for s in seeds[:budget]]
    tol = REL_TOL * oracle.scale

    def sup(a: Array) -> tuple[float, Array]:
        """(outer bound, inner point) in reduced coordinates."""
        c = np.ascontiguousarray(Q @ a)
        return oracle.outer_bound(c) - float(c @ p0), Q.T @ (oracle.support(c)[1] - p0)

    while len(dirs) < 4 * budget:
        vals, pts = zip(*(sup(a) for a in dirs), strict=True)
        inner = np.array(pts)
        try:
            hull = ConvexHull(inner)
        except QhullError:  # the inner points do not span the hull yet: keep the seeds
            break
        centre = inner[hull.vertices].mean(axis=0)
        outer, active = intersection(np.array(dirs), np.array(vals), centre)
        bar.update(max(0, min(active, budget) - bar.n))
        if active >= budget:
            break
        # the inner facet along which the outer polytope sticks out most, measured relative
        # to the force magnitude (floor FLOOR * scale): slices at every thrust level get
        # about the same relative accuracy instead of the large high-thrust cap taking all
        weight = 1.0 / (np.linalg.norm(outer @ Q.T + p0, axis=1) + FLOOR * oracle.scale)
        best, best_gap = None, 0.0
        for eq in hull.equations:
            n, off = eq[:-1], -eq[-1]
            excess = outer @ n - off
            if float(np.max(excess)) <= tol:
                continue
            gap = float(np.max(excess * weight))
            if gap > best_gap and not any(np.allclose(n, d, rtol=0, atol=1e-12) for d in dirs):
                best, best_gap = n, gap
        if best is None:
            break
        dirs.append(np.ascontiguousarray(best / np.linalg.norm(best)))
    return dirs


def _drop_redundant(A: Array, b: Array, keep: int, tol: float) -> tuple[Array, Array]:
    """Remove rows (from index ``keep`` on) whose removal does not enlarge the polytope."""
    from scipy.optimize import linprog

    rows = list(range(A.shape[0]))
    for j in range(A.shape[0] - 1, keep - 1, -1):
        others = [r for r in rows if r != j]
        res = linprog(-A[j], A_ub=A[others], b_ub=b[others], bounds=(None, None),
                      method="highs-ds", options=LP_OPTIONS)
        if res.status == 0 and -res.fun <= b[j] + tol:
            rows = others
    return A[rows], b[rows]


def _distances(outer: Array, inner: Array) -> Array:
    """Distance of each outer vertex to conv(inner) (simplex-weighted NNLS projection).

    With conv(inner) inside conv(outer), the largest one is their Hausdorff distance.
    """
    from scipy.optimize import nnls

    P = inner.T
    weight = 1e3 * (1.0 + float(np.abs(inner).max()))
    M = np.vstack([P, weight * np.ones((1, P.shape[1]))])
    out = np.zeros(outer.shape[0])
    for j, v in enumerate(outer):
        mu, _ = nnls(M, np.concatenate([v, [weight]]), maxiter=50 * M.shape[1])
        out[j] = float(np.linalg.norm(P @ mu - v))
    return out


# ---------------------------------------------------------------------------
# Public API


def _build(af: Airframe, torque: Array | None, n_directions: int, grid: int) -> Polytope:
    """The polytope; a failure of its LPs or of Qhull as one ForceSetError line that names
    the airframe's file (Qhull's message is pages long)."""
    if not 6 <= n_directions <= MAX_FACETS:
        raise ValueError(f"n_directions must be in 6..{MAX_FACETS}, got {n_directions}")
    what = "attainable force set" if torque is None else "feasible force set S(tau)"
    where = f"{af.source or af.name}: the {what} of airframe '{af.name}'"
    # an airframe made in code skips the file's checks: Qhull must never see numbers that
    # it cannot resolve (a thrust of 1e-296 N crashes it, not only makes it fail)
    t_max, (lo, hi) = af.k_t * (af.omega_max * af.omega_max), ROTOR_THRUST_LIMITS
    if not lo <= t_max <= hi:
        raise ForceSetError(f"{where}: a rotor's maximum thrust k_t omega_max^2 = "
                            f"{t_max:.5g} N is outside [{lo:g}, {hi:g}] N")
    try:
        return _build_polytope(af, torque, n_directions, grid)
    except RuntimeError as e:  # scipy's QhullError is one, and so are the LP failures
        lines = [line.strip() for line in str(e).splitlines() if line.strip()]
        reason = lines[0] if lines else type(e).__name__
        raise ForceSetError(f"{where} could not be computed ({reason})") from None


def _build_polytope(af: Airframe, torque: Array | None, n_directions: int,
                    grid: int) -> Polytope:
    oracle = _make_oracle(af, torque, grid)
    tol = REL_TOL * oracle.scale
    p0, Q, W = _affine_hull(oracle)
    k = Q.shape[1]
    flat_dirs = [s * w for w in W.T for s in (1.0, -1.0)]
    what = "attainable force set" if torque is None else "S(tau)"
    dirs_red = _sandwich(oracle, p0, Q, n_directions - len(flat_dirs),
                         label=f"{af.name}: {what}")
    dirs = [np.ascontiguousarray(w) for w in flat_dirs] + \
        [np.ascontiguousarray(Q @ a) for a in dirs_red]
    A = np.array(dirs, dtype=float).reshape(-1, 3) + 0.0  # + 0.0: no negative zeros
    b = np.array([oracle.outer_bound(c) for c in A]) + 0.0  # + 0.0: no negative zeros
    inner = np.array([oracle.support(c)[1] for c in A]).reshape(-1, 3)
    n_flat = len(flat_dirs)
    if k >= 2:
        A, b = _drop_redundant(A, b, n_flat, tol)
        # the cap is a hard limit: dropping facets only enlarges an outer approximation
        A, b = A[:n_directions], b[:n_directions]
    # vertices of the outer polytope, in the affine hull's coordinates
    if k == 3:
        centre = inner.mean(axis=0)
        verts = outer_vertices(A, b, centre)
    elif k == 2:
        Ar = A[n_flat:] @ Q
        br = b[n_flat:] - A[n_flat:] @ p0
        verts = p0 + outer_vertices(Ar, br, Q.T @ (inner.mean(axis=0) - p0)) @ Q.T
    elif k == 1:
        q = Q[:, 0]
        hi = b[n_flat] - float(A[n_flat] @ p0)
        lo = -(b[n_flat + 1] - float(A[n_flat + 1] @ p0))
        verts = np.array([p0 + hi * q, p0 + lo * q])
    else:
        verts = p0.reshape(1, 3)
    verts = dedupe(verts, tol)
    z_lo, z_hi = z_extremes(A, b)
    inner_pts = dedupe(inner, tol)
    dist = _distances(verts, inner_pts)
    A, b = canonical_facets(A, b, n_flat)
    rel = dist / (np.linalg.norm(verts, axis=1) + FLOOR * oracle.scale)
    return Polytope(
        kind="AFS" if torque is None else "S(tau)",
        airframe=af.name,
        A=frozen(A), b=frozen(b), vertices=frozen(verts), inner_points=frozen(inner_pts),
        dimension=k, n_flat=n_flat, gap=float(dist.max()),
        relative_gap=float(rel.max()), z_range=(z_lo, z_hi), scale=oracle.scale,
        torque=frozen(np.zeros(3) if torque is None else torque),
    )


def facet_problem(airframe: Airframe | str | Path, A: ArrayLike, b: ArrayLike,
                  torque: Sequence[float] | Array | None = None, grid: int = DEFAULT_GRID,
                  what: str = "the set") -> str | None:
    """Why {f : A f <= b} is not what this module computes for the airframe's AFS
    (``torque`` None) or S(torque), whatever facet normals it was given (None: it is).

    Each offset must be the outer bound computed here for its normal (within REL_TOL of the
    set's size).  That makes the set valid (it holds every force of real actuator states)
    and exactly as tight as computed, without asking for the same normals: the refinement
    picks each next normal by the largest of several near-equal excesses, so another CPU or
    library version can pick another one (the paper hexacopter's AFS of two machines
    differs by 0.96 N where their offsets agree to 1e-13 N).  An empty set (no rows) must
    be empty here too."""
    af = _airframe(airframe)
    tau = None if torque is None else np.ascontiguousarray(np.asarray(torque, dtype=float))
    oracle = _make_oracle(af, tau, grid)
    A, b = np.atleast_2d(np.asarray(A, dtype=float)), np.asarray(b, dtype=float).ravel()
    try:
        oracle.support(np.array([0.0, 0.0, -1.0]))
    except EmptyForceSetError:
        return None if b.size == 0 else f"{what} has {b.size} facets but is empty here"
    if b.size == 0:
        return f"{what} is empty, but not here"
    tol = REL_TOL * oracle.scale
    worst, at, here = -1.0, -1, 0.0
    for j, a in enumerate(A):
        norm = float(np.linalg.norm(a))
        if not norm > 0.0:
            return f"{what}: facet {j} has no normal"
        bound = oracle.outer_bound(np.ascontiguousarray(a / norm))
        off = abs(b[j] / norm - bound)
        if off > worst:
            worst, at, here = off, j, bound
    if worst > tol:
        n = A[at] / np.linalg.norm(A[at])
        return (f"{what}: facet {at} (normal [{', '.join(f'{x:.4f}' for x in n)}]) has "
                f"offset {b[at] / np.linalg.norm(A[at]):.9g} N where the forces reach "
                f"{here:.9g} N here (tolerance {tol:.2g} N)")
    return None


def _airframe(airframe: Airframe | str | Path) -> Airframe:
    return airframe if isinstance(airframe, Airframe) else load_airframe(airframe)


def attainable_force_set(
    airframe: Airframe | str | Path,
    n_directions: int = MAX_FACETS,
    grid: int = DEFAULT_GRID,
) -> Polytope:
    """AFS = B1 U (paper section II-B) as an outer H-representation with <= n_directions facets."""
    return _build(_airframe(airframe), None, n_directions, grid)


def feasible_force_set(
    airframe: Airframe | str | Path,
    torque: Sequence[float] | Array = (0.0, 0.0, 0.0),
    n_directions: int = MAX_FACETS,
    grid: int = DEFAULT_GRID,
) -> Polytope:
    """S(tau) of paper eq. (5)-(6) (default tau = 0) as an outer H-representation.

    At most ``n_directions`` (<= :data:`MAX_FACETS`) facets, in the canonical order of
    :func:`canonical_facets`; deterministic (same inputs give bit-identical arrays; other
    library versions may move the numbers by round-off: compare with :func:`same_polytope`).
    Raises EmptyForceSetError when no admissible input gives tau.
    """
    tau = np.asarray(torque, dtype=float).reshape(-1)
    if tau.size != 3 or not np.all(np.isfinite(tau)):
        raise ValueError(f"torque must be 3 finite numbers (N m), got {torque!r}")
    return _build(_airframe(airframe), np.ascontiguousarray(tau), n_directions, grid)


def hover_force(airframe: Airframe | str | Path) -> Array:
    """Body force at hover with zero attitude, [0, 0, -m g] (FRD)."""
    af = _airframe(airframe)
    return np.array([0.0, 0.0, -af.mass * af.gravity])


def is_feasible(polytope: Polytope, f_b: ArrayLike) -> bool:
    """Whether the body force f_b lies in the polytope (within its tolerance)."""
    return bool(polytope.contains(np.asarray(f_b, dtype=float).reshape(3)))
