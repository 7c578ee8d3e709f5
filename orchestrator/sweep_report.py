"""What a Monte-Carlo campaign leaves (``fullpose sweep``, :mod:`orchestrator.sweep`): the table
of runs (CSV, Parquet), the statistics per design, the model-mismatch sensitivity, the
Markdown report and the figures.  The rotor-fault campaign's (``fullpose sweep --faults``):
:mod:`orchestrator.sweep_faults_report`."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from orchestrator.sweep import BASE_DESIGNS, COLUMNS, DIVERGED_BOUND, MATCHED


def table_rows(rows: Sequence[dict[str, Any]], deterministic: bool = True,
               columns: Sequence[str] = COLUMNS) -> list[list[str]]:
    """The table of rows as text cells, header first (without wall times when deterministic;
    ``columns``: the campaign's, default the disturbance campaign's)."""
    cols = [c for c in columns if not (deterministic and c == "wall_time")]
    out = [cols]
    for r in rows:
        out.append([f"{r[c]:.10g}" if isinstance(r[c], float) else str(r[c]) for c in cols])
    return out


def write_outputs(rows: Sequence[dict[str, Any]], out: Path, meta: dict[str, Any]) -> list[Path]:
    """Write the sweep's files into out (sweep.csv, sweep.parquet, report.md, the figures);
    the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    files = []
    path = out / "sweep.csv"
    with path.open("w", newline="") as f:
        csv.writer(f).writerows(table_rows(rows, deterministic=False))
    files.append(path)
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq

        tbl = pa.table({c: [r[c] for r in rows] for c in COLUMNS})
        pq.write_table(tbl, out / "sweep.parquet")
        files.append(out / "sweep.parquet")
    except ImportError:
        pass
    stats = summarize(rows)
    files += plot(rows, out)
    (out / "report.md").write_text(report_markdown(stats, meta, sensitivity(rows)))
    files.append(out / "report.md")
    return files


