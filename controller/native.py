"""``libfp_controller``: the allocation solver of the controller FMU and the replay of its
QPs (``fmu_src/host/fp_controller_api.h``), declared for ctypes.  Used by
:mod:`controller.wls` and :mod:`controller.qp_record`."""

from __future__ import annotations

import ctypes
from functools import cache

from plant.common.artifacts import load_library

_DP = ctypes.POINTER(ctypes.c_double)
_I8P = ctypes.POINTER(ctypes.c_int8)
_I32P = ctypes.POINTER(ctypes.c_int32)
_VP = ctypes.c_void_p
_I = ctypes.c_int

SIGNATURES: dict[str, list[object]] = {
    "fp_wls_size": [],
    "fp_wls_caps": [_I32P],
    "fp_wls_setup_api": [_VP, _I, _I, _I],
    "fp_wls_set_data_api": [_VP, _DP, _DP, _DP, _DP, _DP, _DP],
    "fp_wls_set_start_api": [_VP, _DP, _I8P],
    "fp_wls_keep_rows_api": [_VP],
    "fp_wls_get_working_set_api": [_VP, _I8P],
    "fp_wls_solve_api": [_VP, _I, _DP, _I32P, _DP],
    "fp_wls_bench_api": [_VP, _I, _I, _DP, _DP, _I32P, _DP],
    "fp_derive_force_set_api": [_VP, _I, _I, _DP, _DP, _I32P, _DP, ctypes.c_char_p,
                                _I],
    "fp_controller_state_qp": [ctypes.c_char_p, ctypes.c_long, _I, _I32P, _DP, _DP, _DP, _DP,
                               _DP, _DP, _DP],
}
"""ctypes argument types of every function of the library (all return int)."""


@cache
def solver() -> ctypes.CDLL:
    """``libfp_controller`` (``controller/lib/``) with its functions declared."""
    return load_library("controller", "fp_controller", SIGNATURES)
