"""OpenModelica's OMSimulator, an importer nobody here wrote, plays the exported SSP through
its three doors: the command line, the C API (ctypes on libOMSimulator.so) and the Python
API (OMSimulator 3.0).  Each run is a separate process: the library keeps global state.

Oracles: the archive's own step (2 ms) read back through OMSimulator's C API; the hover
pose, which the closed loop must hold; and our runner flying the same pose with the same
(Jacobi) coupling, which the trajectories must match within 1e-9 m.  The tool is found by
tests/tools/omsimulator.sh (FULLPOSE_OMSIMULATOR, else the workplace's build); without it
these tests skip and say so.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from helpers import omsimulator

from orchestrator.export.ssp import experiment, export_ssp
from orchestrator.master import run
from orchestrator.scenario.parser import parse_scenario

pytestmark = pytest.mark.fmitools

POS0 = (0.5, -1.0, -3.0)
SECONDS = 2.0


@pytest.fixture(scope="module")
def oms() -> Path:
    return omsimulator()


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("oms") / "hover.ssp"
    export_ssp(path, pos0=POS0, stop_time=SECONDS)
    return path


@pytest.fixture(scope="module")
def ours() -> np.ndarray:
    """Our runner at the same pose, Jacobi coupling (what OMSimulator's master does):
    rows of [time, x, y, z]."""
    sc = parse_scenario({"name": "hover", "duration": SECONDS, "airframe": "paper_hexacopter",
                         "coupling": "jacobi",
                         "reference": {"position": {"x": POS0[0], "y": POS0[1], "z": POS0[2]}}})
    r = run(sc, progress=False)
    return np.column_stack([r.time, r.get("plant.pos")])


def run_python(code: str, oms: Path, cwd: Path) -> str:
    """Run `code` in a fresh interpreter with OMSimulator's Python API importable."""
    env = {**os.environ, "PYTHONPATH": str(oms / "lib" / "x86_64-linux-gnu")}
    res = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                         text=True, cwd=cwd, env=env, timeout=300, check=False)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    return res.stdout


def python_api_positions(oms: Path, archive: Path, tmp_path: Path) -> np.ndarray:
    """The archive played by OMSimulator 3.0's Python API at the archive's step (set with
    setFixedStepSize from experiment()): its result's plant positions (read_positions)."""
    out = tmp_path / "py.csv"
    run_python(f"""
        from OMSimulator import SSP
        from orchestrator.export.ssp import experiment
        model = SSP({str(archive)!r}, temp_dir={str(tmp_path / 'tmp')!r}).instantiate()
        model.setFixedStepSize(experiment({str(archive)!r})[2])
        model.setResultFile({str(out)!r})
        model.initialize()
        model.simulate()
        model.terminate()
        model.delete()
    """, oms, tmp_path)
    return read_positions(out)


def read_positions(path: Path, component: str = "MultirotorPlant") -> np.ndarray:
    """OMSimulator's CSV result as rows of [time, x, y, z] (the plant's pos; a time that
    appears twice, before and after an event, kept once: the last)."""
    with path.open() as f:
        rows = list(csv.reader(f))
    head = rows[0]
    cols = [head.index(next(c for c in head if c.endswith(f"{component}.pos[{i}]")))
            for i in (1, 2, 3)]
    data = np.array([[float(r[0])] + [float(r[c]) for c in cols] for r in rows[1:]])
    keep = np.append(np.diff(data[:, 0]) > 0, True)
    return data[keep]


def agree(theirs: np.ndarray, ours: np.ndarray) -> float:
    """Largest position difference at the times both recorded."""
    k = np.searchsorted(ours[:, 0], theirs[:, 0] - 1e-9)
    assert np.allclose(ours[k, 0], theirs[:, 0], atol=1e-9), "time grids do not meet"
    return float(np.abs(theirs[:, 1:] - ours[k, 1:]).max())


def test_the_command_line_plays_the_archive(oms, archive, ours, tmp_path):
    """`OMSimulator --stopTime=2 --resultFile=out.csv archive.ssp`: the system is created from
    OpenModelica's annotation (without it: "[NewSystem] internal error"), the loop holds the
    hover pose and matches our Jacobi run."""
    out = tmp_path / "out.csv"
    res = subprocess.run([str(oms / "bin" / "OMSimulator"), f"--stopTime={SECONDS}",
                          f"--resultFile={out}", "--suppressPath=true", str(archive)],
                         capture_output=True, text=True, cwd=tmp_path, timeout=300,
                         check=False)
    assert res.returncode == 0 and "0 errors" in res.stdout, res.stdout[-2000:]
    pos = read_positions(out)
    assert pos[-1, 0] == pytest.approx(SECONDS)
    assert np.abs(pos[:, 1:] - POS0).max() < 1e-9
    assert agree(pos, ours) < 1e-9


