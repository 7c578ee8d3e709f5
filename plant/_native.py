"""Locate the built artifacts (FMUs, core library) and load the core library.

The FMUs and ``libfullpose_core`` are compiled from ``fmu_src/`` by ``pip install``
and installed as package data under ``plant/fmus`` and ``plant/lib`` (controller
FMUs under ``controller/fmus``).  ``FULLPOSE_BUILD_DIR`` points at a CMake build
directory instead, for C development without reinstalling.
"""

from __future__ import annotations

import ctypes
import os
import sys
from functools import cache
from importlib import metadata, resources
from pathlib import Path

_LIB_NAMES = {"win32": "fullpose_core.dll", "darwin": "libfullpose_core.dylib"}


class NativeBuildMissing(RuntimeError):
    """The compiled part of the package is not where it should be."""


def _candidates(package: str, subdir: str, filename: str) -> list[Path]:
    found: list[Path] = []
    build_dir = os.environ.get("FULLPOSE_BUILD_DIR")
    if build_dir:
        found.append(Path(build_dir) / filename)
    try:
        root = resources.files(package)
    except ModuleNotFoundError:
        return found
    found.append(Path(str(root.joinpath(subdir, filename))))
    # editable installs put built files beside the installed package, not the sources
    for entry in getattr(sys.modules.get(package), "__path__", []):
        found.append(Path(entry) / subdir / filename)
    # the source tree imported ahead of the installed package (python -m pytest in a checkout)
    try:
        found.append(Path(str(metadata.distribution("fullpose").locate_file(
            f"{package}/{subdir}/{filename}"))))
    except metadata.PackageNotFoundError:
        pass
    return found


def find_artifact(package: str, subdir: str, filename: str) -> Path:
    """Path of a built file shipped as package data, or a clear error."""
    candidates = _candidates(package, subdir, filename)
    for path in candidates:
        if path.is_file():
            return path
    tried = ", ".join(str(p) for p in candidates) or "(nowhere)"
    raise NativeBuildMissing(
        f"{filename} is not built: install the package with 'pip install .' "
        f"(or set FULLPOSE_BUILD_DIR to a CMake build of fmu_src/); looked in {tried}"
    )


def fmu_path(model_name: str) -> Path:
    """Path of an installed FMU by model name, e.g. ``MultirotorPlant``."""
    owner = {"MultirotorPlant": "plant", "FullPoseController": "controller"}.get(model_name)
    if owner is None:
        raise ValueError(f"unknown FMU {model_name!r}")
    return find_artifact(owner, "fmus", f"{model_name}.fmu")


def core_library_path() -> Path:
    return find_artifact("plant", "lib", _LIB_NAMES.get(sys.platform, "libfullpose_core.so"))


@cache
def core() -> ctypes.CDLL:
    """The core shared library with argument types declared."""
    lib = ctypes.CDLL(str(core_library_path()))
    dp = ctypes.POINTER(ctypes.c_double)
    ip = ctypes.POINTER(ctypes.c_int32)
    vp = ctypes.c_void_p
    d = ctypes.c_double
    i = ctypes.c_int
    signatures: dict[str, list[object]] = {
        "fp_api_version": [],
        "fp_max_rotors": [],
        "fp_rotor_set_size": [],
        "fp_rotor_set_init": [vp, i, d, d, dp, ip, dp, dp, dp, dp, dp, d, d],
        "fp_rotor_rotation_api": [d, d, d, dp],
        "fp_thrust_direction_api": [d, d, d, dp],
        "fp_tilt_from_direction_api": [dp, d, dp, dp],
        "fp_effectiveness_b_api": [vp, dp],
        "fp_effectiveness_bprime_api": [vp, dp, dp, dp],
        "fp_rotor_wrench_api": [vp, dp, dp, dp, dp, dp, dp],
        "fp_preferred_config_api": [vp, dp, dp, dp, dp, ctypes.c_char_p, i],
        "fp_effectiveness_b2prime_api": [vp, dp, dp, dp, dp],
        "fp_cosim_steps": [vp, vp, vp, vp, vp, ctypes.c_long, vp, ctypes.c_long, vp, vp, d, d,
                           i, ctypes.c_long, ctypes.c_long, ctypes.POINTER(ctypes.c_long)],
        "fp_controller_state_qp": [ctypes.c_char_p, ctypes.c_long, i, ip, dp, dp, dp, dp, dp,
                                   dp, dp],
    }
    for name, argtypes in signatures.items():
        fn = getattr(lib, name)
        fn.argtypes = argtypes
        fn.restype = ctypes.c_int
    return lib
