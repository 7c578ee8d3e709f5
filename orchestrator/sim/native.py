"""``libfp_cosim``: the co-simulation step kernel (``fmu_src/host/fp_cosim.h``), declared for
ctypes.  Used by :class:`orchestrator.sim.engine.NativeEngine`."""

from __future__ import annotations

import ctypes
from functools import cache

from plant.common.artifacts import load_library

_VP = ctypes.c_void_p
_L = ctypes.c_long

SIGNATURES: dict[str, list[object]] = {
    "fp_cosim_steps": [_VP, _VP, _VP, _VP, _VP, _L, _VP, _L, _VP, _VP, ctypes.c_double,
                       ctypes.c_double, ctypes.c_int, _L, _L, ctypes.POINTER(_L)],
}
"""ctypes argument types of every function of the library (all return int)."""


@cache
def cosim() -> ctypes.CDLL:
    """``libfp_cosim`` (``orchestrator/lib/``) with ``fp_cosim_steps`` declared."""
    return load_library("orchestrator", "fp_cosim", SIGNATURES)
