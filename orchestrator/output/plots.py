"""PNG plots of a recorded run, reproducing the paper's Figs. 3-10.

:func:`plot_run` writes, into ``out_dir``:

``tracking.png`` (Figs. 4, 7, 9)
    Position x, y, z (reference, shaped reference where it departs, and the true or measured
    position, world NED, never an offset axis) and attitude phi, theta, psi (mu_ref, mu_c,
    mu_m in degrees) with the intervals where mu_ref is infeasible (``ctrl.feasible == 0``)
    shaded; a bottom row with the position error norm in millimetres (against the reference
    the controller flies) and the attitude error mu_m - mu_c per axis.  Rotor faults,
    detections, disturbance steps and reference jumps are vertical lines on every panel;
    a signal that is zero shows a floor (0.1 deg, 0.1 mm, 2 mm of position), not round-off;
    one legend under the plots.
``actuators.png`` (Figs. 5, 10)
    Servo angles alpha_i, beta_i (deg) and rotor speeds omega_i (rpm), commands solid and
    measured states dotted, each axis zoomed on what the actuators did: a limit inside that
    view is dashed, one outside it is named in the legend as off scale.
``forces.png`` (Fig. 6)
    f_b_ref vs f_b_c per body axis over time; both force trajectories in 3-D against the
    attainable force set (AFS, green) and S(tau = 0) (blue edges), drawn with
    :mod:`controller.plots_force_sets`'s helpers; and their lateral components (f_bx, f_by)
    against the lateral force limits P_xy (S(0) sliced at the run's smallest, median and
    largest f_bz) and the AFS slice at the median f_bz.
``disturbance_timing.png`` (Fig. 8)
    The disturbances that act (a_d, f_d, tau_d, rotor efficiency: a panel for each that is
    not at its default, none otherwise) over time, and below the guidance and allocation QP
    solve times as histograms with their p50 and p99, solves slower than 5x the median of
    their iteration count told apart as host preemption (the solver did no more work); the
    QP iteration counts over time when the run did not time them.
``force_set.png`` (Fig. 3)
    :func:`controller.plots_force_sets.plot_force_sets` for the run's airframe (optional).

Only matplotlib's object API and the Agg canvas are used (no pyplot): plotting works headless
and from threads.  Long runs are decimated for drawing by :func:`envelope`, which keeps each
bucket's minimum and maximum sample with one bucket per pixel column of the axes, so spikes
(error extrema, saturation) stay visible while a line has at most two points per pixel.
Figures have fixed margins (no layout engine: constrained layout measured at 40 % of a
figure's time) and are written with fast PNG compression.

Each figure has a builder returning the :class:`~matplotlib.figure.Figure`
(:data:`RUN_FIGURES`, :func:`render_png`), so a figure can be drawn in another process
(``orchestrator.output.figure_pool``) and written by the caller.
"""

from __future__ import annotations

import io
import math
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator, NullFormatter

from orchestrator.output.events import Event, events
from orchestrator.output.figure_names import RUN_FIGURES
from orchestrator.output.metrics import wrap_deg
from orchestrator.output.run_result import RunResult

if TYPE_CHECKING:
    from controller.polytope import Polytope
    from plant.airframe import Airframe

MAX_POINTS = 4000
"""At most this many points per drawn line (a min/max pair per bucket) when the axes' width
is not known."""

DPI = 100
PNG_OPTIONS = {"compress_level": 1}
"""Pillow's fastest zlib level: ~10 % larger files than the default 6, written 3x faster."""
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
AXIS_COLORS = ("#1f77b4", "#d62728", "#2ca02c")
REF_COLOR, CMD_COLOR, MEAS_COLOR = "k", "#ff7f0e", "#1f77b4"
INFEASIBLE_COLOR = "#d62728"


# ---------------------------------------------------------------------------
# Decimation


