"""The FMI call-sequence fuzzer (tests/helpers/fuzz_fmi.py) against both FMUs.

Default run: 5,000 calls per FMU (a few seconds each).  Opt-in (``pytest -m fuzz``): 100,000
calls per FMU, and the separate use-after-free mode (calls on freed instances, undefined
behaviour by the standard).  Each batch runs in child processes, so a crash or a hang is a
finding, not the end of the test session.  The oracle itself is checked on planted bugs.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

FUZZER = Path(__file__).resolve().parents[1] / "helpers" / "fuzz_fmi.py"
_spec = importlib.util.spec_from_file_location("fuzz_fmi", FUZZER)
fuzz_fmi = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("fuzz_fmi", fuzz_fmi)
_spec.loader.exec_module(fuzz_fmi)


def _check(report) -> None:
    print("\n" + report.summary(60))
    assert not report.findings, (
        f"{len(report.findings)} findings on {report.fmu} (seed {report.seed}), "
        f"by kind {dict(report.by_kind())}; first (seed, call index, description): "
        f"{report.triples()[:5]}")


RUNS = [  # (calls, seed, hang timeout s, time budget s): the default run and the long one
    pytest.param(5000, 1, 3.0, 40.0, id="short"),
    pytest.param(100_000, 2, 10.0, 1800.0, id="long", marks=pytest.mark.fuzz),
]


@pytest.mark.parametrize("fmu", ["plant", "controller"])
@pytest.mark.parametrize(("calls", "seed", "hang", "budget"), RUNS)
def test_fuzz(fmu, calls, seed, hang, budget):
    report = fuzz_fmi.run_fuzz(fmu, calls, seed=seed, hang_timeout=hang, time_budget=budget)
    assert report.calls >= 0.8 * calls or report.crashes or report.hangs
    _check(report)


@pytest.mark.fuzz
@pytest.mark.parametrize("fmu", ["plant", "controller"])
def test_fuzz_use_after_free(fmu):
    """Calls on instances after fmi2FreeInstance (undefined behaviour; kept apart)."""
    report = fuzz_fmi.run_fuzz(fmu, 5000, seed=3, use_after_free=True, hang_timeout=5.0)
    _check(report)


@pytest.mark.parametrize("bug, kind", [
    ("nan_output", "nonfinite_output"),
    ("silent_error", "silent_nonok"),
    ("accept_forbidden", "forbidden_accepted"),
    ("crash", "crash"),
    pytest.param("hang", "hang", marks=pytest.mark.heavy),  # (waits out its hang timeout)
])
def test_oracle_finds_planted_bugs(bug, kind):
    """A wrapper that misbehaves (a NaN output with fmi2OK, an error without a message, a
    step accepted before initialization, a segfault, a hang at call 200) is reported, with
    its call index, and the batch goes on after a crash or a hang."""
    report = fuzz_fmi.run_fuzz("plant", 1000, seed=5, plant_bug=bug, hang_timeout=1.0,
                               episode_calls=250)
    found = [f for f in report.findings if f.kind == kind]
    assert found, report.summary()
    if kind == "forbidden_accepted":
        assert any("fmi2DoStep" in f.description for f in found)
    if bug == "silent_error":  # the planted one, not a real NULL-argument finding
        assert any("fmi2GetInteger" in f.description and "arg:" not in f.description
                   for f in found)
    if bug == "nan_output":
        assert len(found) >= 10
    if kind in ("crash", "hang"):
        assert report.calls > 400  # later episodes still ran
        assert found[0].index < 1000  # in the first episode (call 200 of the child)


@pytest.mark.sanitize
def test_sanitizer_run():
    """tests/tools/sanitizer_run.sh: the FMU tests and a fuzz batch on an ASan/UBSan build
    (several minutes; .ci/run runs the script directly)."""
    import subprocess

    script = Path(__file__).resolve().parents[1] / "tools" / "sanitizer_run.sh"
    done = subprocess.run(["bash", str(script)], capture_output=True, text=True)
    print(done.stdout[-4000:])
    assert done.returncode == 0, (done.stdout[-3000:] + done.stderr[-3000:])
