"""What an installed FMU declares: its variables and start values, read once per file.

The FMUs' ``modelDescription.xml`` is generated from the C variable tables with the C defaults
as start values, so it is the one source of the design constants Python also needs (the
controller's sample time and measurement filter, the plant's defaults).
"""

from __future__ import annotations

import os
from functools import cache, lru_cache
from pathlib import Path
from typing import Any


def model_description(fmu: str | Path) -> Any:
    """fmpy's ModelDescription of the FMU at ``fmu``, parsed once per file version (the
    controller's has ~1,800 variables: ~50 ms a parse).  Treat it as read-only."""
    st = os.stat(fmu)
    return _parsed(str(Path(fmu).resolve()), st.st_mtime_ns, st.st_size)


@lru_cache(maxsize=8)
def _parsed(path: str, mtime_ns: int, size: int) -> Any:
    from fmpy import read_model_description

    return read_model_description(path)


@cache
def fmu_variables(fmu: Path) -> dict[str, Any]:
    """name -> fmpy ScalarVariable of the FMU at ``fmu``."""
    return {v.name: v for v in model_description(fmu).modelVariables}


def start_value(fmu: Path, name: str) -> float:
    """The start (default) value of a Real variable of the FMU at ``fmu``."""
    return float(fmu_variables(fmu)[name].start)
