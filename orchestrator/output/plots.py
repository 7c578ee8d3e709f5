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

import math
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from orchestrator.output.events import events
from orchestrator.output.figure_names import RUN_FIGURES
from orchestrator.output.metrics import flying_rows, wrap_deg
from orchestrator.output.plot_style import (
    AXIS_COLORS,
    CMD_COLOR,
    INFEASIBLE_COLOR,
    MEAS_COLOR,
    REF_COLOR,
    RPM_PER_RAD_S,
    columns,
    draw_line,
    false_intervals,
    figure_title,
    finish_time_axis,
    legend_below,
    legend_right,
    mark_events,
    new_figure,
    png_bytes,
    save_png,
    shade_intervals,
    y_floor,
)
from orchestrator.output.run_result import RunResult
from orchestrator.output.timing_figure import disturbance_timing_figure

if TYPE_CHECKING:
    from controller.polytope import Polytope
    from plant.airframe import Airframe

__all__ = ["RUN_FIGURES", "actuators_figure", "figure_inputs", "force_sets", "forces_figure",
           "plot_actuators", "plot_forces", "plot_run", "plot_tracking", "render_png",
           "resolve_airframe", "tracking_figure"]


# ---------------------------------------------------------------------------
# Figures


def plot_tracking(result: RunResult, path: Path) -> Path:
    """Figs. 4/7/9: position and attitude tracking, with the errors in a bottom row."""
    return save_png(tracking_figure(result), path)


def tracking_figure(result: RunResult) -> Figure:
    """The figure of :func:`plot_tracking`."""
    t = result.time
    fig = new_figure(13.0, 10.5, top=0.93, bottom=0.11, hspace=0.12, wspace=0.17)
    axs = fig.subplots(4, 2, sharex=True)
    marks = events(result, ("fault", "detection", "disturbance", "reference", "ground",
                            "mission"))
    # with imperfect sensors the true state is recorded too: it is what is judged, the
    # measured one is drawn faint behind it
    truth = result.has_truth
    pos, pos_ref = result.optional(result.judged("plant.pos")), result.optional("ref.pos_ref")
    shaped = result.optional("ctrl.pos_ref_s")
    sensed = result.optional("plant.pos") if truth else None
    for i, name in enumerate(("x", "y", "z")):
        ax = axs[i, 0]
        if sensed is not None:
            draw_line(ax, t, sensed[:, i], color=MEAS_COLOR, lw=0.6, alpha=0.3,
                  label="measured (sensors)")
        if pos_ref is not None:
            draw_line(ax, t, pos_ref[:, i], color=REF_COLOR, ls="--", lw=1.0, label="reference")
        if shaped is not None and pos_ref is not None and np.any(shaped != pos_ref):
            draw_line(ax, t, shaped[:, i], color=CMD_COLOR, lw=1.0, label="shaped reference")
        if pos is not None:
            draw_line(ax, t, pos[:, i], color=MEAS_COLOR, lw=1.0,
                  label="true" if truth else "measured")
        ax.set_ylabel(f"{name} [m]" + (" (NED, down)" if name == "z" else ""))
        finish_time_axis(ax, t)
        y_floor(ax, 0.002)
        mark_events(ax, marks, label=i == 0)
    axs[0, 0].set_title("position (world NED)")

    feasible = result.optional("ctrl.feasible")
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    bands = [] if feasible is None else false_intervals(t, feasible, min_gap=span / 1000.0)
    mu_ref, mu_c = result.optional("ref.euler_ref"), result.optional("ctrl.mu_c")
    mu_m = result.optional(result.judged("plant.euler"))
    mu_sensed = result.optional("plant.euler") if truth else None
    for i, name in enumerate(("phi", "theta", "psi")):
        ax = axs[i, 1]
        shade_intervals(ax, bands, "mu_ref infeasible" if i == 0 else None)
        if mu_sensed is not None:
            draw_line(ax, t, np.degrees(mu_sensed[:, i]), color=MEAS_COLOR, lw=0.6, alpha=0.3,
                  label="mu_m measured")
        if mu_ref is not None:
            draw_line(ax, t, np.degrees(mu_ref[:, i]), color=REF_COLOR, ls="--", lw=1.0,
                  label="mu_ref")
        if mu_c is not None:
            draw_line(ax, t, np.degrees(mu_c[:, i]), color=CMD_COLOR, lw=1.2, label="mu_c")
        if mu_m is not None:
            draw_line(ax, t, np.degrees(mu_m[:, i]), color=MEAS_COLOR, lw=0.9, ls=":",
                  label="mu_m true" if truth else "mu_m")
        ax.set_ylabel(f"{name} [deg]")
        finish_time_axis(ax, t)
        y_floor(ax, 0.1)
        mark_events(ax, marks)
    axs[0, 1].set_title("attitude")

    ax = axs[3, 0]
    if pos is not None and pos_ref is not None:
        # against the reference the controller flies (its shaped one: a 10 m step is not a
        # 10 m error), in millimetres
        raw = 1e3 * np.linalg.norm(pos - (shaped if shaped is not None else pos_ref), axis=1)
        # (on the ground no reference is flown: those rows are left out, as in the metrics)
        err = np.where(flying_rows(result), raw, np.nan)
        draw_line(ax, t, err, color=MEAS_COLOR, lw=1.0)
        if raw.size and np.all(np.isfinite(raw)) and np.any(np.isfinite(err)):
            k = int(np.nanargmax(err))
            ax.plot(t[k], err[k], "v", color=INFEASIBLE_COLOR, ms=5,
                    label=f"max error {err[k]:.1f} mm at {t[k]:.2f} s")
    what = result.judged("plant.pos").removeprefix("plant.")
    ax.set_ylabel(f"|{what} - pos_ref{'_s' if shaped is not None else ''}| [mm]")
    ax.set_xlabel("time [s]")
    finish_time_axis(ax, t)
    y_floor(ax, 0.1)
    mark_events(ax, marks)
    ax = axs[3, 1]
    if mu_m is not None and mu_c is not None:
        err_att = wrap_deg(np.degrees(mu_m - mu_c))
        for i, name in enumerate(("phi", "theta", "psi")):
            draw_line(ax, t, err_att[:, i], color=AXIS_COLORS[i], lw=0.9, label=f"{name} error")
    ax.set_ylabel(f"mu_m{' true' if truth else ''} - mu_c [deg]")
    ax.set_xlabel("time [s]")
    finish_time_axis(ax, t)
    y_floor(ax, 0.1)
    mark_events(ax, marks)
    legend_below(fig, [axs[0, 0], axs[0, 1], axs[3, 0], axs[3, 1]], ncols=7)
    fig.suptitle(figure_title(result, "full-pose tracking"))
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
    return save_png(actuators_figure(result, airframe), path)


