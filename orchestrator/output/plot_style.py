"""The drawing style every run figure shares: decimation of long signals to the pixel columns
(:func:`envelope`), shaded intervals, event marks, legends that never cover data, fixed-margin
figures on the Agg canvas and fast PNG output (see :mod:`orchestrator.output.plots`)."""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from orchestrator.output.events import Event
from orchestrator.output.run_result import RunResult

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


def draw_line(ax: Axes, t: np.ndarray, y: np.ndarray, **kw: Any) -> None:
    """Plot y over t decimated to two points per pixel column (:func:`envelope`)."""
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


def shade_intervals(ax: Axes, intervals: list[tuple[float, float]], label: str | None) -> None:
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


def columns(a: np.ndarray) -> np.ndarray:
    """A signal as (n, k) (scalar signals become one column)."""
    return a.reshape(a.shape[0], -1)


def new_figure(width: float, height: float, left: float = 0.07, right: float = 0.98,
                bottom: float = 0.06, top: float = 0.92, hspace: float = 0.2,
                wspace: float = 0.2) -> Figure:
    """A figure on the Agg canvas with fixed margins (no layout engine)."""
    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=left, right=right, bottom=bottom, top=top, hspace=hspace,
                        wspace=wspace)
    return fig


def figure_title(result: RunResult, what: str) -> str:
    """'what - scenario - airframe' for a figure's title."""
    scenario = result.meta.get("scenario")
    airframe = result.meta.get("airframe")
    parts = [what] + [str(p) for p in (scenario, airframe) if p]
    return " - ".join(parts)


def save_png(fig: Figure, path: Path) -> Path:
    """Write the figure as PNG to path (folders made); returns path."""
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


def finish_time_axis(ax: Axes, t: np.ndarray) -> None:
    """A time axis over the run, a light grid, and y ticks without an offset."""
    if t.size > 1:
        ax.set_xlim(float(t[0]), float(t[-1]))
    ax.grid(True, alpha=0.3)
    ax.ticklabel_format(axis="y", useOffset=False)  # -3.000, never -2.999 + 2e-4 ticks


def y_floor(ax: Axes, min_span: float) -> None:
    """At least ``min_span`` of y: a signal that is (nearly) zero shows its floor, not
    round-off autoscaled to 1e-14."""
    lo, hi = ax.get_ylim()
    if hi - lo < min_span:
        mid = 0.5 * (lo + hi)
        ax.set_ylim(mid - 0.5 * min_span, mid + 0.5 * min_span)


EVENT_STYLE = {"fault": ("#d62728", "-"), "detection": ("#9467bd", "--"),
               "disturbance": ("#8c564b", ":"), "reference": ("#7f7f7f", "-."),
               "ground": ("#2ca02c", "--"), "mission": ("#1f77b4", ":")}
"""Colour and line style of each kind of event marked on the time axes."""


def mark_events(ax: Axes, found: list[Event], label: bool = False) -> None:
    """Vertical lines at the events (faults, detections, disturbance steps, reference
    jumps, touchdowns and liftoffs); ``label``: one legend entry per kind."""
    seen: set[str] = set()
    for e in found:
        color, ls = EVENT_STYLE[e.kind]
        ax.axvline(e.time, color=color, ls=ls, lw=0.9, alpha=0.8,
                   label=e.kind if label and e.kind not in seen else None)
        seen.add(e.kind)


def legend_below(fig: Figure, axes: list[Axes], ncols: int = 6) -> None:
    """One legend for ``axes`` under the plots: it never covers data."""
    handles: dict[str, Any] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if not lab.startswith("_"):
                handles.setdefault(lab, h)
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="lower center", ncols=ncols,
                   fontsize=8, frameon=False)


def legend_right(ax: Axes) -> None:
    """The axes' legend outside it, on the right: it never covers data."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=7)
