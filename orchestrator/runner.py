"""One scenario end to end: run, write the results, metrics and plots.

Files written into the output directory:

- ``results.parquet``  every recorded signal at every step, typed columns with the run's
  metadata (``orchestrator.output.run_result``; ``RunResult.read``)
- ``results.csv``      the same in text, exact float64 (on request: ``csv=True``)
- ``results.mcap``     the same as MCAP for Foxglove and PlotJuggler (``mcap=True``)
- ``metrics.json``     the metrics summary (``orchestrator.output.metrics``) and the run metadata
- ``*.png``            the paper's figures for this run (``orchestrator.output.plots``), drawn by
  worker processes beside the run where the OS allows (``orchestrator.output.figure_pool``)

The folder is whole or absent: everything is written into a hidden temporary folder beside
it, which replaces the previous folder only once complete.  A run that fails or is
interrupted leaves the previous results as they were; a folder that does not look like
results (no ``metrics.json``, not empty) is never replaced.  A run killed outright (SIGKILL)
may leave its temporary files, and, killed between the two moves that publish, the previous
results moved aside: every run first puts that right (:func:`recover`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import shutil
import time
import uuid
import weakref
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from orchestrator.master import SPILL_BYTES, run
from orchestrator.output import figure_pool as owners  # (whose a temporary file is)
from orchestrator.output.metrics import compare_with_paper, compute_metrics
from orchestrator.output.run_result import CSV_FILE, RESULTS_FILE, RunResult
from orchestrator.scenario.catalogue import load_scenario, scenario_names
from orchestrator.scenario.model import Scenario
from orchestrator.scenario.parser import with_overrides

if TYPE_CHECKING:
    from orchestrator.output.figure_pool import FigurePool

RESULT_MARKER = "metrics.json"
"""Every results folder holds this file; only such folders (or empty ones) are replaced."""


class OutputError(OSError):
    """The results folder cannot be written; the message names it and why."""


@dataclass
class RunOutput:
    """What a run gives back: the result, the metrics, the files written, the lines comparing the
    paper's claims and the phases' wall times."""
    result: RunResult
    metrics: dict[str, Any]
    files: list[Path]
    paper: list[str]
    timings: dict[str, float] = field(default_factory=dict)
    """Wall time of each phase, s: ``setup`` (FMUs loaded and initialized, references
    sampled), ``loop``, ``metrics``, ``results``, ``csv``, ``json``, ``figures`` (waiting for
    them after the rest was written), ``publish``."""


def prepare(name_or_path: str | Path, duration: float | None = None,
            settings: Iterable[str] = (), airframe: str | Path | None = None,
            gains: str | Path | None = None) -> Scenario:
    """Load and validate a scenario with the command line's overrides (nothing runs yet):
    ``airframe`` flies it on another airframe (a shipped name or an airframe file),
    ``gains`` with the gains of a gains file (``fullpose design``), ``settings`` last.
    The scenario's warnings gain one when the airframe's actuator lag lies outside the range
    the gains in use are certified for."""
    from controller.design_check import lag_warning, read_gains

    scenario = load_scenario(name_or_path)
    settings = list(settings)
    if airframe is not None:
        scenario = with_overrides(scenario, airframe=airframe)
    gains_file = read_gains(gains) if gains is not None else None
    if gains_file is not None:
        scenario = dataclasses.replace(scenario, controller_parameters={
            **scenario.controller_parameters, **gains_file.controller_parameters()})
    if duration is not None or settings:
        scenario = with_overrides(scenario, duration=duration, settings=settings)
    lag = lag_warning(scenario.airframe, gains_file)
    if lag is not None:
        scenario = dataclasses.replace(scenario, warnings=(*scenario.warnings, lag))
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


_LEFTOVER = re.compile(r"\.(.+)\." + owners.TAG
                       + r"\.[0-9a-f]+\.(partial|old|trash|recording\.npy)")
"""What a run leaves beside its results folder ``NAME`` while it works, named
``.NAME.PID-START.RANDOM.KIND`` (the owner tag: ``orchestrator.output.figure_pool.owner_tag``):
``partial`` the results being written, ``old`` the previous results moved aside for the
moment between the two moves that publish, ``trash`` the previous results being removed,
``recording.npy`` a long run's recording (``master.SPILL_BYTES``)."""
_LEGACY = re.compile(r"\.(.+)\.([0-9a-f]{12}\.partial|[a-z0-9_]{8}\.old)")
"""The same of earlier versions, without an owner: ``.NAME.<12 hex>.partial`` and the
``.NAME.<8 random>.old`` folder holding the previous results as ``NAME``."""
LEGACY_PARTIAL_AGE = 3600.0
"""s: an ownerless ``partial`` folder of an earlier version untouched for this long is a
killed run's (no run writes its results for an hour without adding a file)."""


