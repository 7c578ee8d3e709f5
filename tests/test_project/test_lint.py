"""The Python sources are ruff-clean and type-check with mypy (configuration in pyproject.toml)."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_ruff_clean():
    if importlib.util.find_spec("ruff") is None:
        pytest.fail("ruff is a test dependency: pip install '.[test]'")
    targets = ["plant", "controller", "orchestrator", "mavlink_bridge", "tests"]
    res = subprocess.run([sys.executable, "-m", "ruff", "check", *targets], cwd=ROOT,
                         capture_output=True, text=True, check=False)
    assert res.returncode == 0, res.stdout + res.stderr


def test_mypy_clean():
    """Types are checked, not only written: mypy over the four packages, for the oldest
    Python the package supports ([tool.mypy] in pyproject.toml)."""
    if importlib.util.find_spec("mypy") is None:
        pytest.fail("mypy is a test dependency: pip install '.[test]'")
    res = subprocess.run([sys.executable, "-m", "mypy", "--no-error-summary"], cwd=ROOT,
                         capture_output=True, text=True, check=False)
    assert res.returncode == 0, res.stdout + res.stderr


def test_python_version_floor_is_declared():
    text = (ROOT / "pyproject.toml").read_text()
    assert 'requires-python = ">=3.10"' in text
    assert sys.version_info >= (3, 10)
