"""The controller's polytope parameters of an airframe, computed once and kept on disk.

S(0) and the single-failure sets take seconds of scipy work per airframe, yet depend only
on the airframe's numbers and on the generator's code.  Every run passes them to the
controller FMU explicitly (never relying on the FMU's built-in defaults matching the
airframe), so they are cached by content: the key is a SHA-256 of the airframe's FMU
parameters and of the generator modules' source, so an edited airframe or a changed
algorithm can never be served a stale set.

Location: ``$FULLPOSE_CACHE_DIR`` if set, else the platform's user cache folder
(``%LOCALAPPDATA%\\fullpose\\cache``, ``~/Library/Caches/fullpose``,
``$XDG_CACHE_HOME/fullpose`` or ``~/.cache/fullpose``).  Entries are written atomically; an
unreadable or corrupt entry is recomputed, an unwritable folder only costs the caching.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import math
import os
import sys
import tempfile
from collections.abc import Callable
from functools import cache
from pathlib import Path

from controller.fmu_parameters import Parameters, failure_parameters, s0_parameters
from plant import Airframe

_GENERATORS = ("controller.force_sets", "controller.failures", "controller.fmu_parameters",
               "controller.polytope_cache", "plant.effectiveness")
"""The modules whose code decides the sets: their source is part of every key."""
_FORMAT = 1


def cache_dir() -> Path:
    """Where entries live (see the module docstring)."""
    env = os.environ.get("FULLPOSE_CACHE_DIR")
    if env:
        return Path(env)
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local"))
        return base / "fullpose" / "cache"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "fullpose"
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "fullpose"


@cache
def _generator_digest() -> str:
    h = hashlib.sha256()
    for name in _GENERATORS:
        spec = importlib.util.find_spec(name)
        if spec is None or spec.origin is None:  # pragma: no cover - part of this package
            raise ImportError(f"{name} not found")
        h.update(Path(spec.origin).read_bytes())
    return h.hexdigest()


def cache_key(kind: str, airframe: Airframe) -> str:
    """Content address of one kind of polytope parameters of an airframe."""
    numbers = {k: (v if isinstance(v, (bool, int)) else repr(float(v)))
               for k, v in sorted(airframe.fmu_parameters().items())}
    doc = {"format": _FORMAT, "kind": kind, "generator": _generator_digest(),
           "airframe": numbers}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def _read(path: Path) -> Parameters | None:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    params = doc.get("parameters") if isinstance(doc, dict) else None
    if not isinstance(params, dict):
        return None
    for v in params.values():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return None
    return params


def _write(path: Path, params: Parameters) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump({"parameters": params}, f)
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only cache folder costs the next run the computation, nothing else


def cached_parameters(kind: str, airframe: Airframe,
                      compute: Callable[[Airframe], Parameters]) -> Parameters:
    """``compute(airframe)``, or its stored result for an airframe with the same numbers."""
    path = cache_dir() / f"{kind}-{cache_key(kind, airframe)}.json"
    found = _read(path)
    if found is not None:
        return found
    params = compute(airframe)
    _write(path, params)
    return params


def polytope_parameters(airframe: Airframe) -> Parameters:
    """``poly_n``, ``poly_A[i,j]``, ``poly_b[i]``: the airframe's S(0) for the controller."""
    return cached_parameters("s0", airframe, _s0_parameters)


def failure_set_parameters(airframe: Airframe) -> Parameters:
    """The ``fail_poly_*`` parameters: S(0) after each single-rotor loss."""
    return cached_parameters("failures", airframe, _failure_parameters)


def _s0_parameters(airframe: Airframe) -> Parameters:
    from controller.force_sets import feasible_force_set

    return s0_parameters(feasible_force_set(airframe))


def _failure_parameters(airframe: Airframe) -> Parameters:
    from controller.failures import failure_polytopes

    return failure_parameters(failure_polytopes(airframe))
