"""Locate the built artifacts (FMUs, host-API libraries) and load a host-API library.

The FMUs and the shared libraries of the host C API (``fmu_src/host/``) are compiled from
``fmu_src/`` by ``pip install`` and installed as package data of the package that uses
them: ``plant/fmus`` and ``plant/lib`` (``libfp_multirotor``), ``controller/fmus`` and
``controller/lib`` (``libfp_controller``), ``orchestrator/lib`` (``libfp_cosim``).
``FULLPOSE_BUILD_DIR`` points at a CMake build directory instead, for C development
without reinstalling.  Each package declares its own library's functions
(``plant.native``, ``controller.native``, ``orchestrator.sim.native``).
"""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Mapping, Sequence
from importlib import metadata, resources
from pathlib import Path


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
    found.append(Path(str(root.joinpath(subdir).joinpath(filename))))
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


def library_filename(stem: str) -> str:
    """The platform's file name of the shared library ``stem``: ``lib<stem>.so``,
    ``lib<stem>.dylib`` or ``<stem>.dll``."""
    if sys.platform == "win32":
        return f"{stem}.dll"
    if sys.platform == "darwin":
        return f"lib{stem}.dylib"
    return f"lib{stem}.so"


def library_path(package: str, stem: str) -> Path:
    """Path of the host-API library ``stem`` that ``package`` ships in its ``lib/``."""
    return find_artifact(package, "lib", library_filename(stem))


def load_library(package: str, stem: str,
                 signatures: Mapping[str, Sequence[object]]) -> ctypes.CDLL:
    """Load the host-API library ``stem`` of ``package`` with its functions declared:
    ``signatures`` maps each function name to its ctypes argument types; every function
    of the host API returns int (0: success)."""
    lib = ctypes.CDLL(str(library_path(package, stem)))
    for name, argtypes in signatures.items():
        fn = getattr(lib, name)
        fn.argtypes = list(argtypes)
        fn.restype = ctypes.c_int
    return lib
