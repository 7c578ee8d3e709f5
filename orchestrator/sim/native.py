"""``libfp_cosim``: the co-simulation step kernel (``fmu_src/host/fp_cosim.h``), declared for
ctypes.  Used by :class:`orchestrator.sim.engine.NativeEngine`."""

from __future__ import annotations

import ctypes
from functools import cache

from plant.common.artifacts import load_library

_VP = ctypes.c_void_p
_L = ctypes.c_long

_SZ = ctypes.c_size_t
SIGNATURES: dict[str, list[object]] = {
    "fp_cosim_steps": [_VP, _VP, _VP, _VP, _VP, _L, _VP, _L, _VP, _VP, ctypes.c_double,
                       ctypes.c_double, ctypes.c_int, _L, _L, ctypes.POINTER(_L)],
    # the FMI 3.0 adapter (fmu_src/host/fp_cosim.h, fp_fmi3_*)
    "fp_fmi3_adapter_new": [_VP, _VP, _SZ, _VP, _VP, _VP, _VP],
    "fp_fmi3_adapter_free": [_VP],
    "fp_fmi3_set_real": [_VP, _VP, _SZ, _VP],
    "fp_fmi3_get_real": [_VP, _VP, _SZ, _VP],
    "fp_fmi3_get_integer": [_VP, _VP, _SZ, _VP],
    "fp_fmi3_get_boolean": [_VP, _VP, _SZ, _VP],
    "fp_fmi3_do_step": [_VP, ctypes.c_double, ctypes.c_double, ctypes.c_int],
}
"""ctypes argument types of every function of the library (all return int)."""


@cache
def cosim() -> ctypes.CDLL:
    """``libfp_cosim`` (``orchestrator/lib/``) with ``fp_cosim_steps`` declared."""
    return load_library("orchestrator", "fp_cosim", SIGNATURES)
