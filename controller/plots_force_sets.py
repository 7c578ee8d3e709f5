"""Figure like the paper's Fig. 3: the attainable force set vs S(0) and the hover slice P_xy.

    python -m controller.plots_force_sets [AIRFRAME] [OUT.png]

Left: the attainable force set, AFS (translucent green) and S(tau = 0) (blue edges) in body
FRD, f_bz axis pointing down so that thrust is drawn upwards, with the hover plane slice P_xy
of S(0) in red.
Right: P_xy = S(0) cut by f_bz = -m g (hover, zero attitude) as a polygon (the outer
H-representation the controller uses), with the slices of the AFS and of the inner hull
(attainable forces; the exact set lies between the two) for reference.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import cast

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d import Axes3D
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from controller.force_sets import (
    Polytope,
    attainable_force_set,
    feasible_force_set,
    hover_force,
)
from plant.airframe import Airframe, load_airframe

GREEN, BLUE, RED = "#2ca02c", "#1f77b4", "#d62728"
FORCE_SET_DPI = 110


def _faces(poly: Polytope) -> list[np.ndarray]:
    """Facets of a 3-D polytope as vertex loops (coplanar hull triangles merged)."""
    verts = poly.vertices
    faces = []
    for a, b in zip(poly.A, poly.b, strict=True):
        on = verts[np.abs(verts @ a - b) <= 1e-7 * max(1.0, poly.scale)]
        if on.shape[0] < 3:
            continue
        centre = on.mean(axis=0)
        u = on[0] - centre
        u = u / np.linalg.norm(u) if np.linalg.norm(u) > 0 else np.cross(a, [1.0, 0.0, 0.0])
        v = np.cross(a, u)
        order = np.argsort(np.arctan2((on - centre) @ v, (on - centre) @ u), kind="stable")
        faces.append(on[order])
    return faces


def force_axes(ax: Axes, points: np.ndarray | None) -> None:
    """A 3-D axes of body forces (FRD, thrust drawn upwards) framing ``points`` (N) in a
    cube (None: matplotlib's limits)."""
    ax3 = cast(Axes3D, ax)
    if points is not None:
        span = float(np.max(np.ptp(points, axis=0))) or 1.0
        mid = (points.max(axis=0) + points.min(axis=0)) / 2
        for setter, m in zip((ax3.set_xlim, ax3.set_ylim, ax3.set_zlim), mid, strict=True):
            setter(m - span / 2, m + span / 2)
    ax3.invert_zaxis()  # FRD: thrust (negative f_bz) drawn upwards
    ax3.set_xlabel("f_bx [N]")
    ax3.set_ylabel("f_by [N]")
    ax3.set_zlabel("f_bz [N]")


def draw_polytope(ax: Axes, poly: Polytope, color: str, alpha: float, edges: bool,
                   label: str) -> None:
    """Draw a polytope on a 3-D axis: its faces (or its segment when flat)."""
    if poly.dimension < 3:
        pts = poly.vertices
        ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=color, lw=3, label=label)
        return
    faces = _faces(poly)
    if alpha > 0:
        # callers set the limits from the vertices; mplot3d's autoscale from a fresh
        # axes' infinite data limits overflowed into NaN limits now and then
        cast(Axes3D, ax).add_collection3d(Poly3DCollection(faces, facecolor=color, alpha=alpha,
                                             edgecolor="none"), autolim=False)
    if edges:
        cast(Axes3D, ax).add_collection3d(Line3DCollection([np.vstack([f, f[:1]]) for f in faces],
                                             colors=color, linewidths=0.6), autolim=False)
    # legend proxy: a one-point line (draws nothing) at a real vertex, so that the
    # autoscale it triggers sees finite data (an empty line gave NaN limits)
    v = poly.vertices[:1]
    ax.plot(v[:, 0], v[:, 1], v[:, 2], color=color, lw=6 if alpha > 0 else 1,
            alpha=max(alpha, 0.6), label=label)


def _closed(poly2: np.ndarray) -> np.ndarray:
    return np.vstack([poly2, poly2[:1]])


