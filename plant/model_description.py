"""What an installed FMU declares: its variables and start values, read once per file.

The FMUs' ``modelDescription.xml`` is generated from the C variable tables with the C defaults
as start values, so it is the one source of the design constants Python also needs (the
controller's sample time and measurement filter, the plant's defaults).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any


@cache
def fmu_variables(fmu: Path) -> dict[str, Any]:
    """name -> fmpy ScalarVariable of the FMU at ``fmu``."""
    from fmpy import read_model_description

    return {v.name: v for v in read_model_description(str(fmu)).modelVariables}


def start_value(fmu: Path, name: str) -> float:
    """The start (default) value of a Real variable of the FMU at ``fmu``."""
    return float(fmu_variables(fmu)[name].start)