def summarize(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per design: stable fraction, mean and worst max error, mean RMS error and recovery time."""
    out = {}
    for d in sorted({r["design"] for r in rows}):
        rs = [r for r in rows if r["design"] == d]
        st = [r for r in rs if r["stable"]]
        mx = np.array([r["max_err"] for r in st]) if st else np.array([np.nan])
        rm = np.array([r["rms_err"] for r in st]) if st else np.array([np.nan])
        rc = np.array([r["recovery_time"] for r in st]) if st else np.array([np.nan])
        out[d] = {"runs": len(rs), "stable_fraction": len(st) / max(len(rs), 1),
                  "max_err_mean": float(mx.mean()), "max_err_p95": float(np.percentile(mx, 95)),
                  "max_err_worst": float(mx.max()), "rms_err_mean": float(rm.mean()),
                  "recovery_mean": float(rc.mean()), "recovery_p95": float(np.percentile(rc, 95))}
    return out


SAMPLED = ("mass_scale", "ixx_scale", "iyy_scale", "izz_scale", "tau_motor_scale",
           "tau_servo_scale", "noise_scale")


def sensitivity(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    """The model-mismatch view: per design and sampled plant parameter, how the max error per
    unit disturbance (m per m/s^2, stable runs) depends on it - the Pearson correlation and
    the mean in the parameter's lowest and highest quartile of cases."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for d in sorted({r["design"] for r in rows}):
        st = [r for r in rows if r["design"] == d and r["stable"]]
        if len(st) < 4:
            continue
        y = np.array([r["max_err"] / r["dist_amp"] for r in st])
        out[d] = {}
        for key in SAMPLED:
            x = np.array([r[key] for r in st], dtype=float)
            lo, hi = np.percentile(x, [25, 75])
            corr = float(np.corrcoef(x, y)[0, 1]) if np.ptp(x) > 0 and np.ptp(y) > 0 else 0.0
            out[d][key] = {"corr": corr, "low": float(y[x <= lo].mean()),
                           "high": float(y[x >= hi].mean())}
    return out


def report_markdown(stats: dict[str, dict[str, float]], meta: dict[str, Any],
                    sens: dict[str, dict[str, dict[str, float]]] | None = None) -> str:
    """The sweep's report as Markdown."""
    lines = ["# Robustness sweep", "",
             f"{meta.get('n')} cases x {len(stats)} designs, seed {meta.get('seed')}, "
             f"{meta.get('duration')} s each; plant mass +-30 %, inertia +-50 %, actuator time "
             "constants +-30 %, acceleration disturbance steps 0.5-3 m/s^2 in random "
             f"directions, sensor noise x {meta.get('noise', 1.0):g}; controller at nominal "
             "mass/inertia.", "",
             "| design | runs | stable | max err mean (m) | max err p95 (m) | worst (m) | "
             "RMS err mean (m) | recovery mean (s) | recovery p95 (s) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for d, s in stats.items():
        lines.append(f"| {d} | {s['runs']} | {100 * s['stable_fraction']:.0f} % | "
                     f"{s['max_err_mean']:.4f} | {s['max_err_p95']:.4f} | "
                     f"{s['max_err_worst']:.4f} | {s['rms_err_mean']:.4f} | "
                     f"{s['recovery_mean']:.2f} | {s['recovery_p95']:.2f} |")
    pairs = [("hinf", "baseline", "H-infinity vs baseline (relative reduction)"),
             ("hinf", "prototype", "H-infinity vs the hand-tuned prototype gains (relative "
                                   "reduction)")]
    pairs += [(d + MATCHED, d, f"{d} told the true mass and inertia vs {d} at nominal values "
                               "(what the model mismatch costs, as a reduction)")
              for d in BASE_DESIGNS]
    for better, ref, title in pairs:
        if better in stats and ref in stats:
            h, b = stats[better], stats[ref]
            lines += ["", f"{title}: max error mean "
                      f"{_reduction(h['max_err_mean'], b['max_err_mean'])}, RMS error mean "
                      f"{_reduction(h['rms_err_mean'], b['rms_err_mean'])}, recovery mean "
                      f"{_reduction(h['recovery_mean'], b['recovery_mean'])}."]
    if meta.get("wall_time") is not None:
        lines += ["", f"Wall time {meta['wall_time']:.1f} s with {meta.get('workers')} "
                  f"worker(s) ({meta.get('throughput', float('nan')):.2f} runs/s)."]
    for d, per in (sens or {}).items():
        told = ("told the true mass and inertia" if d.endswith(MATCHED)
                else "keeps nominal mass and inertia")
        lines += ["", f"Model mismatch, {d}: max error per unit disturbance (mm per m/s^2) in "
                  "the lowest and highest quartile of each sampled parameter (the controller "
                  f"{told})", "",
                  "| parameter | correlation | low quartile | high quartile | high / low |",
                  "|---|---|---|---|---|"]
        for key, v in per.items():
            ratio = v["high"] / v["low"] if v["low"] > 0 else math.nan
            lines.append(f"| {key} | {v['corr']:+.2f} | {1e3 * v['low']:.2f} | "
                         f"{1e3 * v['high']:.2f} | {ratio:.2f} |")
    lines += ["", "Files: sweep.csv (one row per run), sweep_errors.png (distributions), "
              "sweep_worst.png (worst cases).", ""]
    return "\n".join(lines)


def _reduction(x: float, ref: float) -> str:
    return f"{100 * (1 - x / ref):.0f} %" if ref > 0 and math.isfinite(x / ref) else "n/a"


def plot(rows: Sequence[dict[str, Any]], out: Path) -> list[Path]:
    """The sweep's figures (errors per design, the worst cases) into out; the paths."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ds = sorted({r["design"] for r in rows})
    fig = Figure(figsize=(10, 4))
    FigureCanvasAgg(fig)
    for j, (key, label) in enumerate((("max_err", "max position error (m)"),
                                      ("rms_err", "RMS position error (m)"),
                                      ("recovery_time", "recovery time (s)"))):
        ax = fig.add_subplot(1, 3, j + 1)
        data = [[r[key] for r in rows if r["design"] == d and r["stable"]] or [np.nan]
                for d in ds]
        if _mpl_new():
            ax.boxplot(data, tick_labels=ds)
        else:  # matplotlib < 3.9
            ax.boxplot(data, labels=ds)  # type: ignore[call-arg]
        ax.set_title(label, fontsize=9)
    fig.tight_layout()
    p1 = out / "sweep_errors.png"
    fig.savefig(p1, dpi=100)
    fig = Figure(figsize=(8, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for d in ds:
        rs = sorted((r for r in rows if r["design"] == d), key=lambda r: -r["max_err"])[:10]
        ax.plot([r["case"] for r in rs], [min(r["max_err"], DIVERGED_BOUND) for r in rs], "o",
                label=d)
    ax.set_xlabel("case")
    ax.set_ylabel("max position error (m), 10 worst per design")
    ax.legend()
    fig.tight_layout()
    p2 = out / "sweep_worst.png"
    fig.savefig(p2, dpi=100)
    return [p1, p2]


def _mpl_new() -> bool:
    import matplotlib

    major, minor = (int(x) for x in matplotlib.__version__.split(".")[:2])
    return (major, minor) >= (3, 9)

