"""The installed ``fullpose`` command, run the way users run it."""

import csv
import json
import os
import subprocess
import sysconfig
from pathlib import Path

import pytest

# the command installed beside the running interpreter, never one a PATH happens to find
FULLPOSE = Path(sysconfig.get_path("scripts")) / ("fullpose.exe" if os.name == "nt" else "fullpose")


def run(*args, check=True):
    if not FULLPOSE.is_file():
        pytest.fail(f"{FULLPOSE} missing: `pip install .` installs the fullpose command")
    cmd = [str(FULLPOSE), *args]
    return subprocess.run(cmd, capture_output=True, text=True, check=check, timeout=300)


def test_help_lists_commands():
    out = run("--help").stdout
    for command in ("hover", "airframes", "fmus"):
        assert command in out


def test_hover_demo_writes_results(tmp_path):
    out = run("hover", "--duration", "1", "--out", str(tmp_path)).stdout
    assert "max position drift" in out
    summary = json.loads((tmp_path / "hover_summary.json").read_text())
    assert summary["steps"] == 500
    assert summary["max_position_drift_m"] < 1e-3
    with open(tmp_path / "hover.csv") as f:
        rows = list(csv.reader(f))
    assert rows[0][:4] == ["time", "pos[1]", "pos[2]", "pos[3]"]
    assert len(rows) == 502
    assert float(rows[-1][0]) == pytest.approx(1.0)
    assert float(rows[-1][3]) == pytest.approx(-3.0, abs=1e-3)


@pytest.mark.parametrize("frame", ["fixed_tilt_hexarotor", "quadrotor"])
def test_hover_other_airframes(frame):
    out = run("hover", "--airframe", frame, "--duration", "0.5").stdout
    assert frame in out


def test_bad_airframe_file_is_named(tmp_path):
    bad = tmp_path / "frame.toml"
    bad.write_text('name = "x"\n[body]\nmass = -1\n')
    res = run("hover", "--airframe", str(bad), check=False)
    assert res.returncode == 2
    assert str(bad) in res.stderr and "body.mass" in res.stderr


def test_airframes_and_fmus_listing():
    assert "paper_hexacopter" in run("airframes").stdout
    assert "MultirotorPlant.fmu" in run("fmus").stdout