def _temporary(out_dir: Path, kind: str) -> Path:
    """A name for a temporary folder of ``kind`` beside ``out_dir``, tagged with this
    process."""
    return out_dir.absolute().parent / (f".{out_dir.name}.{owners.owner_tag()}."
                                        f"{uuid.uuid4().hex[:12]}.{kind}")


def recover(out_dir: Path) -> list[str]:
    """Puts right what killed runs left beside ``out_dir``, in its parent folder: the
    previous results of a run killed between the two moves that publish (``NAME`` missing,
    ``.NAME.*.old`` there) go back into place; the temporary folders and recording files of
    runs that no longer run are removed, whatever results folder they were for.  A live
    run's files are never touched, nor a folder that does not hold what a run writes.
    Returns what was done, one line each.  Safe at every instant: each step is one rename
    or the removal of a folder no one needs; a step that fails is left for the next run."""
    parent = Path(out_dir).absolute().parent
    try:
        entries = [p for p in parent.iterdir() if p.name.startswith(".")]
    except OSError:
        return []
    done: list[str] = []
    olds: dict[str, list[Path]] = {}
    for path in entries:
        m = _LEFTOVER.fullmatch(path.name)
        if m is not None:
            if owners.tag_alive(m, 2):
                continue
            if m.group(4) == "old":
                olds.setdefault(m.group(1), []).append(path)
            else:
                _remove(path)
                done.append(f"removed {path.name}, left by a run that no longer runs")
            continue
        m = _LEGACY.fullmatch(path.name)
        if m is None or not path.is_dir() or path.is_symlink():
            continue
        name = m.group(1)
        if m.group(2).endswith(".old"):  # (the previous results inside, as NAME)
            inside = [p.name for p in _listing(path)]
            if inside == [name] and (path / name).is_dir():
                if _vacant(parent / name) and _move(path / name, parent / name):
                    done.append(f"restored {name} from {path.name}, left by a killed run")
                    inside = []
                elif _holds_results(parent / name) and _results_or_empty(path / name):
                    _remove(path / name)  # results older than those in place
                    inside = []
            if not inside:
                with contextlib.suppress(OSError):
                    path.rmdir()
        elif _results_or_empty(path):
            with contextlib.suppress(OSError):
                if time.time() - path.stat().st_mtime > LEGACY_PARTIAL_AGE:
                    _remove(path)
                    done.append(f"removed {path.name}, left by a killed run")
    for name, found in olds.items():
        target = parent / name
        if _vacant(target):
            newest = max(found, key=_changed)  # (several only from runs side by side)
            if _move(newest, target):
                found.remove(newest)
                done.append(f"restored {name} from {newest.name}: the run publishing it was "
                            "killed between its two moves")
        if _holds_results(target):  # the others are older results, replaced since
            for path in found:
                _discard(path)
                done.append(f"removed {path.name}, left by a run that no longer runs")
    return done


_RUN_FILES = re.compile(r"(results\.(parquet|csv|mcap|npz)|metrics\.json|force_sets\.json|"
                        r"[\w.-]+\.png)")
"""The names of the files a run writes into its results folder."""


def _listing(folder: Path) -> list[Path]:
    try:
        return list(folder.iterdir())
    except OSError:
        return []


def _results_or_empty(folder: Path) -> bool:
    """Whether ``folder`` holds only files a run writes (or nothing): ours to remove."""
    return folder.is_dir() and all(p.is_file() and _RUN_FILES.fullmatch(p.name)
                                   for p in _listing(folder))


def _holds_results(folder: Path) -> bool:
    return (folder / RESULT_MARKER).is_file()


def _vacant(target: Path) -> bool:
    """Whether results can be moved back to ``target``: it is missing (or an empty folder,
    which goes)."""
    if target.is_dir() and not target.is_symlink() and not _listing(target):
        with contextlib.suppress(OSError):
            target.rmdir()
    return not target.exists() and not target.is_symlink()


def _move(src: Path, dst: Path) -> bool:
    try:
        os.replace(src, dst)
    except OSError:
        return False
    return True


