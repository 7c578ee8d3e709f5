"""What the rotor-fault campaign leaves (``fullpose sweep --faults``,
:mod:`orchestrator.sweep_faults`): its table (CSV, Parquet), its counts and statistics per
design as printed lines and a Markdown report, and the figure ``sweep_faults.png``
(:func:`write_fault_outputs`)."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from orchestrator.sweep import DIVERGED_BOUND
from orchestrator.sweep_faults import (
    EST_TOL,
    FAULT_COLUMNS,
    HEADING_BOUND,
    LOSS_MIN,
    summarize_faults,
)
from orchestrator.sweep_report import table_rows

FAULT_FIGURE = "sweep_faults.png"


def fault_stats(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """:func:`~orchestrator.sweep_faults.summarize_faults` per design."""
    return {d: summarize_faults([r for r in rows if r["design"] == d])
            for d in sorted({r["design"] for r in rows})}


def _ms(x: float) -> str:
    return "n/a" if math.isnan(x) else f"{1e3 * x:.0f} ms"


def _num(x: float) -> str:
    return "n/a" if math.isnan(x) else f"{x:.4f}"


def summary_lines(design: str, s: dict[str, float]) -> list[str]:
    """One design's counts and statistics as the lines ``fullpose sweep --faults`` prints."""
    return [
        f"{design}: {s['loads']:.0f} load cases, {s['faults']:.0f} fault cases "
        f"({s['total_losses']:.0f} of them total losses)",
        f"  false alarms        {s['false_alarms']:.0f} (load cases {s['false_alarms_load']:.0f}, "
        f"fault cases {s['false_alarms_fault']:.0f}); healthy rotors declared lost "
        f"{s['false_lost']:.0f}",
        f"  missed detections   {s['missed']:.0f} of {s['faults']:.0f} faults (loss >= "
        f"{LOSS_MIN:g}; total losses missed {s['missed_total']:.0f})",
        f"  estimate error      mean {_num(s['est_err_mean'])}, max {_num(s['est_err_max'])} "
        f"over {s['detected']:.0f} detected; > {EST_TOL:g}: {s['est_off']:.0f}",
        f"  detection time      median {_ms(s['detect_time_median'])}, p95 "
        f"{_ms(s['detect_time_p95'])}, max {_ms(s['detect_time_max'])} (total losses: median "
        f"{_ms(s['lost_time_median'])}, max {_ms(s['lost_time_max'])})",
        f"  not held            {s['not_held']:.0f} cases (position or heading lost); in the "
        f"cases held: false alarms {s['false_alarms_held']:.0f}, missed "
        f"{s['missed_held']:.0f}"]


def write_fault_outputs(rows: Sequence[dict[str, Any]], out: Path,
                        meta: dict[str, Any]) -> list[Path]:
    """Write the fault campaign's files into out (sweep.csv, sweep.parquet, report.md,
    sweep_faults.png); the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / "sweep.csv"
    with path.open("w", newline="") as f:
        csv.writer(f).writerows(table_rows(rows, deterministic=False, columns=FAULT_COLUMNS))
    files = [path]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq

        pq.write_table(pa.table({c: [r[c] for r in rows] for c in FAULT_COLUMNS}),
                       out / "sweep.parquet")
        files.append(out / "sweep.parquet")
    except ImportError:
        pass
    files.append(plot_faults(rows, out))
    (out / "report.md").write_text(fault_report_markdown(fault_stats(rows), meta))
    files.append(out / "report.md")
    return files


def fault_report_markdown(stats: dict[str, dict[str, float]], meta: dict[str, Any]) -> str:
    """The fault campaign's report as Markdown."""
    frame = meta.get("airframe") or "the scenario's"
    lines = ["# Rotor-fault campaign", "",
             f"{meta.get('n')} cases (half loads, half faults) x {len(stats)} design(s), seed "
             f"{meta.get('seed')}, {meta.get('duration')} s each, scenario "
             f"{meta.get('scenario')}, airframe {frame}; "
             "loads: mass x U(0.7, 1.3), payload U(5, 15) % at an arm tip, torque step "
             "U(0.05, 0.3) N m, force step U(0.05, 0.3) x weight; faults: a rotor at "
             "efficiency 0 or U(0, 0.9), half with a load; sensor noise x "
             f"{meta.get('noise', 1.0):g}; the controller is never told.", "",
             "| design | cases | false alarms (load / fault) | healthy declared lost | missed "
             f"| estimate error mean / max | error > {EST_TOL:g} | detection time median / p95 "
             "/ max | not held |",
             "|---|---|---|---|---|---|---|---|---|"]
    for d, s in stats.items():
        lines.append(
            f"| {d} | {s['cases']:.0f} | {s['false_alarms']:.0f} ({s['false_alarms_load']:.0f} "
            f"/ {s['false_alarms_fault']:.0f}) | {s['false_lost']:.0f} | {s['missed']:.0f} of "
            f"{s['faults']:.0f} | {_num(s['est_err_mean'])} / {_num(s['est_err_max'])} | "
            f"{s['est_off']:.0f} | {_ms(s['detect_time_median'])} / "
            f"{_ms(s['detect_time_p95'])} / {_ms(s['detect_time_max'])} | "
            f"{s['not_held']:.0f} |")
    lines.append("")
    for d, s in stats.items():
        lines.append(f"{d}: in the {s['cases'] - s['not_held']:.0f} cases held (position error "
                     f"below {DIVERGED_BOUND:g} m, heading error below {HEADING_BOUND:g} rad): "
                     f"false alarms {s['false_alarms_held']:.0f}, missed "
                     f"{s['missed_held']:.0f}.")
    lines += ["", "Definitions: orchestrator/sweep_faults.py (module docstring)."]
    if meta.get("wall_time") is not None:
        lines += ["", f"Wall time {meta['wall_time']:.1f} s with {meta.get('workers')} "
                  f"worker(s)."]
    lines += ["", f"Files: sweep.csv (one row per run), {FAULT_FIGURE} (estimates, detection "
              "times, counts).", ""]
    return "\n".join(lines)


