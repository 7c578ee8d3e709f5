"""FMI4j (the JVM FMI library, info.laht.fmi4j:fmi-import 0.38.0), an importer nobody here
wrote, loads and runs the FMUs of the exported SSP.  FMI4j 0.38 reads no SSP itself, so a
small Java harness (tests/tools/fmi4j/, SspReplay) reads the SSD and SSV files and steps the
FMUs with a Jacobi master; tests/tools/fmi4j.sh builds it once with Maven and prints the
command.  Without java or mvn, or when the build fails, these tests skip and say why.

Oracles: the hover pose, which the closed loop must hold; and our runner flying the same
scenario with the same (Jacobi) coupling, which the replay must match within 1e-9 m and
1e-9 rad at every communication point.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest

from orchestrator.export.ssp import export_ssp
from orchestrator.master import run
from orchestrator.scenario.catalogue import load_scenario
from orchestrator.scenario.parser import parse_scenario
from orchestrator.scenario_ssp import export_scenario_ssp
from plant import load_airframe

pytestmark = pytest.mark.fmitools

ROOT = Path(__file__).resolve().parents[2]
POS0 = (0.5, -1.0, -3.0)
SECONDS = 2.0
STEP = 0.002
COLUMNS = ["time", "pos[1]", "pos[2]", "pos[3]", "euler[1]", "euler[2]", "euler[3]"]


@dataclass
class Replay:
    rows: np.ndarray  # [time, pos (3), euler (3)] at every communication point
    step_us: float
    stderr: str


@pytest.fixture(scope="module")
def fmi4j() -> list[str]:
    """The command prefix tests/tools/fmi4j.sh prints (java -cp ... SspReplay)."""
    res = subprocess.run(["bash", str(ROOT / "tests" / "tools" / "fmi4j.sh")],
                         capture_output=True, text=True, check=False, timeout=1800)
    if res.returncode != 0:
        pytest.skip(res.stderr.strip())
    return shlex.split(res.stdout.strip())


def replay(fmi4j: list[str], archive: Path, seconds: float, out: Path) -> Replay:
    """Replay `archive` for `seconds` with FMI4j: the plant's pose at every step, and the
    STEP_US line, the only line on stdout (the FMUs' messages go to stderr)."""
    res = subprocess.run([*fmi4j, str(archive), f"{seconds:g}", str(out)],
                         capture_output=True, text=True, timeout=900, check=False)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    lines = res.stdout.splitlines()
    assert len(lines) == 1 and lines[0].startswith("STEP_US "), res.stdout[-2000:]
    with out.open() as f:
        assert f.readline().strip().split(",") == COLUMNS
    rows = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    assert len(rows) == round(seconds / STEP) + 1 and rows[-1, 0] == pytest.approx(seconds)
    return Replay(rows, float(lines[0].split()[1]), res.stderr)


def differences(theirs: np.ndarray, ours: np.ndarray) -> tuple[float, float]:
    """Largest position and attitude differences at the times both recorded."""
    k = np.searchsorted(ours[:, 0], theirs[:, 0] - 1e-9)
    assert np.allclose(ours[k, 0], theirs[:, 0], atol=1e-9), "time grids do not meet"
    d = np.abs(theirs[:, 1:] - ours[k, 1:])
    return float(d[:, :3].max()), float(d[:, 3:].max())


def ours_jacobi(sc: object) -> np.ndarray:
    """Our runner on the scenario with Jacobi coupling: rows of [time, pos, euler]."""
    r = run(replace(sc, coupling="jacobi"), progress=False)
    return np.column_stack([r.time, r.get("plant.pos"), r.get("plant.euler")])


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("fmi4j") / "hover.ssp"
    export_ssp(path, pos0=POS0, stop_time=SECONDS)
    return path


def test_the_hover_archive_holds_the_pose_and_matches_our_runner(fmi4j, archive, tmp_path):
    """Both FMUs from the archive as written; the 2 ms step from the OSP annotation; the
    airframe's inertia note, an FMU warning, on stderr and not on stdout."""
    got = replay(fmi4j, archive, SECONDS, tmp_path / "hover.csv")
    assert np.abs(got.rows[:, 1:4] - POS0).max() < 1e-9
    sc = parse_scenario({"name": "hover", "duration": SECONDS, "airframe": "paper_hexacopter",
                         "coupling": "jacobi",
                         "reference": {"position": {"x": POS0[0], "y": POS0[1], "z": POS0[2]}}})
    dpos, _ = differences(got.rows, ours_jacobi(sc))
    print(f"\nFMI4j, hover archive, {SECONDS:g} s: {dpos:.3g} m from fullpose run (Jacobi), "
          f"{got.step_us:.1f} us per step")
    assert dpos < 1e-9
    assert re.search(r"status = Warning, instanceName = MultirotorPlant.*inertia", got.stderr)


@pytest.mark.parametrize(("name", "seconds", "airframe"), [
    ("hover_varying_orientation", 10.0, None),  # paper scenario 1
    ("rotor_failure_hover", 3.0, "x8_coaxial"),  # a shipped non-paper airframe, rotor 1 lost
])
def test_a_scenario_archive_replays_as_our_runner_flies_it(fmi4j, tmp_path, name, seconds,
                                                           airframe):
    """Three components (ScenarioSignals, plant, controller) as export-ssp --scenario writes
    them, stepped from the archive's start time with its 2 ms step."""
    sc = replace(load_scenario(name), duration=seconds)
    if airframe is not None:
        sc = replace(sc, airframe=load_airframe(airframe))
    archive = export_scenario_ssp(tmp_path / f"{name}.ssp", sc)
    got = replay(fmi4j, archive, seconds, tmp_path / f"{name}.csv")
    dpos, datt = differences(got.rows, ours_jacobi(sc))
    print(f"\nFMI4j, {name} ({airframe or 'paper airframe'}), {seconds:g} s: position "
          f"{dpos:.3g} m, attitude {datt:.3g} rad from fullpose run (Jacobi), "
          f"{got.step_us:.1f} us per step")
    assert dpos < 1e-9 and datt < 1e-9


def test_a_refused_parameter_exits_1_with_the_fmus_reason(fmi4j, archive, tmp_path):
    """A mass of -1 kg in the plant's parameter set: the FMU's error reaches stderr, the
    harness exits 1 without a STEP_US line or a CSV."""
    bad = tmp_path / "bad.ssp"
    with zipfile.ZipFile(archive) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename.endswith("MultirotorPlant.ssv"):
                data, n = re.subn(rb'(name="mass">\s*<ssv:Real value=")[^"]*', rb"\g<1>-1", data)
                assert n == 1
            dst.writestr(item, data)
    out = tmp_path / "bad.csv"
    res = subprocess.run([*fmi4j, str(bad), "1", str(out)], capture_output=True, text=True,
                         timeout=300, check=False)
    assert res.returncode == 1, res.stdout + res.stderr
    assert res.stdout == "" and not out.exists()
    assert "parameter mass = -1: must be positive" in res.stderr
    assert "SspReplay: " in res.stderr