def actuators_figure(result: RunResult, airframe: Airframe | None = None) -> Figure:
    """The figure of :func:`plot_actuators`: commands solid, measured states dotted, each axis
    zoomed on what the actuators did; a limit is drawn where it lies within that view and
    named in the legend as off scale where it does not."""
    t = result.time
    n = result.n_rotors
    lims = _limits(result, airframe)
    fig = new_figure(13.0, 9.0, right=0.86, top=0.94, hspace=0.12)
    axs = fig.subplots(3, 1, sharex=True)
    marks = events(result, ("fault", "detection", "ground"))
    groups = (("alpha", "alpha", np.degrees(1.0), "deg", 1.0),
              ("beta", "beta", np.degrees(1.0), "deg", 1.0),
              ("omega", "omega", RPM_PER_RAD_S, "rpm", 20.0))
    for ax, (key, sym, scale, unit, floor) in zip(axs, groups, strict=True):
        cmd, meas = result.optional(f"ctrl.{key}_cmd"), result.optional(f"plant.{key}")
        drawn: list[np.ndarray] = []
        for sig, ls, what in ((cmd, "-", "command"), (meas, ":", "measured")):
            if sig is None:
                continue
            sig = scale * columns(sig)[:, :n]
            drawn.append(sig)
            for i in range(sig.shape[1]):
                draw_line(ax, t, sig[:, i], lw=0.9, ls=ls, color=f"C{i}",
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
        finish_time_axis(ax, t)
        mark_events(ax, marks, label=key == "alpha")
        legend_right(ax)
    axs[-1].set_xlabel("time [s]")
    fig.suptitle(figure_title(result, "actuators: commands and measured states"))
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
    return save_png(forces_figure(result, afs, s0), path)


def forces_figure(result: RunResult, afs: Polytope | None = None,
                  s0: Polytope | None = None) -> Figure:
    """The figure of :func:`plot_forces`."""
    t = result.time
    f_ref, f_c = result.optional("ctrl.f_b_ref"), result.optional("ctrl.f_b_c")
    fig = new_figure(15.0, 10.0, left=0.06, right=0.8, top=0.93, hspace=0.5, wspace=0.15)
    grid = fig.add_gridspec(6, 2, width_ratios=[1.25, 1.0])
    axes_t = [fig.add_subplot(grid[2 * i:2 * i + 2, 0]) for i in range(3)]
    for i, (ax, name) in enumerate(zip(axes_t, ("f_bx", "f_by", "f_bz"), strict=True)):
        if i:
            ax.sharex(axes_t[0])
        if f_ref is not None:
            draw_line(ax, t, f_ref[:, i], color=REF_COLOR, ls="--", lw=1.0, label="f_b_ref")
        if f_c is not None:
            draw_line(ax, t, f_c[:, i], color=CMD_COLOR, lw=1.0, label="f_b_c")
        ax.set_ylabel(f"{name} [N]")
        finish_time_axis(ax, t)
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
        fig.suptitle(figure_title(result, "reference vs commanded body force"))
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
