"""The installed ``fullpose`` command, run the way users run it."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import fullpose


def test_help_lists_commands():
    out = fullpose("--help", check=True).stdout
    for command in ("hover", "airframes", "fmus"):
        assert command in out


def test_hover_demo_writes_results(tmp_path):
    out = fullpose("hover", "--duration", "1", "--out", str(tmp_path), check=True).stdout
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
    out = fullpose("hover", "--airframe", frame, "--duration", "0.5", check=True).stdout
    assert frame in out


def test_bad_airframe_file_is_named(tmp_path):
    bad = tmp_path / "frame.toml"
    bad.write_text('name = "x"\n[body]\nmass = -1\n')
    res = fullpose("hover", "--airframe", str(bad), check=False)
    assert res.returncode == 2
    assert str(bad) in res.stderr and "body.mass" in res.stderr


def test_airframes_and_fmus_listing():
    assert "paper_hexacopter" in fullpose("airframes", check=True).stdout
    assert "MultirotorPlant.fmu" in fullpose("fmus", check=True).stdout


_HUGE_PAGES_PROBE = """
import re, sys
import numpy as np  # first, its huge-page hint on (its default on Linux >= 4.6)
if sys.argv[1] == "recording":  # as a run's recording is allocated
    from orchestrator.sim.engine import zeroed
    a = zeroed((40_000, 210))
else:
    a = np.zeros((40_000, 210))
a[:] = 1.0  # 64 MiB touched: a long run's recording
smaps = open("/proc/self/smaps_rollup").read()
print(int(re.search(r"AnonHugePages:\\s+(\\d+) kB", smaps).group(1)))
"""


def test_a_long_recording_gets_small_pages():
    """A long run's recording gets 4 KiB pages whatever numpy's setting: its first touch is
    not left to the kernel's memory compaction for transparent huge pages (0.1-0.65 s for
    70 MB on a VM, ``engine.zeroed``).  Told apart by the huge pages the kernel gave a
    touched 64 MiB array (/proc/self/smaps_rollup): numpy's own zeros get them here."""
    thp = Path("/sys/kernel/mm/transparent_hugepage/enabled")
    if not thp.is_file() or "[never]" in thp.read_text():
        pytest.skip("no transparent huge pages here: nothing to tell apart")
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}

    def huge_kb(array: str) -> int:
        out = subprocess.run([sys.executable, "-c", _HUGE_PAGES_PROBE, array], env=env,
                             capture_output=True, text=True, check=True)
        return int(out.stdout)

    if huge_kb("zeros") == 0:
        pytest.skip("the kernel gave no huge pages even when numpy asked: nothing to tell apart")
    assert huge_kb("recording") == 0
