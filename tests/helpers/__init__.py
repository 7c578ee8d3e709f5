"""Small helpers the tests share (conftest.py puts this folder on sys.path)."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path
from typing import Any

import pytest


def logged(inst: Any, *statuses: str) -> list[str]:
    """The messages an FMU instance (orchestrator.sim.fmu.FmuInstance) logged with any of
    the statuses ("ERROR", "WARNING", ...), in order."""
    return [m for s, _, m in inst.messages if s in statuses]


def problems(inst: Any) -> str:
    """The instance's errors and warnings, joined into one line for assertions on text."""
    return " | ".join(logged(inst, "ERROR", "WARNING"))


# the command installed beside the running interpreter, never one a PATH happens to find
FULLPOSE = Path(sysconfig.get_path("scripts")) / ("fullpose.exe" if os.name == "nt" else "fullpose")


def fullpose(*args: str, check: bool = False, cwd: Path | None = None,
             timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """Run the installed ``fullpose`` command as a user types it (output captured)."""
    if not FULLPOSE.is_file():
        pytest.fail(f"{FULLPOSE} missing: `pip install .` installs the fullpose command")
    return subprocess.run([str(FULLPOSE), *args], capture_output=True, text=True, check=check,
                          timeout=timeout, cwd=cwd)


def cli(*args: str, cwd: Path | None = None,
        timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """Run the CLI of this interpreter's orchestrator (``python -m orchestrator.cli``)."""
    return subprocess.run([sys.executable, "-m", "orchestrator.cli", *args],
                          capture_output=True, text=True, timeout=timeout, cwd=cwd)


def rezip(folder: Path, fmu: Path) -> None:
    """Zip the unpacked FMU `folder` into `fmu` (entries in sorted order, deflated)."""
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                z.write(p, p.relative_to(folder).as_posix())


def omsimulator() -> Path:
    """The OMSimulator build tests/tools/omsimulator.sh finds (the folder holding
    bin/OMSimulator); skips the calling test with the script's reason when there is none."""
    root = Path(__file__).resolve().parents[2]
    res = subprocess.run(["bash", str(root / "tests" / "tools" / "omsimulator.sh")],
                         capture_output=True, text=True, check=False)
    if res.returncode != 0:
        pytest.skip(res.stderr.strip())
    return Path(res.stdout.strip())
