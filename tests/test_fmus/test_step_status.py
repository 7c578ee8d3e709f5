"""What fmi2DoStep returns when the FMU has something to say (issue 34, deliverable 2), and
that every importer we test continues through it.

The policy (docs/fmus.md, "What doStep returns"): a step that completed returns fmi2OK; what
the model has to say about it (the controller holding its last command on an unusable
input, a communication step longer than its sample time) is logged as it happens with status
fmi2Warning in category logStatusWarning.  fmi2Warning is never returned from fmi2DoStep:
OMSimulator takes any status but fmi2OK from a step for a failure and stops the run (its
ComponentFMUCS::stepUntil), while fmpy, fmusim and the FMU Compliance Checker continue
either way.

The held command is provoked by a reference outside its plausible range (``pos_ref[1] =
2e7`` m, the range is +-1e7 m) or not finite (NaN), for 10 ms of a run, then restored:

- fmpy (raw fmi2DoStep, fast tier): every step answers fmi2OK, the hold and the recovery are
  logged at fmi2Warning, the commands are held;
- fmusim and the Compliance Checker (their command lines, an input file; ``fmitools``) run
  to the stop time and print the FMU's warnings;
- OMSimulator (its Python API on the exported closed loop; ``fmitools``) steps on through
  the hold, and initializes the loop without reporting an algebraic loop (the
  InitialUnknowns' dependencies, tests/test_fmus/test_model_structure.py).
"""

from __future__ import annotations

import csv
import ctypes
import math
import os
import shutil
import subprocess
import sys
import textwrap
from ctypes import c_double, c_int, c_void_p
from pathlib import Path

import numpy as np
import pytest
from helpers import omsimulator

from orchestrator.export.ssp import CONTROLLER, PLANT, SYSTEM, export_ssp
from orchestrator.sim.fmu import FmuInstance, installed_fmu

H = 0.002
OK = 0
HOLD = "holding the last valid command"
RESUMED = "control resumed"


def test_a_held_command_is_a_step_that_returns_ok_and_says_so():
    with FmuInstance(installed_fmu(CONTROLLER)) as c:
        c.initialize()
        do_step = ctypes.CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_int)(
            ("fmi2DoStep", c.slave.dll))
        commands = c.signal(["omega_cmd", "alpha_cmd", "beta_cmd"])
        statuses, t = [], 0.0
        for k in range(15):
            if k == 5:
                held = c.read(commands).copy()
                c.set("pos_ref[1]", math.nan)
            if k == 10:
                c.set("pos_ref[1]", 0.0)
            statuses.append(do_step(c.slave.component, t, H, 1))
            t += H
            if 5 <= k < 10:
                np.testing.assert_array_equal(c.read(commands), held)
        assert statuses == [OK] * 15
        warned = [m for s, _, m in c.messages if s == "WARNING"]
        assert sum(HOLD in m for m in warned) == 1 and any(RESUMED in m for m in warned)


def test_a_coarse_step_returns_ok_and_says_so():
    with FmuInstance(installed_fmu(CONTROLLER)) as c:
        c.initialize()
        do_step = ctypes.CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_int)(
            ("fmi2DoStep", c.slave.dll))
        assert [do_step(c.slave.component, k * 0.01, 0.01, 1) for k in range(3)] == [OK] * 3
        assert sum("longer than the sample time" in m for s, _, m in c.messages
                   if s == "WARNING") == 1


# ---------------------------------------------------------------------------
# the importers' own programs


def tool(name: str) -> Path:
    """An FMI tool of tests/tools/fmi_tools.sh (FULLPOSE_FMI_TOOLS, else the PATH)."""
    folder = os.environ.get("FULLPOSE_FMI_TOOLS")
    for c in ([Path(folder) / "bin" / name] if folder else []) + \
            ([Path(p)] if (p := shutil.which(name)) else []):
        if c.is_file() and os.access(c, os.X_OK):
            return c
    pytest.skip(f"{name} not found (set FULLPOSE_FMI_TOOLS to the folder holding bin/{name}; "
                "tests/tools/fmi_tools.sh builds it)")