def envelope_indices(y: np.ndarray, max_points: int = MAX_POINTS) -> np.ndarray:
    """Sorted row indices that keep the min and max of every bucket of ``y`` (1-D).

    With n <= max_points all indices are returned.  Otherwise the rows are cut into
    max_points // 2 buckets and each contributes its minimum and maximum sample (in time
    order), plus the first and last rows; the global extrema are always kept.  Non-finite
    values are kept where they fall (argmin/argmax pick the first NaN of a bucket).
    """
    v = np.asarray(y, dtype=float).reshape(-1)
    n = v.size
    if n <= max(max_points, 2):
        return np.arange(n)
    size = math.ceil(n / max(max_points // 2, 1))
    n_buckets = math.ceil(n / size)
    padded = np.concatenate([v, np.full(n_buckets * size - n, v[-1])]).reshape(n_buckets, size)
    base = np.arange(n_buckets) * size
    lo = np.minimum(base + np.argmin(padded, axis=1), n - 1)
    hi = np.minimum(base + np.argmax(padded, axis=1), n - 1)
    return np.unique(np.concatenate([[0], lo, hi, [n - 1]]))


def envelope(t: np.ndarray, y: np.ndarray,
             max_points: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """(t, y) decimated for drawing, keeping each bucket's extrema (:func:`envelope_indices`)."""
    idx = envelope_indices(y, max_points)
    return np.asarray(t)[idx], np.asarray(y).reshape(-1)[idx]


def pixel_columns(ax: Axes) -> int:
    """The axes' width in pixels at the figure's resolution."""
    fig = ax.get_figure()
    width = fig.get_figwidth() if isinstance(fig, Figure) else 10.0
    return max(math.ceil(ax.get_position().width * width * DPI), 1)


def _line(ax: Axes, t: np.ndarray, y: np.ndarray, **kw: Any) -> None:
    td, yd = envelope(t, y, 2 * pixel_columns(ax))
    ax.plot(td, yd, **kw)


def false_intervals(t: np.ndarray, ok: np.ndarray,
                    min_gap: float = 0.0) -> list[tuple[float, float]]:
    """[start, end) time intervals where ``ok`` is 0 (a sample covers [t_k, t_k+1)).

    Intervals separated by less than ``min_gap`` are merged (keeps chattering flags cheap to
    draw).
    """
    bad = np.asarray(ok, dtype=float) == 0.0
    if t.size == 0 or not np.any(bad):
        return []
    dt = float(t[-1] - t[-2]) if t.size > 1 else 0.0
    edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    t_end = np.append(t, t[-1] + dt)
    out: list[tuple[float, float]] = []
    for s, e in zip(starts, ends, strict=True):
        a, b = float(t_end[s]), float(t_end[e])
        if out and a - out[-1][1] < min_gap:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out


def _shade(ax: Axes, intervals: list[tuple[float, float]], label: str | None) -> None:
    """One filled polygon (axes-height bands) for all intervals."""
    if not intervals:
        return
    xs, ys = [], []
    for a, b in intervals:
        xs += [a, a, b, b]
        ys += [0.0, 1.0, 1.0, 0.0]
    ax.fill(xs, ys, color=INFEASIBLE_COLOR, alpha=0.12, lw=0,
            transform=ax.get_xaxis_transform(), label=label)


# ---------------------------------------------------------------------------
# Helpers


def _cols(a: np.ndarray) -> np.ndarray:
    """A signal as (n, k) (scalar signals become one column)."""
    return a.reshape(a.shape[0], -1)


def _new_figure(width: float, height: float, left: float = 0.07, right: float = 0.98,
                bottom: float = 0.06, top: float = 0.92, hspace: float = 0.2,
                wspace: float = 0.2) -> Figure:
    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=left, right=right, bottom=bottom, top=top, hspace=hspace,
                        wspace=wspace)
    return fig


def _title(result: RunResult, what: str) -> str:
    scenario = result.meta.get("scenario")
    airframe = result.meta.get("airframe")
    parts = [what] + [str(p) for p in (scenario, airframe) if p]
    return " - ".join(parts)


def _save(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(png_bytes(fig))
    return path


def png_bytes(fig: Figure, dpi: float = DPI) -> bytes:
    """The figure as PNG file contents."""
    buf = io.BytesIO()
    # mplot3d's projection of legend-proxy lines can overflow harmlessly while drawing
    with np.errstate(over="ignore", invalid="ignore"):
        fig.savefig(buf, format="png", dpi=dpi, pil_kwargs=PNG_OPTIONS)
    return buf.getvalue()


def _finish_time_axis(ax: Axes, t: np.ndarray) -> None:
    if t.size > 1:
        ax.set_xlim(float(t[0]), float(t[-1]))
    ax.grid(True, alpha=0.3)
    ax.ticklabel_format(axis="y", useOffset=False)  # -3.000, never -2.999 + 2e-4 ticks


def _floor(ax: Axes, min_span: float) -> None:
    """At least ``min_span`` of y: a signal that is (nearly) zero shows its floor, not
    round-off autoscaled to 1e-14."""
    lo, hi = ax.get_ylim()
    if hi - lo < min_span:
        mid = 0.5 * (lo + hi)
        ax.set_ylim(mid - 0.5 * min_span, mid + 0.5 * min_span)


EVENT_STYLE = {"fault": ("#d62728", "-"), "detection": ("#9467bd", "--"),
               "disturbance": ("#8c564b", ":"), "reference": ("#7f7f7f", "-.")}
"""Colour and line style of each kind of event marked on the time axes."""


def _mark_events(ax: Axes, found: list[Event], label: bool = False) -> None:
    """Vertical lines at the events (faults, detections, disturbance steps, reference
    jumps); ``label``: one legend entry per kind."""
    seen: set[str] = set()
    for e in found:
        color, ls = EVENT_STYLE[e.kind]
        ax.axvline(e.time, color=color, ls=ls, lw=0.9, alpha=0.8,
                   label=e.kind if label and e.kind not in seen else None)
        seen.add(e.kind)


def _legend_below(fig: Figure, axes: list[Axes], ncols: int = 6) -> None:
    """One legend for ``axes`` under the plots: it never covers data."""
    handles: dict[str, Any] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if not lab.startswith("_"):
                handles.setdefault(lab, h)
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="lower center", ncols=ncols,
                   fontsize=8, frameon=False)


def _legend_right(ax: Axes) -> None:
    """The axes' legend outside it, on the right: it never covers data."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=7)


# ---------------------------------------------------------------------------
# Figures


def plot_tracking(result: RunResult, path: Path) -> Path:
    """Figs. 4/7/9: position and attitude tracking, with the errors in a bottom row."""
    return _save(tracking_figure(result), path)


def tracking_figure(result: RunResult) -> Figure:
    """The figure of :func:`plot_tracking`."""
    t = result.time
    fig = _new_figure(13.0, 10.5, top=0.93, bottom=0.11, hspace=0.12, wspace=0.17)
    axs = fig.subplots(4, 2, sharex=True)
    marks = events(result, ("fault", "detection", "disturbance", "reference"))
    # with imperfect sensors the true state is recorded too: it is what is judged, the
    # measured one is drawn faint behind it
    truth = result.has_truth
    pos, pos_ref = result.optional(result.judged("plant.pos")), result.optional("ref.pos_ref")
    shaped = result.optional("ctrl.pos_ref_s")
    sensed = result.optional("plant.pos") if truth else None
    for i, name in enumerate(("x", "y", "z")):
        ax = axs[i, 0]
        if sensed is not None:
            _line(ax, t, sensed[:, i], color=MEAS_COLOR, lw=0.6, alpha=0.3,
                  label="measured (sensors)")
        if pos_ref is not None:
            _line(ax, t, pos_ref[:, i], color=REF_COLOR, ls="--", lw=1.0, label="reference")
        if shaped is not None and pos_ref is not None and np.any(shaped != pos_ref):
            _line(ax, t, shaped[:, i], color=CMD_COLOR, lw=1.0, label="shaped reference")
        if pos is not None:
            _line(ax, t, pos[:, i], color=MEAS_COLOR, lw=1.0,
                  label="true" if truth else "measured")
        ax.set_ylabel(f"{name} [m]" + (" (NED, down)" if name == "z" else ""))
        _finish_time_axis(ax, t)
        _floor(ax, 0.002)
        _mark_events(ax, marks, label=i == 0)
    axs[0, 0].set_title("position (world NED)")

    feasible = result.optional("ctrl.feasible")
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    bands = [] if feasible is None else false_intervals(t, feasible, min_gap=span / 1000.0)
    mu_ref, mu_c = result.optional("ref.euler_ref"), result.optional("ctrl.mu_c")
    mu_m = result.optional(result.judged("plant.euler"))
    mu_sensed = result.optional("plant.euler") if truth else None
    for i, name in enumerate(("phi", "theta", "psi")):
        ax = axs[i, 1]
        _shade(ax, bands, "mu_ref infeasible" if i == 0 else None)
        if mu_sensed is not None:
            _line(ax, t, np.degrees(mu_sensed[:, i]), color=MEAS_COLOR, lw=0.6, alpha=0.3,
                  label="mu_m measured")
        if mu_ref is not None:
            _line(ax, t, np.degrees(mu_ref[:, i]), color=REF_COLOR, ls="--", lw=1.0,
                  label="mu_ref")
        if mu_c is not None:
            _line(ax, t, np.degrees(mu_c[:, i]), color=CMD_COLOR, lw=1.2, label="mu_c")
        if mu_m is not None:
            _line(ax, t, np.degrees(mu_m[:, i]), color=MEAS_COLOR, lw=0.9, ls=":",
                  label="mu_m true" if truth else "mu_m")
        ax.set_ylabel(f"{name} [deg]")
        _finish_time_axis(ax, t)
        _floor(ax, 0.1)
        _mark_events(ax, marks)
    axs[0, 1].set_title("attitude")

    ax = axs[3, 0]
    if pos is not None and pos_ref is not None:
        # against the reference the controller flies (its shaped one: a 10 m step is not a
        # 10 m error), in millimetres
        err = 1e3 * np.linalg.norm(pos - (shaped if shaped is not None else pos_ref), axis=1)
        _line(ax, t, err, color=MEAS_COLOR, lw=1.0)
        if err.size and np.all(np.isfinite(err)):
            k = int(np.argmax(err))
            ax.plot(t[k], err[k], "v", color=INFEASIBLE_COLOR, ms=5,
                    label=f"max error {err[k]:.1f} mm at {t[k]:.2f} s")
    what = result.judged("plant.pos").removeprefix("plant.")
    ax.set_ylabel(f"|{what} - pos_ref{'_s' if shaped is not None else ''}| [mm]")
    ax.set_xlabel("time [s]")
    _finish_time_axis(ax, t)
    _floor(ax, 0.1)
    _mark_events(ax, marks)
    ax = axs[3, 1]
    if mu_m is not None and mu_c is not None:
        err_att = wrap_deg(np.degrees(mu_m - mu_c))
        for i, name in enumerate(("phi", "theta", "psi")):
            _line(ax, t, err_att[:, i], color=AXIS_COLORS[i], lw=0.9, label=f"{name} error")
    ax.set_ylabel(f"mu_m{' true' if truth else ''} - mu_c [deg]")
    ax.set_xlabel("time [s]")
    _finish_time_axis(ax, t)
    _floor(ax, 0.1)
    _mark_events(ax, marks)
    _legend_below(fig, [axs[0, 0], axs[0, 1], axs[3, 0], axs[3, 1]], ncols=7)
    fig.suptitle(_title(result, "full-pose tracking"))
    return fig


def _limits(result: RunResult, airframe: Airframe | None) -> dict[str, tuple[float, float]]:
    """Servo limits (rad) and speed limits (rad/s) from meta, else the airframe."""
    out: dict[str, tuple[float, float]] = {}
    meta = result.meta
    for key, attr in (("alpha", "alpha_limits"), ("beta", "beta_limits")):
        if meta.get(attr) is not None:
            lo, hi = meta[attr]
            out[key] = (float(lo), float(hi))
        elif airframe is not None:
            lims = getattr(airframe, attr)
            out[key] = (float(lims[0][0]), float(lims[0][1]))
    lo = float(airframe.omega_min) if airframe is not None else 0.0
    if meta.get("omega_max") is not None:
        out["omega"] = (lo, float(meta["omega_max"]))
    elif airframe is not None:
        out["omega"] = (lo, float(airframe.omega_max))
    return out


def plot_actuators(result: RunResult, path: Path, airframe: Airframe | None = None) -> Path:
    """Figs. 5/10: commanded servo angles and rotor speeds with their limits."""
    return _save(actuators_figure(result, airframe), path)


def actuators_figure(result: RunResult, airframe: Airframe | None = None) -> Figure:
    """The figure of :func:`plot_actuators`: commands solid, measured states dotted, each axis
    zoomed on what the actuators did; a limit is drawn where it lies within that view and
    named in the legend as off scale where it does not."""
    t = result.time
    n = result.n_rotors
    lims = _limits(result, airframe)
    fig = _new_figure(13.0, 9.0, right=0.86, top=0.94, hspace=0.12)
    axs = fig.subplots(3, 1, sharex=True)
    marks = events(result, ("fault", "detection"))
    groups = (("alpha", "alpha", np.degrees(1.0), "deg", 1.0),
              ("beta", "beta", np.degrees(1.0), "deg", 1.0),
              ("omega", "omega", RPM_PER_RAD_S, "rpm", 20.0))
    for ax, (key, sym, scale, unit, floor) in zip(axs, groups, strict=True):
        cmd, meas = result.optional(f"ctrl.{key}_cmd"), result.optional(f"plant.{key}")
        drawn: list[np.ndarray] = []
        for sig, ls, what in ((cmd, "-", "command"), (meas, ":", "measured")):
            if sig is None:
                continue
            sig = scale * _cols(sig)[:, :n]
            drawn.append(sig)
            for i in range(sig.shape[1]):
                _line(ax, t, sig[:, i], lw=0.9, ls=ls, color=f"C{i}",
                      label=f"{sym}_{i + 1}" if what == "command" else None)
        if drawn:
            both = np.concatenate(drawn, axis=1)
            lo, hi = float(np.min(both)), float(np.max(both))
            pad = max(0.1 * (hi - lo), 0.5 * floor)
            ax.set_ylim(lo - pad, hi + pad)
        view = ax.get_ylim()
        if key in lims:
            for j, v in enumerate(lims[key]):
                v = scale * v
                inside = view[0] <= v <= view[1]
                if inside:
                    ax.axhline(v, color="k", ls="--", lw=1.0, label="limit" if j == 0 else None)
                else:  # said, not drawn: it would flatten what the actuators did
                    ax.plot([], [], " ", label=f"limit {v:.0f} {unit} (off scale)")
        ax.plot([], [], color="0.3", ls="-", lw=0.9, label="solid: command")
        ax.plot([], [], color="0.3", ls=":", lw=0.9, label="dotted: measured")
        ax.set_ylabel(f"{sym} [{unit}]")
        _finish_time_axis(ax, t)
        _mark_events(ax, marks, label=key == "alpha")
        _legend_right(ax)
    axs[-1].set_xlabel("time [s]")
    fig.suptitle(_title(result, "actuators: commands and measured states"))
    return fig


def _sample_3d(points: np.ndarray, max_points: int = 1500) -> np.ndarray:
    """Row indices: a uniform subsample plus each coordinate's extrema."""
    n = points.shape[0]
    if n <= max_points:
        return np.arange(n)
    stride = math.ceil(n / max_points)
    extra = np.concatenate([np.argmin(points, axis=0), np.argmax(points, axis=0)])
    return np.unique(np.concatenate([np.arange(0, n, stride), extra, [n - 1]]))


def plot_forces(result: RunResult, path: Path, afs: Polytope | None = None,
                s0: Polytope | None = None) -> Path:
    """Fig. 6: f_b_ref vs f_b_c over time, in 3-D against the AFS and S(0), and in the
    lateral plane against the slices P_xy of S(0) at the run's f_bz range."""
    return _save(forces_figure(result, afs, s0), path)


def forces_figure(result: RunResult, afs: Polytope | None = None,
                  s0: Polytope | None = None) -> Figure:
    """The figure of :func:`plot_forces`."""
    t = result.time
    f_ref, f_c = result.optional("ctrl.f_b_ref"), result.optional("ctrl.f_b_c")
    fig = _new_figure(15.0, 10.0, left=0.06, right=0.8, top=0.93, hspace=0.5, wspace=0.15)
    grid = fig.add_gridspec(6, 2, width_ratios=[1.25, 1.0])
    axes_t = [fig.add_subplot(grid[2 * i:2 * i + 2, 0]) for i in range(3)]
    for i, (ax, name) in enumerate(zip(axes_t, ("f_bx", "f_by", "f_bz"), strict=True)):
        if i:
            ax.sharex(axes_t[0])
        if f_ref is not None:
            _line(ax, t, f_ref[:, i], color=REF_COLOR, ls="--", lw=1.0, label="f_b_ref")
        if f_c is not None:
            _line(ax, t, f_c[:, i], color=CMD_COLOR, lw=1.0, label="f_b_c")
        ax.set_ylabel(f"{name} [N]")
        _finish_time_axis(ax, t)
    axes_t[0].set_title("body force (FRD) over time")
    axes_t[0].legend(loc="upper right", fontsize=8)
    axes_t[-1].set_xlabel("time [s]")

    trajectories = []
    for sig, color, label in ((f_ref, REF_COLOR, "f_b_ref"), (f_c, CMD_COLOR, "f_b_c")):
        if sig is None:
            continue
        finite = sig[np.all(np.isfinite(sig), axis=1)]
        if finite.size:
            trajectories.append((finite[_sample_3d(finite)], color, label))
    # mplot3d's autoscaling of the empty legend-proxy lines can overflow harmlessly
    with np.errstate(over="ignore", invalid="ignore"):
        _forces_3d(fig.add_subplot(grid[0:3, 1], projection="3d"), trajectories, afs, s0)
        _forces_lateral(fig.add_subplot(grid[3:6, 1]), trajectories, afs, s0)
        fig.suptitle(_title(result, "reference vs commanded body force"))
    return fig


def _forces_3d(ax3: Any, trajectories: list[tuple[np.ndarray, str, str]],
               afs: Polytope | None, s0: Polytope | None) -> None:
    from controller.plots_force_sets import BLUE, GREEN, draw_polytope, force_axes

    bounds = []
    if afs is not None or s0 is not None:
        if afs is not None:
            draw_polytope(ax3, afs, GREEN, 0.12, False, "attainable force set")
            bounds.append(afs.vertices)
        if s0 is not None:
            draw_polytope(ax3, s0, BLUE, 0.0, True, "S(tau = 0)")
            bounds.append(s0.vertices)
    for pts, color, label in trajectories:
        ax3.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=color, lw=0.6, alpha=0.8)
        ax3.scatter(pts[:, 0], pts[:, 1], pts[:, 2], color=color, s=2, label=label,
                    depthshade=False)
        bounds.append(pts)
    force_axes(ax3, np.vstack(bounds) if bounds else None)
    ax3.view_init(elev=18, azim=-60)
    ax3.set_box_aspect((1.0, 1.0, 1.0), zoom=0.85)  # room for the axis labels
    ax3.legend(loc="upper left", fontsize=8)
    ax3.set_title("forces vs the attainable force set" if afs is not None
                  else "forces (force sets unavailable)", fontsize=10)


def _forces_lateral(ax: Axes, trajectories: list[tuple[np.ndarray, str, str]],
                    afs: Polytope | None, s0: Polytope | None) -> None:
    """(f_bx, f_by) of the forces, with P_xy = S(0) sliced at the min/median/max f_bz."""
    for pts, color, label in trajectories:
        ax.plot(pts[:, 0], pts[:, 1], ".", color=color, ms=1.5, label=label)
    if s0 is not None and trajectories:
        from controller.plots_force_sets import GREEN, RED
        from controller.polytope import EmptyForceSetError

        fz = trajectories[0][0][:, 2]
        levels = np.unique(np.round(np.percentile(fz, [0.0, 50.0, 100.0]), 6))
        styles = ("-", "--", ":")
        for k, z in enumerate(levels[::-1]):  # least thrust (largest f_bz) first
            try:
                ring = s0.slice_polygon(float(z))
            except EmptyForceSetError:
                continue
            ring = np.vstack([ring, ring[:1]])
            ax.plot(ring[:, 0], ring[:, 1], styles[k % 3], color=RED, lw=1.3,
                    label=f"P_xy: S(0) at f_bz = {s0.clamp_z(float(z)):.2f} N")
        if afs is not None:
            z = float(np.median(fz))
            try:
                ring = afs.slice_polygon(z)
                ring = np.vstack([ring, ring[:1]])
                ax.plot(ring[:, 0], ring[:, 1], "-", color=GREEN, lw=1.0, alpha=0.8,
                        label=f"AFS at f_bz = {afs.clamp_z(z):.2f} N")
            except EmptyForceSetError:
                pass
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("f_bx [N]")
    ax.set_ylabel("f_by [N]")
    ax.set_title("lateral forces vs the lateral force limits P_xy", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, markerscale=4)


def _nonzero(sig: np.ndarray | None, default: float = 0.0) -> bool:
    return sig is not None and bool(np.any(sig != default))


def plot_disturbance_timing(result: RunResult, path: Path) -> Path:
    """Fig. 8: disturbances on top, QP computation times (or iterations) below."""
    return _save(disturbance_timing_figure(result), path)


PREEMPTION_FACTOR = 5.0
"""A solve that took this many times the median of the solves with its iteration count did no
more work than they did: the host took the CPU away (preemption), not the solver."""


def preempted(times: np.ndarray, iterations: np.ndarray | None) -> np.ndarray:
    """Which solve times are host preemption: above PREEMPTION_FACTOR x the median time of
    the solves with the same iteration count (all solves when the counts are unknown)."""
    out = np.zeros(times.shape, dtype=bool)
    groups = np.zeros(times.shape) if iterations is None else np.asarray(iterations)
    for it in np.unique(groups):
        sel = groups == it
        out[sel] = times[sel] > PREEMPTION_FACTOR * np.median(times[sel])
    return out


HIST_BASELINE = 0.5
"""Where a log-count histogram's bars start (below one sample, so an empty bin shows none)."""


def _log_histogram(ax: Axes, values: np.ndarray, bins: np.ndarray, color: str,
                   label: str) -> None:
    counts, _ = np.histogram(values, bins=bins)
    heights = np.where(counts > 0, counts, HIST_BASELINE).astype(float)
    ax.stairs(heights, bins, fill=True, baseline=HIST_BASELINE, color=color, label=label)


def disturbance_timing_figure(result: RunResult) -> Figure:
    """The figure of :func:`plot_disturbance_timing`: the disturbances that act (a panel per
    kind that is not zero throughout, none when nothing acts) over time, and the QP solve
    times as the distribution they are (or the iteration counts when timing was off)."""
    t = result.time
    n = result.n_rotors
    panels: list[tuple[str, np.ndarray, str]] = []
    for name, unit in (("a_d", "m/s^2"), ("f_d", "N"), ("tau_d", "N m")):
        sig = result.optional(f"dist.{name}")
        if sig is not None and _nonzero(sig):
            panels.append((name, sig, unit))
    eff = result.optional("dist.efficiency")
    eff = None if eff is None else _cols(eff)[:, :n]
    show_eff = eff is not None and eff.size > 0 and _nonzero(eff, 1.0)
    timing = {k: result.optional(f"ctrl.{k}") for k in ("t_guid", "t_alloc")}
    measured = any(_nonzero(v) for v in timing.values())
    time_rows = len(panels) + int(show_eff) + int(not measured)
    height = 2.4 * time_rows + (3.0 if measured else 0.0) + 1.0
    fig = _new_figure(12.0, height, left=0.09, right=0.86, bottom=0.55 / height,
                      top=1 - 0.85 / height, hspace=0.45)
    grid = fig.add_gridspec(time_rows + int(measured), 2 if measured else 1)
    axs: list[Axes] = []
    for row in range(time_rows):
        ax = fig.add_subplot(grid[row, :], sharex=axs[0] if axs else None)
        axs.append(ax)
    marks = events(result, ("fault", "detection"))
    for ax, (name, sig, unit) in zip(axs, panels, strict=False):
        for i, axis in enumerate(("x", "y", "z")):
            _line(ax, t, sig[:, i], color=AXIS_COLORS[i], lw=1.0, label=f"{name} {axis}")
        frame = "body FRD" if name == "tau_d" else "world NED"
        ax.set_ylabel(f"{name} [{unit}]\n({frame})")
        _finish_time_axis(ax, t)
        _legend_right(ax)
    if panels:
        axs[0].set_title("disturbances")
    k = len(panels)
    if show_eff and eff is not None:
        ax = axs[k]
        for i in range(eff.shape[1]):
            _line(ax, t, eff[:, i], lw=1.0, label=f"rotor {i + 1}")
        ax.set_ylabel("rotor efficiency [-]")
        ax.set_ylim(-0.05, 1.05)
        _finish_time_axis(ax, t)
        _mark_events(ax, marks, label=True)
        _legend_right(ax)
        if not panels:
            ax.set_title("rotor faults")
        k += 1
    if not measured:
        ax = axs[k]
        for name, color, label in (("guid_iter", CMD_COLOR, "guidance QP"),
                                   ("alloc_iter", MEAS_COLOR, "allocation QP")):
            sig = result.optional(f"ctrl.{name}")
            if sig is not None:
                _line(ax, t, sig, color=color, lw=0.8, label=label)
        ax.set_ylabel("iterations [-]")
        ax.set_title("QP iterations (computation times not measured: controller timing off)")
        _finish_time_axis(ax, t)
        _legend_right(ax)
    if axs:
        axs[-1].set_xlabel("time [s]")
        for ax in axs[:-1]:
            ax.tick_params(labelbottom=False)
    if measured:
        for col, (key, label, iters) in enumerate((("t_guid", "guidance QP", "guid_iter"),
                                                   ("t_alloc", "allocation QP", "alloc_iter"))):
            ax = fig.add_subplot(grid[time_rows, col])
            sig = timing[key]
            if sig is None or not np.any(sig > 0):
                ax.set_title(f"{label}: no solve timed")
                continue
            timed = sig > 0
            solved = sig[timed]
            it = result.optional(f"ctrl.{iters}")
            spike = preempted(solved, None if it is None else it[timed])
            us = 1e6 * solved
            bins = np.geomspace(max(us.min(), 1e-3), us.max() * 1.01, 60)
            # one filled outline per series (a bar per bin is 60 patches to lay out and
            # draw); empty bins sit on the baseline below the axis
            _log_histogram(ax, us[~spike], bins, MEAS_COLOR, "solves")
            if np.any(spike):
                _log_histogram(ax, us[spike], bins, INFEASIBLE_COLOR,
                               f"host preemption ({int(spike.sum())}, "
                               f"{100 * spike.mean():.2f} %)")
            for q, ls in ((50, "-"), (99, "--")):
                v = float(np.percentile(us, q))
                ax.axvline(v, color="k", ls=ls, lw=1.0, label=f"p{q} {v:.2f} us")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_ylim(bottom=HIST_BASELINE)
            # minor ticks at 2 and 5 of each decade, unlabelled: 8 per decade, each labelled
            # on an axis spanning one decade, cost half of the figure's drawing time
            for log_axis in (ax.xaxis, ax.yaxis):
                log_axis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0)))
                log_axis.set_minor_formatter(NullFormatter())
            ax.set_xlabel(f"{label} solve time [us]")
            ax.set_ylabel("samples")
            ax.set_title(f"{label}: {us.size} solves")
            ax.legend(loc="upper right", fontsize=7)
            ax.grid(True, alpha=0.3)
    fig.suptitle(_title(result, "disturbances and guidance computation"))
    return fig