def test_the_c_api_reads_the_2ms_step_and_hovers(oms, archive, ours, tmp_path):
    lib = oms / "lib" / "x86_64-linux-gnu" / "libOMSimulator.so"
    out = run_python(f"""
        import ctypes
        lib = ctypes.CDLL({str(lib)!r})
        cref = ctypes.c_char_p()
        assert lib.oms_importFile({str(archive)!r}.encode(), ctypes.byref(cref)) == 0
        model = cref.value
        step = ctypes.c_double()
        assert lib.oms_getFixedStepSize(model + b".ClosedLoop", ctypes.byref(step)) == 0
        assert lib.oms_setStopTime(model, ctypes.c_double({SECONDS})) == 0
        for call in (lib.oms_instantiate, lib.oms_initialize, lib.oms_simulate):
            assert call(model) < 3, call  # ok or warning (the airframe's inertia note)
        pos = []
        for i in (1, 2, 3):
            v = ctypes.c_double()
            name = model + b".ClosedLoop.MultirotorPlant.pos[%d]" % i
            assert lib.oms_getReal(name, ctypes.byref(v)) == 0
            pos.append(v.value)
        print("STEP", repr(step.value))
        print("POS", *map(repr, pos))
        lib.oms_terminate(model)
        lib.oms_delete(model)
    """, oms, tmp_path)
    values = {ln.split()[0]: [float(x) for x in ln.split()[1:]] for ln in out.splitlines()
              if ln.startswith(("STEP", "POS"))}
    assert values["STEP"] == [experiment(archive)[2]] == [0.002]
    assert np.abs(np.array(values["POS"]) - ours[-1, 1:]).max() < 1e-9


def test_the_python_api_plays_it_at_the_archives_step(oms, archive, ours, tmp_path):
    """OMSimulator 3.0's Python API takes start and stop time from the archive but a step only
    from its solver units, which exist for model-exchange FMUs alone: the step of a system of
    co-simulation FMUs is set with setFixedStepSize, from the archive (experiment())."""
    pos = python_api_positions(oms, archive, tmp_path)
    assert pos[-1, 0] == pytest.approx(SECONDS)
    assert np.abs(pos[:, 1:] - POS0).max() < 1e-9
    assert agree(pos, ours) < 1e-9


# -- the first paper scenario, exported with its signals (export-ssp --scenario) --------------

S1_SECONDS = 10.0


@pytest.fixture(scope="module")
def s1_archive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from dataclasses import replace

    from orchestrator.scenario.catalogue import load_scenario
    from orchestrator.scenario_ssp import export_scenario_ssp

    sc = replace(load_scenario("hover_varying_orientation"), duration=S1_SECONDS)
    return export_scenario_ssp(tmp_path_factory.mktemp("oms_s1") / "s1.ssp", sc)


@pytest.fixture(scope="module")
def s1_ours() -> np.ndarray:
    """`fullpose run hover_varying_orientation` for 10 s with coupling = "jacobi"."""
    from dataclasses import replace

    from orchestrator.scenario.catalogue import load_scenario

    sc = replace(load_scenario("hover_varying_orientation"), duration=S1_SECONDS,
                 coupling="jacobi")
    r = run(sc, progress=False)
    return np.column_stack([r.time, r.get("plant.pos")])


def test_the_command_line_replays_paper_scenario_1(oms, s1_archive, s1_ours, tmp_path):
    """Three components (ScenarioSignals, plant, controller) from the archive as written: the
    stop time and the 2 ms step are the archive's."""
    out = tmp_path / "s1.csv"
    res = subprocess.run([str(oms / "bin" / "OMSimulator"), f"--resultFile={out}",
                          f"--stopTime={S1_SECONDS}", "--suppressPath=true", str(s1_archive)],
                         capture_output=True, text=True, cwd=tmp_path, timeout=600,
                         check=False)
    assert res.returncode == 0 and "0 errors" in res.stdout, res.stdout[-2000:]
    pos = read_positions(out)
    assert pos[-1, 0] == pytest.approx(S1_SECONDS) and len(pos) == round(S1_SECONDS / 0.002) + 1
    diff = agree(pos, s1_ours)
    print(f"\nOMSimulator CLI, paper scenario 1, {S1_SECONDS:g} s: {diff:.3g} m")
    assert diff < 1e-9


def test_the_python_api_replays_paper_scenario_1(oms, s1_archive, s1_ours, tmp_path):
    pos = python_api_positions(oms, s1_archive, tmp_path)
    assert pos[-1, 0] == pytest.approx(S1_SECONDS)
    assert agree(pos, s1_ours) < 1e-9
