"""Small helpers the tests share (conftest.py puts this folder on sys.path)."""

from __future__ import annotations

from typing import Any


def logged(inst: Any, *statuses: str) -> list[str]:
    """The messages an FMU instance (orchestrator.sim.fmu.FmuInstance) logged with any of
    the statuses ("ERROR", "WARNING", ...), in order."""
    return [m for s, _, m in inst.messages if s in statuses]


def problems(inst: Any) -> str:
    """The instance's errors and warnings, joined into one line for assertions on text."""
    return " | ".join(logged(inst, "ERROR", "WARNING"))