def write_hold_input(path: Path) -> None:
    """pos_ref[1] = 2e7 m (beyond its plausible +-1e7 m) from 10 ms to 20 ms, else 0."""
    rows = [(0.0, 0.0), (0.0099, 0.0), (0.01, 2e7), (0.0199, 2e7), (0.02, 0.0), (0.05, 0.0)]
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time", "pos_ref[1]"])
        w.writerows(rows)


def last_time(path: Path) -> float:
    with path.open() as f:
        return float(list(csv.reader(f))[-1][0])


@pytest.mark.fmitools
def test_fmusim_steps_on_through_a_held_command(tmp_path):
    fmusim = tool("fmusim")
    write_hold_input(tmp_path / "in.csv")
    out = tmp_path / "out.csv"
    res = subprocess.run([str(fmusim), "simulate", "--input-file", str(tmp_path / "in.csv"),
                          "--output-file", str(out), "--output-interval", str(H),
                          "--stop-time", "0.05", str(installed_fmu(CONTROLLER))],
                         capture_output=True, text=True, timeout=300, check=False)
    text = res.stdout + res.stderr
    assert res.returncode == 0, text[-2000:]
    assert HOLD in text and RESUMED in text
    assert last_time(out) == pytest.approx(0.05)


@pytest.mark.fmitools
def test_the_compliance_checker_steps_on_through_a_held_command(tmp_path):
    checker = tool("fmuCheck.linux64")
    write_hold_input(tmp_path / "in.csv")
    out = tmp_path / "out.csv"
    res = subprocess.run([str(checker), "-l", "3", "-h", str(H), "-s", "0.05", "-k", "cs",
                          "-i", str(tmp_path / "in.csv"), "-t", str(tmp_path), "-o", str(out),
                          str(installed_fmu(CONTROLLER))],
                         capture_output=True, text=True, timeout=300, check=False)
    text = res.stdout + res.stderr
    assert res.returncode == 0, text[-2000:]
    assert "0 Warning(s)" in text and "0 Error(s)" in text, text[-2000:]
    assert HOLD in text and RESUMED in text
    assert last_time(out) == pytest.approx(0.05)


@pytest.fixture(scope="module")
def oms() -> Path:
    return omsimulator()


@pytest.mark.fmitools
def test_omsimulator_initializes_the_loop_and_steps_on_through_a_held_command(oms, tmp_path):
    """OMSimulator's Python API (in a process of its own: the library keeps global state) on
    the exported hover: no algebraic loop at initialization, and a NaN reference held for
    10 ms does not stop the run (before: "fmi2_doStep failed", Status.error)."""
    archive = tmp_path / "hover.ssp"
    export_ssp(archive, pos0=(0.0, 0.0, -3.0), stop_time=0.06)
    code = f"""
        from OMSimulator import SSP
        from OMSimulator.cref import CRef
        model = SSP({str(archive)!r}, temp_dir={str(tmp_path / 'tmp')!r}).instantiate()
        model.setFixedStepSize({H})
        model.setResultFile("")
        model.initialize()
        ref = CRef({SYSTEM!r}, {CONTROLLER!r}, "pos_ref[1]")
        for t, value in ((0.02, float("nan")), (0.03, 0.0), (0.06, None)):
            model.stepUntil(t)
            print("REACHED", t, flush=True)
            if value is not None:
                model.setValue(ref, value)
        print("Z", model.getValue(CRef({SYSTEM!r}, {PLANT!r}, "pos[3]")), flush=True)
        model.terminate()
        model.delete()
    """
    env = {**os.environ, "PYTHONPATH": str(oms / "lib" / "x86_64-linux-gnu")}
    res = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                         text=True, cwd=tmp_path, env=env, timeout=300, check=False)
    text = res.stdout + res.stderr
    assert res.returncode == 0, text[-3000:]
    assert "Alg. loop" not in text, text[-3000:]
    assert HOLD in text and RESUMED in text
    assert "REACHED 0.06" in text and "0 errors" in text, text[-3000:]
    z = float(next(ln.split()[1] for ln in res.stdout.splitlines() if ln.startswith("Z ")))
    assert abs(z + 3.0) < 1e-6
