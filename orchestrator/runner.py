"""One scenario end to end: run, write the results, metrics and plots.

Files written into the output directory:

- ``results.csv``    every recorded signal at every step (header = column names)
- ``results.npz``    the same, compressed numpy archive with the columns and run metadata
  (``RunResult.read_npz``)
- ``metrics.json``   the metrics summary (``orchestrator.metrics``) and the run metadata
- ``*.png``          the paper's figures for this run (``orchestrator.plots``)
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from orchestrator.master import run
from orchestrator.metrics import compare_with_paper, compute_metrics
from orchestrator.results import RunResult
from orchestrator.scenario import Scenario, load_scenario


@dataclass
class RunOutput:
    result: RunResult
    metrics: dict[str, Any]
    files: list[Path]
    paper: list[str]


def prepare(name_or_path: str | Path, duration: float | None = None,
            settings: Iterable[str] = ()) -> Scenario:
    """Load and validate a scenario with the command line's overrides (nothing runs yet)."""
    scenario = load_scenario(name_or_path)
    settings = list(settings)
    if duration is not None or settings:
        scenario = scenario.with_overrides(duration=duration, settings=settings)
    return scenario


def run_scenario(scenario: Scenario, out_dir: Path | None = None, *, timing: bool = True,
                 plots: bool = True, csv: bool = True, progress: bool | None = None,
                 engine: str = "native") -> RunOutput:
    """Run and, with an output directory, write results, metrics and figures."""
    result = run(scenario, timing=timing, progress=progress, engine=engine)
    metrics = compute_metrics(result)
    paper = compare_with_paper(metrics, scenario.name)
    files: list[Path] = []
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        if csv:
            result.write_csv(out_dir / "results.csv")
            files.append(out_dir / "results.csv")
        result.write_npz(out_dir / "results.npz")
        files.append(out_dir / "results.npz")
        doc = {"scenario": scenario.name, "metrics": metrics, "paper": paper,
               "meta": result.meta}
        (out_dir / "metrics.json").write_text(json.dumps(doc, indent=2, default=str) + "\n")
        files.append(out_dir / "metrics.json")
        if plots:
            files += plot_files(result, out_dir, scenario)
    return RunOutput(result=result, metrics=metrics, files=files, paper=paper)


def plot_files(result: RunResult, out_dir: Path, scenario: Scenario) -> list[Path]:
    from orchestrator.plots import plot_run

    return plot_run(result, out_dir, force_set_png=True, airframe=scenario.airframe)
