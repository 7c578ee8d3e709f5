"""Fig. 8 of a run: the disturbances that act over time, and the guidance and allocation QP
solve times as the distribution they are, host preemption told apart (see
:mod:`orchestrator.output.plots`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator, NullFormatter

from orchestrator.output.events import events
from orchestrator.output.plot_style import (
    AXIS_COLORS,
    CMD_COLOR,
    INFEASIBLE_COLOR,
    MEAS_COLOR,
    columns,
    draw_line,
    figure_title,
    finish_time_axis,
    legend_right,
    mark_events,
    new_figure,
    save_png,
)
from orchestrator.output.run_result import RunResult


def _nonzero(sig: np.ndarray | None, default: float = 0.0) -> bool:
    return sig is not None and bool(np.any(sig != default))


def plot_disturbance_timing(result: RunResult, path: Path) -> Path:
    """Fig. 8: disturbances on top, QP computation times (or iterations) below."""
    return save_png(disturbance_timing_figure(result), path)


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
    eff = None if eff is None else columns(eff)[:, :n]
    show_eff = eff is not None and eff.size > 0 and _nonzero(eff, 1.0)
    timing = {k: result.optional(f"ctrl.{k}") for k in ("t_guid", "t_alloc")}
    measured = any(_nonzero(v) for v in timing.values())
    time_rows = len(panels) + int(show_eff) + int(not measured)
    height = 2.4 * time_rows + (3.0 if measured else 0.0) + 1.0
    fig = new_figure(12.0, height, left=0.09, right=0.86, bottom=0.55 / height,
                      top=1 - 0.85 / height, hspace=0.45)
    grid = fig.add_gridspec(time_rows + int(measured), 2 if measured else 1)
    axs: list[Axes] = []
    for row in range(time_rows):
        ax = fig.add_subplot(grid[row, :], sharex=axs[0] if axs else None)
        axs.append(ax)
    marks = events(result, ("fault", "detection"))
    for ax, (name, sig, unit) in zip(axs, panels, strict=False):
        for i, axis in enumerate(("x", "y", "z")):
            draw_line(ax, t, sig[:, i], color=AXIS_COLORS[i], lw=1.0, label=f"{name} {axis}")
        frame = "body FRD" if name == "tau_d" else "world NED"
        ax.set_ylabel(f"{name} [{unit}]\n({frame})")
        finish_time_axis(ax, t)
        legend_right(ax)
    if panels:
        axs[0].set_title("disturbances")
    k = len(panels)
    if show_eff and eff is not None:
        ax = axs[k]
        for i in range(eff.shape[1]):
            draw_line(ax, t, eff[:, i], lw=1.0, label=f"rotor {i + 1}")
        ax.set_ylabel("rotor efficiency [-]")
        ax.set_ylim(-0.05, 1.05)
        finish_time_axis(ax, t)
        mark_events(ax, marks, label=True)
        legend_right(ax)
        if not panels:
            ax.set_title("rotor faults")
        k += 1
    if not measured:
        ax = axs[k]
        for name, color, label in (("guid_iter", CMD_COLOR, "guidance QP"),
                                   ("alloc_iter", MEAS_COLOR, "allocation QP")):
            sig = result.optional(f"ctrl.{name}")
            if sig is not None:
                draw_line(ax, t, sig, color=color, lw=0.8, label=label)
        ax.set_ylabel("iterations [-]")
        ax.set_title("QP iterations (computation times not measured: controller timing off)")
        finish_time_axis(ax, t)
        legend_right(ax)
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
    fig.suptitle(figure_title(result, "disturbances and guidance computation"))
    return fig
