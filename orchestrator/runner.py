"""One scenario end to end: run, write the results, metrics and plots.

Files written into the output directory:

- ``results.csv``    every recorded signal at every step (header = column names)
- ``results.npz``    the same, compressed numpy archive with the columns and run metadata
  (``RunResult.read_npz``)
- ``metrics.json``   the metrics summary (``orchestrator.metrics``) and the run metadata
- ``*.png``          the paper's figures for this run (``orchestrator.plots``)

The folder is whole or absent: everything is written into a hidden temporary folder beside
it, which replaces the previous folder only once complete.  A run that fails or is
interrupted leaves the previous results as they were; a folder that does not look like
results (no ``metrics.json``, not empty) is never replaced.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from orchestrator.master import run
from orchestrator.metrics import compare_with_paper, compute_metrics
from orchestrator.results import RunResult
from orchestrator.scenario import Scenario, load_scenario, scenario_names

RESULT_MARKER = "metrics.json"
"""Every results folder holds this file; only such folders (or empty ones) are replaced."""


class OutputError(OSError):
    """The results folder cannot be written; the message names it and why."""


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


def check_output_dir(out_dir: Path) -> None:
    """Refuses, before a run, an output folder that could not be replaced by its results."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputError(f"{out_dir}: exists and is not a folder; choose another --out")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / RESULT_MARKER).is_file():
        raise OutputError(f"{out_dir}: exists and does not hold fullpose results (no "
                          f"{RESULT_MARKER}), so it is not replaced; choose another --out")
    parent = out_dir.absolute().parent
    probe = parent
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise OutputError(f"{out_dir}: cannot create it, {probe} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OutputError(f"{out_dir}: cannot write into {probe} (permission denied)")


def publish(out_dir: Path, write: Callable[[Path], None]) -> None:
    """``write(tmp)`` fills a temporary folder beside ``out_dir``, which then replaces
    ``out_dir`` whole; on any failure (or Ctrl-C) the temporary folder is removed and
    ``out_dir`` is left as it was."""
    out_dir = Path(out_dir)
    check_output_dir(out_dir)
    parent = out_dir.absolute().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = parent / f".{out_dir.name}.{uuid.uuid4().hex[:12]}.partial"
        tmp.mkdir()  # (not mkdtemp: the results get the user's usual permissions)
    except OSError as e:
        raise OutputError(f"{out_dir}: cannot create the results folder: "
                          f"{e.strerror or e}") from None
    old: Path | None = None
    try:
        write(tmp)
        if out_dir.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", suffix=".old", dir=parent))
            os.replace(out_dir, old / out_dir.name)  # a folder cannot replace a folder on
        os.replace(tmp, out_dir)                     # every OS: move the old one aside first
    except BaseException:
        if old is not None and not out_dir.exists() and (old / out_dir.name).exists():
            os.replace(old / out_dir.name, out_dir)  # interrupted between the two moves
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def paper_conditions(scenario: Scenario) -> str | None:
    """Why this run cannot be compared with the paper's claims, or None when it can: a
    paper scenario run as shipped, for at least the shipped duration."""
    stem = Path(scenario.source).stem
    if stem not in scenario_names():
        return None  # not a paper scenario: there are no claims to compare with
    shipped = load_scenario(stem)
    reasons = []
    if Path(scenario.source).read_bytes() != Path(shipped.source).read_bytes():
        reasons.append(f"{scenario.source} differs from the shipped scenario file")
    if scenario.duration < shipped.duration:
        reasons.append(f"a {scenario.duration:g} s run; the paper's is {shipped.duration:g} s")
    changed = ([f"plant.{k}" for k, v in scenario.plant_parameters.items()
                if shipped.plant_parameters.get(k) != v]
               + [f"controller.{k}" for k, v in scenario.controller_parameters.items()
                  if shipped.controller_parameters.get(k) != v])
    if changed:
        reasons.append(f"parameters set: {', '.join(changed[:4])}"
                       + (", ..." if len(changed) > 4 else ""))
    return "; ".join(reasons) or None


def run_scenario(scenario: Scenario, out_dir: Path | None = None, *, timing: bool = True,
                 plots: bool = True, csv: bool = True, progress: bool | None = None,
                 engine: str = "native") -> RunOutput:
    """Run and, with an output directory, write results, metrics and figures (whole or not
    at all: :func:`publish`).  A lost vehicle is a completed call: ``metrics["outcome"]``
    says ``"lost"``, with the time and reason in ``metrics["lost"]``."""
    if out_dir is not None:
        check_output_dir(out_dir)  # before the run, not after minutes of it
    result = run(scenario, timing=timing, progress=progress, engine=engine)
    metrics = compute_metrics(result)
    lost = metrics.get("lost")
    why_not = (f"the vehicle was lost at t = {lost['time']:.3f} s" if lost
               else paper_conditions(scenario))
    paper = compare_with_paper(metrics, scenario.name, not_comparable=why_not)
    names: list[str] = []

    def write(folder: Path) -> None:
        if csv:
            result.write_csv(folder / "results.csv")
            names.append("results.csv")
        result.write_npz(folder / "results.npz")
        names.append("results.npz")
        doc = {"scenario": scenario.name, "metrics": metrics, "paper": paper,
               "meta": result.meta}
        (folder / RESULT_MARKER).write_text(json.dumps(doc, indent=2, default=str) + "\n")
        names.append(RESULT_MARKER)
        if plots:
            names.extend(p.name for p in plot_files(result, folder, scenario))

    files: list[Path] = []
    if out_dir is not None:
        publish(out_dir, write)
        files = [Path(out_dir) / n for n in names]
    return RunOutput(result=result, metrics=metrics, files=files, paper=paper)


def plot_files(result: RunResult, out_dir: Path, scenario: Scenario) -> list[Path]:
    from orchestrator.plots import plot_run

    return plot_run(result, out_dir, force_set_png=True, airframe=scenario.airframe)
