"""A force set as the controller's guidance uses it: the polytope {f : A f <= b} (body FRD, N)
with its vertices and an inner V-representation (:class:`Polytope`), and the operations on
polytopes that need no airframe: support functions and z extremes (scipy's LP), a canonical
facet order, comparison as sets (:func:`same_polytope`).  The sets themselves are computed
by :mod:`controller.force_sets` (the design tool) and by the controller FMU
(:mod:`controller.derived_sets`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

REL_TOL = 1e-9
"""Tolerances are this times the force scale sum_i T_max,i (about the largest |f|)."""

LP_OPTIONS = {
    "presolve": True,
    "primal_feasibility_tolerance": 1e-10,
    "dual_feasibility_tolerance": 1e-10,
}
"""HiGHS settings of every LP over force sets (scipy's linprog)."""


class EmptyForceSetError(ValueError):
    """The requested feasible force set is empty (e.g. an unattainable torque)."""


@dataclass(frozen=True, eq=False)
class Polytope:
    """{f in R^3 : A f <= b} (body FRD, N), plus its vertices and an inner V-representation.

    ``A`` rows are unit normals; the first ``n_flat`` rows are pairs of opposite normals that
    pin a degenerate (flat) set to its affine hull.  ``vertices`` are the vertices of the
    H-representation (outer approximation), ``inner_points`` are attainable forces of the
    relaxed set (LP maximisers), ``gap`` the Hausdorff distance between the two hulls (N),
    ``relative_gap`` the largest vertex distance divided by (|vertex| + FLOOR * scale).
    The true (relaxed) set lies between the two, so both bound the approximation error.
    """

    kind: str
    airframe: str
    A: Array
    b: Array
    vertices: Array
    inner_points: Array
    dimension: int
    n_flat: int
    gap: float
    relative_gap: float
    z_range: tuple[float, float]
    scale: float
    torque: Array

    @property
    def n_facets(self) -> int:
        """Number of facets (rows of A)."""
        return int(self.A.shape[0])

    @property
    def tol(self) -> float:
        """The absolute tolerance (N) of the set's checks: REL_TOL times its force scale."""
        return REL_TOL * self.scale

    def contains(self, f: ArrayLike, tol: float | None = None) -> bool | NDArray[np.bool_]:
        """Whether f (shape (3,) or (N, 3)) satisfies A f <= b + tol."""
        x = np.asarray(f, dtype=float)
        t = self.tol if tol is None else tol
        ok = np.all(x @ self.A.T <= self.b + t, axis=-1)
        return bool(ok) if x.ndim == 1 else ok

    def violation(self, f: ArrayLike) -> Array | float:
        """max(A f - b): negative inside, the largest facet violation (N) outside."""
        x = np.asarray(f, dtype=float)
        v = np.max(x @ self.A.T - self.b, axis=-1)
        return float(v) if x.ndim == 1 else v

    def clamp_z(self, f_bz: float) -> float:
        """f_bz clamped into the polytope's z range (so the slice is never empty)."""
        return min(max(float(f_bz), self.z_range[0]), self.z_range[1])

    def slice_z(self, f_bz: float, clamp: bool = True) -> tuple[Array, Array]:
        """P_xy = {(fx, fy) : A [fx, fy, f_bz] <= b} as (A_xy, b_xy) (paper eq. 22-23).

        With ``clamp`` (default) f_bz is first clamped into the z range, the prototype's fix
        for an empty slice.  Rows whose normal has no (fx, fy) part are constant; they are
        checked and dropped.  Raises EmptyForceSetError when the slice is empty.
        """
        z = self.clamp_z(f_bz) if clamp else float(f_bz)
        A_xy = self.A[:, :2]
        b_xy = self.b - self.A[:, 2] * z
        flat = np.linalg.norm(A_xy, axis=1) <= 1e-12
        if np.any(b_xy[flat] < -self.tol) or not self.z_range[0] - self.tol <= z \
                <= self.z_range[1] + self.tol:
            raise EmptyForceSetError(
                f"{self.kind} of {self.airframe}: no force with f_bz = {z:.6g} N "
                f"(z range [{self.z_range[0]:.6g}, {self.z_range[1]:.6g}] N)")
        return A_xy[~flat].copy(), b_xy[~flat].copy()

    def slice_polygon(self, f_bz: float, clamp: bool = True) -> Array:
        """Vertices (counter-clockwise, (k, 2)) of the slice P_xy; one point if degenerate."""
        A_xy, b_xy = self.slice_z(f_bz, clamp)
        return _polygon(A_xy, b_xy, self.tol)

    def inner_slice_polygon(self, f_bz: float) -> Array:
        """The slice of the inner hull conv(inner_points) at f_bz (attainable side), or an
        empty (0, 2) array when the inner hull is flat or misses the plane."""
        from scipy.spatial import ConvexHull

        if self.dimension < 3:
            return np.zeros((0, 2))
        eq = ConvexHull(self.inner_points).equations
        A, b = eq[:, :3], -eq[:, 3]
        A_xy, b_xy = A[:, :2], b - A[:, 2] * float(f_bz)
        flat = np.linalg.norm(A_xy, axis=1) <= 1e-12
        if np.any(b_xy[flat] < 0.0):
            return np.zeros((0, 2))
        try:
            return _polygon(A_xy[~flat], b_xy[~flat], self.tol)
        except EmptyForceSetError:
            return np.zeros((0, 2))

    @cached_property
    def volume(self) -> float:
        """Volume (N^3) of the outer polytope."""
        return _volume(self.vertices)

    @cached_property
    def inner_volume(self) -> float:
        """Volume (N^3) of the inner hull (attainable forces)."""
        return _volume(self.inner_points)


def _volume(points: Array) -> float:
    from scipy.spatial import ConvexHull, QhullError

    try:
        return float(ConvexHull(points).volume)
    except (QhullError, ValueError):  # flat or too few points
        return 0.0


def _polygon(A: Array, b: Array, tol: float) -> Array:
    """Vertices of a bounded 2-D polygon {x : A x <= b}, counter-clockwise.

    A polygon thinner than ``tol`` (a point or a segment, e.g. a slice through a vertex) is
    returned as its extreme points along x and y.
    """
    from scipy.optimize import linprog
    from scipy.spatial import ConvexHull

    # Chebyshev centre: max r s.t. A x + r |a_i| <= b + tol (tol: not empty by round-off)
    norms = np.linalg.norm(A, axis=1)
    res = linprog([0.0, 0.0, -1.0], A_ub=np.column_stack([A, norms]), b_ub=b + tol,
                  bounds=[(None, None), (None, None), (0.0, None)], method="highs-ds",
                  options=LP_OPTIONS)
    if res.status != 0:
        raise EmptyForceSetError("the slice polygon is empty")
    x, r = res.x[:2], float(res.x[2])
    if r > 2.0 * tol:
        verts = outer_vertices(A, b, x)
        return verts[ConvexHull(verts).vertices]
    pts = []
    for c in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
        for rhs in (b, b + tol):
            q = linprog(-np.array(c), A_ub=A, b_ub=rhs, bounds=(None, None),
                        method="highs-ds", options=LP_OPTIONS)
            if q.status == 0:
                pts.append(q.x + 0.0)
                break
    return np.unique(np.array(pts).reshape(-1, 2), axis=0)


def canonical_facets(A: Array, b: Array, n_flat: int = 0) -> tuple[Array, Array]:
    """The facets (A, b) in a canonical order, so that round-off does not permute them.

    The first ``n_flat`` rows (pairs of opposite normals, see :class:`Polytope`) stay first,
    each pair ordered and the pairs sorted like the others; the remaining rows are sorted
    lexicographically by their unit normal rounded to :data:`REL_TOL` (so that components
    equal up to round-off, e.g. 0 and 1e-17, tie) and then by their offset.
    """
    A, b = np.asarray(A, dtype=float), np.asarray(b, dtype=float)
    decimals = round(-math.log10(REL_TOL))  # 9
    key = np.round(A / np.linalg.norm(A, axis=1, keepdims=True), decimals) + 0.0  # no -0.0
    # flat pairs: the lexicographically larger normal of each pair first, then pairs sorted
    pairs = []
    for j in range(0, n_flat, 2):
        first, second = (j, j + 1) if tuple(key[j]) >= tuple(key[j + 1]) else (j + 1, j)
        pairs.append((tuple(key[first]), first, second))
    flat = [r for _, first, second in sorted(pairs) for r in (first, second)]
    rest = n_flat + np.lexsort((b[n_flat:], *key[n_flat:].T[::-1]))  # last key is primary
    order = np.concatenate([np.array(flat, dtype=int), rest])
    return A[order], b[order]


def same_polytope(A1: ArrayLike, b1: ArrayLike, A2: ArrayLike, b2: ArrayLike,
                  rtol: float = REL_TOL, names: tuple[str, str] = ("the first set",
                                                                   "the second set"),
                  ) -> tuple[bool, str]:
    """Whether {x : A1 x <= b1} and {x : A2 x <= b2} are the same set: (same, reason).

    Compared as sets, never row by row: each set must lie inside every facet of the other,
    i.e. its support function h(a_i) = max a_i . x at each unit facet normal a_i of the other
    set stays below that facet's offset b_i / |a_i| + tol (an LP per facet; for bounded
    polytopes this is exact set equality up to tol).  Facet order, scaling of a row, and
    redundant facets do not matter.  ``tol = rtol * size``, with size the largest |x_k| over
    both sets (their bounding boxes; N, like every polytope here).  ``reason`` names the worst
    violated facet each way, by how much and along which normal.
    """
    sets = []
    for A, b in ((A1, b1), (A2, b2)):
        A, b = np.atleast_2d(np.asarray(A, dtype=float)), np.asarray(b, dtype=float).ravel()
        if A.shape != (b.size, A.shape[1]):
            return False, f"inconsistent shapes: A {A.shape}, b {b.shape}"
        sets.append((A, b))
    (A1, b1), (A2, b2) = sets
    if A1.shape[1] != A2.shape[1]:
        return False, f"dimension {A1.shape[1]} of {names[0]} differs from {A2.shape[1]}"
    axes = np.vstack([np.eye(A1.shape[1]), -np.eye(A1.shape[1])])
    reach = [[set_support(A, b, c) for c in axes] for A, b in sets]
    empty = [any(h is None for h in r) for r in reach]
    if empty[0] or empty[1]:
        if empty[0] and empty[1]:
            return True, "both sets are empty"
        return False, f"{names[0] if empty[0] else names[1]} is empty, the other is not"
    size = max(abs(h) for r in reach for h in r if h is not None)
    if not math.isfinite(size):
        return False, "an unbounded set cannot be compared with a tolerance scaled to it"
    tol = rtol * size
    problems = []
    for (A, b), (Ao, bo), who, other in (((A1, b1), (A2, b2), names[0], names[1]),
                                         ((A2, b2), (A1, b1), names[1], names[0])):
        norms = np.linalg.norm(Ao, axis=1)
        worst, at = -math.inf, -1
        for i in np.flatnonzero(norms > 0.0):
            h = set_support(A, b, Ao[i] / norms[i])
            excess = math.inf if h is None else h - bo[i] / norms[i]
            if excess > worst:
                worst, at = excess, int(i)
        if worst > tol:
            n = Ao[at] / norms[at]
            problems.append(
                f"{who} reaches {worst:.3g} N beyond facet {at} of {other} (normal "
                f"[{', '.join(f'{x:.4f}' for x in n)}], offset {bo[at] / norms[at]:.6g} N)")
    if problems:
        return False, "; ".join(problems) + f" (tolerance {tol:.2g} N)"
    return True, f"same set within {tol:.2g} N ({A1.shape[0]} and {A2.shape[0]} facets)"


def set_support(A: Array, b: Array, c: Array) -> float | None:
    """max c . x over {x : A x <= b}: inf if unbounded, None if empty."""
    from scipy.optimize import linprog

    res = linprog(-c, A_ub=A, b_ub=b, bounds=(None, None), method="highs-ds",
                  options=LP_OPTIONS)
    if res.status == 2:
        return None
    if res.status == 3:
        return math.inf
    if res.status != 0:
        raise RuntimeError(f"support LP failed ({res.status}): {res.message}")
    return -float(res.fun)


def dedupe(points: Array, tol: float) -> Array:
    """The points without those within tol of an earlier one."""
    out: list[Array] = []
    for p in points:
        if not any(float(np.max(np.abs(p - q))) <= tol for q in out):
            out.append(p)
    return np.array(out).reshape(-1, 3)


def _lp_extreme(A: Array, b: Array, c: Array, minimise: bool) -> float:
    from scipy.optimize import linprog

    res = linprog(c if minimise else -c, A_ub=A, b_ub=b, bounds=(None, None),
                  method="highs-ds", options=LP_OPTIONS)
    if res.status != 0:
        raise RuntimeError(f"polytope LP failed ({res.status}): {res.message}")
    return float(res.fun) + 0.0 if minimise else -float(res.fun) + 0.0


def frozen(a: Array) -> Array:
    """A read-only float copy of a (a polytope's arrays never change)."""
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


def z_extremes(A: ArrayLike, b: ArrayLike) -> tuple[float, float]:
    """(min, max) of f_z over {f : A f <= b} (N)."""
    A, b = np.atleast_2d(np.asarray(A, dtype=float)), np.asarray(b, dtype=float).ravel()
    ez = np.array([0.0, 0.0, 1.0])
    return _lp_extreme(A, b, ez, minimise=True), _lp_extreme(A, b, ez, minimise=False)


def outer_vertices(A: Array, b: Array, interior: Array) -> Array:
    """Vertices of {x : A x <= b} (2-D or 3-D, bounded, interior point given)."""
    return intersection(A, b, interior)[0]


def intersection(A: Array, b: Array, interior: Array) -> tuple[Array, int]:
    """(vertices, number of non-redundant halfspaces) of {x : A x <= b}."""
    from scipy.spatial import HalfspaceIntersection

    hs = HalfspaceIntersection(np.column_stack([A, -b]), interior)
    active = {int(i) for facet in hs.dual_facets for i in facet}
    return np.asarray(hs.intersections, dtype=float), len(active)
