"""Long runs: a recording larger than ``master.SPILL_BYTES`` is written to a file mapped into
memory as the run goes, so a run of hours needs disk, not memory, and gives the same
results as one held in memory."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import textwrap
from pathlib import Path

import numpy as np
import pytest

from orchestrator import master
from orchestrator.master import RecordingTooLarge, check_memory
from orchestrator.output.run_result import RESULTS_FILE, RunResult
from orchestrator.runner import run_scenario
from orchestrator.scenario.catalogue import load_scenario
from orchestrator.scenario.parser import with_overrides

FULLPOSE = Path(sysconfig.get_path("scripts")) / ("fullpose.exe" if os.name == "nt" else "fullpose")


def _scenario(duration: float):
    return with_overrides(load_scenario("hover_varying_orientation"), duration=duration)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if p.name.endswith(".recording.npy")
                  or p.name.endswith(".partial"))


def test_a_recording_in_a_file_is_the_same_run(tmp_path):
    sc = _scenario(4.0)
    held = master.run(sc)
    spill = tmp_path / "run.recording.npy"
    filed = master.run(sc, spill=spill, spill_above=0)
    assert isinstance(filed.data, np.memmap)
    assert spill.stat().st_size >= filed.data.nbytes
    assert filed.columns == held.columns and filed.integer == held.integer
    assert np.array_equal(filed.data, held.data)  # bit-identical, not close
    # below the threshold the offered file is not used
    small = tmp_path / "unused.npy"
    kept = master.run(sc, spill=small)
    assert not small.exists() and not isinstance(kept.data, np.memmap)
    assert np.array_equal(kept.data, held.data)


@pytest.mark.heavy  # about 2 s: the heavy tier (CI runs it), room in the fast one
def test_results_folder_of_a_filed_recording(tmp_path):
    """The whole main job (results, metrics, figures drawn by the workers from the mapped
    file) gives the folder of a run held in memory, and leaves no file behind."""
    sc = _scenario(6.0)
    a = run_scenario(sc, tmp_path / "filed", timing=False, spill_above=0)
    b = run_scenario(sc, tmp_path / "held", timing=False)
    names = sorted(p.name for p in (tmp_path / "filed").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "held").iterdir())
    assert {"tracking.png", "actuators.png", "forces.png", RESULTS_FILE} <= set(names)
    ra, rb = (RunResult.read(tmp_path / n / RESULTS_FILE) for n in ("filed", "held"))
    assert ra.columns == rb.columns and np.array_equal(ra.data, rb.data)
    assert a.metrics["position_error"] == b.metrics["position_error"]
    assert a.metrics["saturation"] == b.metrics["saturation"]
    assert _leftovers(tmp_path) == []
    # the returned result still reads (POSIX keeps a removed file while it is mapped)
    assert np.array_equal(a.result.data, b.result.data)


def test_a_killed_runs_recording_file_is_removed_by_the_next_run(tmp_path):
    stale = tmp_path / ".res.0123456789ab.recording.npy"  # as a run killed by SIGKILL leaves
    stale.write_bytes(b"\0" * 1024)
    other = tmp_path / ".other.0123456789ab.recording.npy"  # another folder's: kept
    other.write_bytes(b"")
    run_scenario(_scenario(1.0), tmp_path / "res", plots=False)
    assert not stale.exists() and other.exists()


def test_the_disk_is_checked_before_the_run(tmp_path):
    with pytest.raises(RecordingTooLarge, match=r"GiB of disk.*shorten the duration"):
        check_memory(10**12, 143, file=tmp_path / "r.recording.npy")
    check_memory(10**12 // 10**6, 143, file=tmp_path / "r.recording.npy")  # 1e6 rows fit


def test_cli_refuses_a_run_larger_than_the_disk(tmp_path):
    """Ten million seconds would need terabytes: refused with the reason, before anything
    runs, and nothing is written."""
    res = subprocess.run([str(FULLPOSE), "run", "hover_varying_orientation", "--duration",
                          "1e7", "--out", str(tmp_path / "big")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode != 0
    assert "GiB of disk" in res.stderr and "Traceback" not in res.stderr
    assert list(tmp_path.iterdir()) == []


_MEMORY_PROBE = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    from orchestrator import master
    from orchestrator.scenario.catalogue import load_scenario
    from orchestrator.scenario.parser import with_overrides

    def anon_kib():
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("RssAnon:"):
                    return int(line.split()[1])
        raise RuntimeError("no RssAnon")

    sc = with_overrides(load_scenario("hover_varying_orientation"), duration=float(sys.argv[1]))
    spill = Path(sys.argv[2]) if sys.argv[2] != "-" else None
    base = anon_kib()
    peak = [base]
    sim = master.CoSimulation(sc, spill=spill, spill_above=0)
    res = sim.run(on_chunk=lambda k, n: peak.__setitem__(0, max(peak[0], anon_kib())))
    print(json.dumps({"growth": (max(peak[0], anon_kib()) - base) * 1024,
                      "bytes": int(res.data.nbytes)}))
""")


@pytest.mark.heavy  # (a recording larger than memory's share, filed: 3.8 s)
@pytest.mark.skipif(not sys.platform.startswith("linux"),
                    reason="reads the process's anonymous memory from Linux's /proc")
def test_a_filed_recording_keeps_memory_bounded(tmp_path):
    """The process's anonymous memory while a 300 s run steps: with the recording in a file
    it grows by a small part of the recording; held in memory, by the recording itself (the
    control that shows the probe sees it)."""
    def probe(spill: str) -> dict[str, int]:
        out = subprocess.run([sys.executable, "-c", _MEMORY_PROBE, "300", spill],
                             capture_output=True, text=True, check=True, timeout=300)
        return json.loads(out.stdout.strip().splitlines()[-1])

    held = probe("-")
    filed = probe(str(tmp_path / "run.recording.npy"))
    assert held["bytes"] > 150 * 2**20  # 150,001 rows x 144 columns of float64
    assert held["growth"] > 0.8 * held["bytes"]
    assert filed["growth"] < 0.25 * filed["bytes"]
