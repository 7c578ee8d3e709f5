"""What the installed FMUs declare: their variables and start values, read once.

The FMUs' ``modelDescription.xml`` is generated from the C variable tables with the C defaults
as start values, so it is the one source of the design constants Python also needs (the
controller's sample time and measurement filter, the plant's defaults).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

from plant import fmu_path


@cache
def _variables(path: Path) -> dict[str, Any]:
    from fmpy import read_model_description

    return {v.name: v for v in read_model_description(str(path)).modelVariables}


def model_variables(model: str) -> dict[str, Any]:
    """name -> fmpy ScalarVariable of an installed FMU (``MultirotorPlant``,
    ``FullPoseController``)."""
    return _variables(fmu_path(model))


def start_value(model: str, name: str) -> float:
    """The start (default) value of a Real variable of an installed FMU."""
    return float(model_variables(model)[name].start)