# ---------------------------------------------------------------------------
# Entry point


def resolve_airframe(result: RunResult,
                     airframe: Airframe | str | Path | None = None) -> Airframe | None:
    """The run's airframe: the argument, else the airframe the results recorded (meta
    ``airframe_record``: what flew, whatever its file says now), else for results written
    before records the file ``airframe_source``, else the name ``airframe``.

    Returns None (with a warning) when none of them loads.
    """
    from plant.airframe import Airframe, AirframeError, load_airframe

    if isinstance(airframe, Airframe):
        return airframe
    record = result.meta.get("airframe_record")
    if airframe is None and isinstance(record, dict):
        try:
            return Airframe.from_record(record)
        except AirframeError as exc:
            warnings.warn(f"the results' airframe record is unusable: {exc}", stacklevel=2)
    candidates = [airframe, result.meta.get("airframe_source"), result.meta.get("airframe")]
    errors = []
    for c in candidates:
        if c is None:
            continue
        try:
            return load_airframe(c)
        except Exception as exc:  # unknown name, unreadable file: try the next candidate
            errors.append(f"{c}: {exc}")
    if errors:
        warnings.warn("no airframe for the force-set plots: " + "; ".join(errors),
                      stacklevel=3)
    return None


def force_sets(airframe: Airframe) -> tuple[Polytope, Polytope]:
    """(AFS, S(0)) of an airframe: the shipped airframes' design-time sets, else the
    content-addressed cache, else computed once and cached
    (:func:`controller.polytope_cache.force_sets`)."""
    from controller.polytope_cache import force_sets as sets

    return sets(airframe)