def plot_faults(rows: Sequence[dict[str, Any]], out: Path) -> Path:
    """The figure: final estimate against the true efficiency (missed faults at their
    untouched 1), detection time against the true efficiency, the counts; its path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 4))
    FigureCanvasAgg(fig)
    faults = [r for r in rows if r["kind"] == "fault"]
    _plot_estimates(fig.add_subplot(1, 3, 1), faults)
    found = [r for r in faults if not math.isnan(r["detect_time"])]
    ax = fig.add_subplot(1, 3, 2)
    ax.plot([r["fault_eff"] for r in found], [1e3 * r["detect_time"] for r in found], "o", ms=3)
    ax.set_xlabel("true efficiency")
    ax.set_ylabel("detection time after the fault (ms)")
    _plot_counts(fig.add_subplot(1, 3, 3), summarize_faults(rows))
    fig.tight_layout()
    path = out / FAULT_FIGURE
    fig.savefig(path, dpi=100)
    return path


def _plot_estimates(ax: Any, faults: Sequence[dict[str, Any]]) -> None:
    """Final estimate against the truth, the EST_TOL band, missed and not-held faults."""
    found = [r for r in faults if not math.isnan(r["detect_time"])]
    missed = [r for r in faults if math.isnan(r["detect_time"])]
    loose = [r for r in faults if not r["held"]]
    ax.plot([0, 1], [0, 1], "k-", lw=0.5)
    ax.fill_between([0, 1], [-EST_TOL, 1 - EST_TOL], [EST_TOL, 1 + EST_TOL], color="0.9")
    ax.plot([r["fault_eff"] for r in found], [r["est"] for r in found], "o", ms=3,
            label="detected")
    ax.plot([r["fault_eff"] for r in missed], [1.0] * len(missed), "x", color="C3",
            label="missed")
    ax.plot([r["fault_eff"] for r in loose],
            [1.0 if math.isnan(r["est"]) else r["est"] for r in loose],
            "o", ms=8, mfc="none", color="0.4", label="not held")
    ax.set_xlabel("true efficiency")
    ax.set_ylabel("final estimate")
    ax.legend(fontsize=8)


def _plot_counts(ax: Any, s: dict[str, float]) -> None:
    """The counts as horizontal bars."""
    from matplotlib.ticker import MaxNLocator

    names = ("false alarms, loads", "false alarms, faults", "missed",
             f"estimate error > {EST_TOL:g}", "not held")
    vals = [s[k] for k in ("false_alarms_load", "false_alarms_fault", "missed", "est_off",
                           "not_held")]
    bars = ax.barh(np.arange(len(vals)), vals, color=["C3", "C3", "C1", "C1", "0.5"])
    ax.bar_label(bars, fmt="%d", padding=3)
    ax.set_yticks(np.arange(len(vals)), names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, max(1.0, *vals) * 1.15)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title(f"{s['cases']:.0f} runs: {s['loads']:.0f} loads, {s['faults']:.0f} faults",
                 fontsize=9)