def plot_force_sets(
    airframe: Airframe | str | Path,
    path: str | Path,
    afs: Polytope | None = None,
    s0: Polytope | None = None,
) -> Path:
    """Write the Fig.-3-like PNG for an airframe; returns the path.

    Precomputed ``afs`` / ``s0`` polytopes may be passed to avoid recomputing them.
    """
    af = airframe if isinstance(airframe, Airframe) else load_airframe(airframe)
    afs = attainable_force_set(af) if afs is None else afs
    s0 = feasible_force_set(af) if s0 is None else s0
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig = force_set_figure(af, afs, s0)
    fig.savefig(out, dpi=FORCE_SET_DPI, pil_kwargs={"compress_level": 1})
    return out


def force_set_figure(af: Airframe, afs: Polytope, s0: Polytope) -> Figure:
    """The figure of :func:`plot_force_sets`."""
    hover = hover_force(af)
    z = s0.clamp_z(hover[2])
    pxy = s0.slice_polygon(z)
    pxy_afs = afs.slice_polygon(afs.clamp_z(hover[2]))

    fig = Figure(figsize=(15.0, 7.5))
    FigureCanvasAgg(fig)  # the Agg backend, without touching pyplot's global state
    grid = fig.add_gridspec(1, 2, width_ratios=[1.5, 1.0], wspace=0.25, left=0.01, right=0.84,
                            top=0.92, bottom=0.16)
    ax = fig.add_subplot(grid[0], projection="3d")
    draw_polytope(ax, afs, GREEN, 0.18, False,
                  f"attainable force set, AFS ({afs.n_facets} facets)")
    draw_polytope(ax, s0, BLUE, 0.0, True, f"S(0): forces at zero torque ({s0.n_facets} facets)")
    ring = _closed(pxy)
    ax.add_collection3d(Poly3DCollection([np.column_stack([pxy, np.full(len(pxy), z)])],
                                         facecolor=RED, alpha=0.45, edgecolor=RED),
                        autolim=False)
    ax.plot(ring[:, 0], ring[:, 1], np.full(len(ring), z), color=RED, lw=1.5,
            label=f"P_xy at f_bz = {z:.2f} N")
    ax.scatter(*hover, color="k", s=12, label="hover force")
    force_axes(ax, np.vstack([afs.vertices, s0.vertices]))
    ax.set_title(f"{af.name}: attainable force set vs S(tau = 0)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), ncols=2, fontsize=9)  # below it
    ax.view_init(elev=18, azim=-60)

    ax2 = fig.add_subplot(grid[1])
    a_ring = _closed(pxy_afs)
    ax2.plot(a_ring[:, 0], a_ring[:, 1], "--", color=GREEN, lw=1.5,
             label="attainable force set (AFS) slice")
    inner = s0.inner_slice_polygon(z)
    if len(inner) >= 3:
        i_ring = _closed(inner)
        ax2.plot(i_ring[:, 0], i_ring[:, 1], ":", color="k", lw=1.2,
                 label="S(0) inner hull slice (attainable)")
    ax2.fill(ring[:, 0], ring[:, 1], color=RED, alpha=0.3)
    ax2.plot(ring[:, 0], ring[:, 1], "-o", color=RED, ms=3, lw=1.5,
             label=f"P_xy: S(0) at f_bz = {z:.2f} N")
    ax2.plot(0.0, 0.0, "k+", ms=10, label="hover (0, 0)")
    ax2.set_aspect("equal", adjustable="datalim")
    ax2.grid(True, alpha=0.3)
    ax2.set_xlabel("f_bx [N]")
    ax2.set_ylabel("f_by [N]")
    ext = np.abs(pxy).max(axis=0)
    ax2.set_title(f"lateral force limits at hover (m g = {-hover[2]:.2f} N): "
                  f"|f_bx| <= {ext[0]:.2f} N, |f_by| <= {ext[1]:.2f} N", fontsize=9)
    ax2.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    return fig


def main(argv: list[str] | None = None) -> int:
    """The command: draw an airframe's force sets (Fig. 3) into a PNG."""
    args = sys.argv[1:] if argv is None else argv
    name = args[0] if args else "paper_hexacopter"
    out = Path(args[1]) if len(args) > 1 else Path(f"force_sets_{Path(name).stem}.png")
    print(plot_force_sets(name, out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
