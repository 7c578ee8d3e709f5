"""``libfp_multirotor``: the rotor geometry of the C core (``fmu_src/host/fp_multirotor_api.h``,
the code both FMUs run), declared for ctypes.  Used by :mod:`plant.effectiveness`."""

from __future__ import annotations

import ctypes
from functools import cache

from plant.common.artifacts import load_library

_DP = ctypes.POINTER(ctypes.c_double)
_I32P = ctypes.POINTER(ctypes.c_int32)
_VP = ctypes.c_void_p
_D = ctypes.c_double
_I = ctypes.c_int

SIGNATURES: dict[str, list[object]] = {
    "fp_api_version": [],
    "fp_max_rotors": [],
    "fp_airframe_variable_count": [],
    "fp_airframe_variable": [_I, ctypes.c_char_p, _I, _I32P, _I32P, _I32P, _I32P],
    "fp_airframe_size": [],
    "fp_rotor_set_from_airframe": [_VP, _VP],
    "fp_rotor_set_size": [],
    "fp_rotor_rotation_api": [_D, _D, _D, _DP],
    "fp_thrust_direction_api": [_D, _D, _D, _DP],
    "fp_tilt_from_direction_api": [_DP, _D, _DP, _DP],
    "fp_effectiveness_b_api": [_VP, _DP],
    "fp_effectiveness_bprime_api": [_VP, _DP, _DP, _DP],
    "fp_effectiveness_b2prime_api": [_VP, _DP, _DP, _DP, _DP],
    "fp_rotor_wrench_api": [_VP, _DP, _DP, _DP, _DP, _DP, _DP],
    "fp_preferred_config_api": [_VP, _DP, _DP, _DP, _DP, ctypes.c_char_p, _I],
}
"""ctypes argument types of every function of the library (all return int)."""


@cache
def multirotor() -> ctypes.CDLL:
    """``libfp_multirotor`` (``plant/lib/``) with its functions declared."""
    return load_library("plant", "fp_multirotor", SIGNATURES)