def _remove(path: Path) -> None:
    """Removes a file or a folder tree; what cannot be removed stays (errors ignored)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            path.unlink()


def _changed(path: Path) -> float:
    with contextlib.suppress(OSError):
        return path.stat().st_ctime
    return 0.0


def _discard(folder: Path) -> None:
    """Removes a folder of results no one needs: renamed first (one atomic step), so a
    removal cut short leaves a ``trash`` folder, never a half ``old`` one that could be
    restored."""
    trash = folder.with_name(f"{folder.name.rsplit('.', 1)[0]}.trash")
    try:
        os.replace(folder, trash)
    except OSError:
        trash = folder
    _remove(trash)


def publish(out_dir: Path, write: Callable[[Path], None]) -> None:
    """``write(tmp)`` fills a temporary folder beside ``out_dir``, which then replaces
    ``out_dir`` whole; on any failure (or Ctrl-C) the temporary folder is removed and
    ``out_dir`` is left as it was.  Killed at any instant (SIGKILL, a power cut of the
    process), it leaves ``out_dir`` either as it was or whole and new, or, between the two
    moves, the previous results in a ``.NAME.*.old`` folder that the next run (its
    :func:`recover`) moves back."""
    out_dir = Path(out_dir)
    recover(out_dir)
    check_output_dir(out_dir)
    try:
        out_dir.absolute().parent.mkdir(parents=True, exist_ok=True)
        tmp = _temporary(out_dir, "partial")
        tmp.mkdir()  # (not mkdtemp: the results get the user's usual permissions)
    except OSError as e:
        raise OutputError(f"{out_dir}: cannot create the results folder: "
                          f"{e.strerror or e}") from None
    old: Path | None = None
    try:
        write(tmp)
        if out_dir.exists():
            old = _temporary(out_dir, "old")
            os.replace(out_dir, old)  # a folder cannot replace a folder on every OS:
        os.replace(tmp, out_dir)      # move the old one aside first
    except BaseException:
        if old is not None and not out_dir.exists() and old.exists():
            os.replace(old, out_dir)  # interrupted between the two moves
        _remove(tmp)
        if old is not None and old.exists():
            _discard(old)
        raise
    if old is not None:
        _discard(old)


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
                 plots: bool = True, csv: bool = False, progress: bool | None = None,
                 engine: str = "native", figure_workers: bool | None = None,
                 mcap: bool = False,
                 spill_above: int = SPILL_BYTES, pil: Path | None = None) -> RunOutput:
    """Run and, with an output directory, write results, metrics and figures (whole or not
    at all: :func:`publish`).  A lost vehicle is a completed call: ``metrics["outcome"]``
    says ``"lost"``, with the time and reason in ``metrics["lost"]``.  ``figure_workers``:
    draw the figures in worker processes started before the run (None: where
    :func:`orchestrator.output.figure_pool.available`)."""
    spill = None
    if out_dir is not None:
        recover(out_dir)  # what killed runs left: the previous results back, the rest gone
        check_output_dir(out_dir)  # before the run, not after minutes of it
        here = _existing(Path(out_dir).absolute().parent)
        _remove_stale_spills(here, Path(out_dir).name)
        spill = here / _temporary(Path(out_dir), "recording.npy").name
        if plots:
            from orchestrator.output.figure_pool import remove_stale_handoffs

            remove_stale_handoffs()
    draw = plots and out_dir is not None
    pool = _start_pool(scenario) if draw and figure_workers is not False else None
    out = None
    try:
        out = _run_and_write(scenario, out_dir, pool, timing=timing, plots=draw, csv=csv,
                             progress=progress, engine=engine, spill=spill,
                             spill_above=spill_above, mcap=mcap, pil=pil)
        return out
    finally:
        if pool is not None:
            pool.close()
        if spill is not None:
            _remove_spill(spill, out)


def _existing(folder: Path) -> Path:
    """The folder, or its nearest ancestor that exists (the results folder's parent may be
    created only when the results are published)."""
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


FORCE_SETS_FILE = "force_sets.json"
"""A results folder's record of the force sets the controller flew with
(:func:`controller.derived_sets.flown_sets`)."""


def _remove_stale_spills(folder: Path, name: str) -> None:
    """Removes the recording files killed runs left in ``folder`` (where the results
    folder's parent does not exist yet, the nearest folder that does): those of runs that no
    longer run, and the ownerless ones of earlier versions of the same results folder (safe
    even while another run maps one: POSIX keeps a removed file for the process that maps
    it, and Windows refuses to remove a file in use; the error is ignored)."""
    with contextlib.suppress(OSError):
        for stale in folder.glob(".*.recording.npy"):
            m = _LEFTOVER.fullmatch(stale.name)
            if m is not None and not owners.tag_alive(m, 2):
                _forget(stale)
            elif m is None and re.fullmatch(rf"\.{re.escape(name)}\.[0-9a-f]{{12}}"
                                            r"\.recording\.npy", stale.name):
                _forget(stale)


def _remove_spill(path: Path, out: RunOutput | None) -> None:
    """Removes a long run's recording file (``master.SPILL_BYTES``) once it is written out.
    The returned result still maps it: on POSIX a removed file stays readable while mapped;
    where it cannot be removed while mapped (Windows), it goes when the result does."""
    try:
        path.unlink(missing_ok=True)
    except OSError:
        if out is not None:
            weakref.finalize(out.result.data, _forget, path)


def _forget(path: Path) -> None:
    with contextlib.suppress(OSError):
        path.unlink(missing_ok=True)


def _start_pool(scenario: Scenario) -> FigurePool | None:
    from orchestrator.output import figure_pool

    if not figure_pool.available():
        return None
    try:
        return figure_pool.FigurePool(scenario.airframe)
    except OSError:  # no processes to be had: the figures are drawn here
        return None


def _run_and_write(scenario: Scenario, out_dir: Path | None, pool: FigurePool | None, *,
                   timing: bool, plots: bool, csv: bool, progress: bool | None,
                   engine: str, spill: Path | None = None,
                   spill_above: int = SPILL_BYTES, mcap: bool = False,
                   pil: Path | None = None) -> RunOutput:
    timings: dict[str, float] = {}
    mark = time.perf_counter()

    def phase(name: str) -> None:
        nonlocal mark
        now = time.perf_counter()
        timings[name] = timings.get(name, 0.0) + now - mark
        mark = now

    result = run(scenario, timing=timing, progress=progress, engine=engine, spill=spill,
                 spill_above=spill_above, pil=pil)
    spilled = spill is not None and spill.exists()  # a long run: its recording is that file
    phase("setup")
    timings["loop"] = float(result.meta["wall_time"])
    timings["setup"] -= timings["loop"]
    metrics = compute_metrics(result)
    lost = metrics.get("lost")
    why_not = (f"the vehicle was lost at t = {lost['time']:.3f} s" if lost
               else paper_conditions(scenario))
    paper = compare_with_paper(metrics, scenario.name, not_comparable=why_not)
    names: list[str] = []
    phase("metrics")

    def write(folder: Path) -> None:
        from orchestrator.output.figure_names import RUN_FIGURES
        from orchestrator.output.figure_pool import HANDOFF_BYTES

        handed = False  # whether the workers have the run
        if pool is not None and plots and spilled:  # they map the recording's file
            pool.submit(result, RUN_FIGURES, recording=spill)
            handed = True
        elif pool is not None and plots and result.data.nbytes <= HANDOFF_BYTES:
            try:  # first: the workers draw while this writes
                pool.submit(result, RUN_FIGURES)
                handed = True
            except OSError:  # no room for the copy: they read the results file instead
                pass
        result.write_parquet(folder / RESULTS_FILE)
        names.append(RESULTS_FILE)
        if pool is not None and plots and not handed:  # a long run: no second copy of it
            pool.submit(result, RUN_FIGURES, written=folder / RESULTS_FILE)
        phase("results")
        if csv:
            result.write_csv(folder / CSV_FILE)
            names.append(CSV_FILE)
            phase("csv")
        if mcap:
            from orchestrator.output.mcap_export import MCAP_FILE, write_mcap

            write_mcap(result, folder / MCAP_FILE)
            names.append(MCAP_FILE)
            phase("mcap")
        from controller.derived_sets import flown_sets

        # the force sets the controller flew with, beside the airframe record in the meta
        (folder / FORCE_SETS_FILE).write_text(json.dumps(flown_sets(scenario.airframe)) + "\n")
        names.append(FORCE_SETS_FILE)
        doc = {"scenario": scenario.name, "metrics": metrics, "paper": paper,
               "meta": result.meta}
        (folder / RESULT_MARKER).write_text(json.dumps(doc, indent=2, default=str) + "\n")
        names.append(RESULT_MARKER)
        phase("json")
        if not plots:
            return
        if pool is None:
            names.extend(p.name for p in plot_files(result, folder, scenario))
        else:
            for name, png in pool.collect().items():
                (folder / f"{name}.png").write_bytes(png)
                names.append(f"{name}.png")
        phase("figures")

    files: list[Path] = []
    if out_dir is not None:
        publish(out_dir, write)
        phase("publish")
        files = [Path(out_dir) / n for n in names]
    return RunOutput(result=result, metrics=metrics, files=files, paper=paper,
                     timings=timings)


def plot_files(result: RunResult, out_dir: Path, scenario: Scenario) -> list[Path]:
    """Draw the run's figures into out_dir (in this process)."""
    from orchestrator.output.plots import plot_run

    return plot_run(result, out_dir, force_set_png=True, airframe=scenario.airframe)