def render_png(name: str, result: RunResult | None, airframe: Airframe | None,
               afs: Polytope | None, s0: Polytope | None) -> bytes:
    """One figure's PNG: a name of :data:`RUN_FIGURES`, or ``force_set`` (the airframe's
    Fig. 3, which needs no run)."""
    if name == "force_set":
        if airframe is None or afs is None or s0 is None:
            raise ValueError("the force_set figure needs the airframe and its force sets")
        from controller.plots_force_sets import FORCE_SET_DPI, force_set_figure

        return png_bytes(force_set_figure(airframe, afs, s0), dpi=FORCE_SET_DPI)
    if result is None:
        raise ValueError(f"the {name} figure needs a run")
    builders: dict[str, Callable[[], Figure]] = {
        "tracking": lambda: tracking_figure(result),
        "actuators": lambda: actuators_figure(result, airframe),
        "forces": lambda: forces_figure(result, afs, s0),
        "disturbance_timing": lambda: disturbance_timing_figure(result),
    }
    if name not in builders:
        raise ValueError(f"unknown figure {name!r} (known: {', '.join(RUN_FIGURES)}, force_set)")
    return png_bytes(builders[name]())


def figure_inputs(result: RunResult, airframe: Airframe | str | Path | None = None
                  ) -> tuple[Airframe | None, Polytope | None, Polytope | None]:
    """The run's airframe and its (AFS, S(0)): an unknown airframe or failing force sets
    give a warning and Nones (the figures are drawn without them)."""
    af = resolve_airframe(result, airframe)
    afs = s0 = None
    if af is not None:
        try:
            afs, s0 = force_sets(af)
        except Exception as exc:  # an airframe whose sets cannot be built still gets plots
            warnings.warn(f"force sets of {af.name} unavailable: {exc}", stacklevel=3)
    return af, afs, s0


def plot_run(result: RunResult, out_dir: Path, force_set_png: bool = True,
             airframe: Airframe | str | Path | None = None) -> list[Path]:
    """Write the run's PNG figures into ``out_dir``; returns their paths (in order).

    ``tracking.png``, ``actuators.png``, ``forces.png``, ``disturbance_timing.png`` always;
    ``force_set.png`` when ``force_set_png`` and the airframe is known.  The force sets
    (AFS and S(0)) come from :func:`force_sets` (shipped, cached or computed once); an
    unknown airframe or failing force sets give a warning and the force figures without
    the sets.  See the module docstring.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    af, afs, s0 = figure_inputs(result, airframe)
    names = list(RUN_FIGURES)
    if force_set_png and af is not None and afs is not None and s0 is not None:
        names.append("force_set")
    paths = []
    for name in names:
        path = out / f"{name}.png"
        path.write_bytes(render_png(name, result, af, afs, s0))
        paths.append(path)
    return paths
