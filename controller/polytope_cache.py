"""The controller's polytope parameters of an airframe, computed once and kept on disk.

S(0) and the single-failure sets take seconds of scipy work per airframe, yet depend only
on the airframe's numbers and on the generator's code.  Every run passes them to the
controller FMU explicitly (never relying on the FMU's built-in defaults matching the
airframe), so they are cached by content: the key is a SHA-256 of the airframe's FMU
parameters and of the generator modules' source, so an edited airframe or a changed
algorithm can never be served a stale set.

The shipped airframes' sets are generated at design time and shipped beside this module
(``controller/airframe_sets/<airframe>.json``, written by ``python -m
controller.shipped_sets``): they serve an airframe whose numbers are exactly the shipped ones,
so a first run on a new machine computes nothing.  Their freshness against the generator is a
test (``--check`` compares them as sets, the way ``polytope_defaults`` does).

The plots' attainable force set and S(0) are kept the same way (:func:`force_sets`): whole
:class:`~controller.force_sets.Polytope` objects, serialized as JSON (``repr`` floats, so
they read back bit-identical).

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
import threading
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from controller.fmu_parameters import Parameters, failure_parameters, s0_parameters
from plant import Airframe

if TYPE_CHECKING:
    from controller.force_sets import Polytope

_GENERATORS = ("controller.force_sets", "controller.failures", "controller.fmu_parameters",
               "controller.polytope_cache", "plant.effectiveness")
"""The modules whose code decides the sets: their source is part of every key."""
_FORMAT = 1
SHIPPED_DIR = Path(__file__).resolve().parent / "airframe_sets"
"""Design-time sets of the shipped airframes, one JSON file per airframe name."""


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


def _numbers(airframe: Airframe) -> dict[str, Any]:
    return {k: (v if isinstance(v, (bool, int)) else repr(float(v)))
            for k, v in sorted(airframe.fmu_parameters().items())}


def cache_key(kind: str, airframe: Airframe) -> str:
    """Content address of one kind of polytope parameters of an airframe."""
    doc = {"format": _FORMAT, "kind": kind, "generator": _generator_digest(),
           "airframe": _numbers(airframe)}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def airframe_digest(airframe: Airframe) -> str:
    """SHA-256 of the airframe's numbers alone: what a shipped set file is valid for."""
    return hashlib.sha256(json.dumps(_numbers(airframe), sort_keys=True).encode()).hexdigest()


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
    _write_doc(path, {"parameters": params})


def _write_doc(path: Path, doc: dict[str, Any]) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(doc, f)
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
    return s0_parameters(cached_polytope("s0", airframe))


def failure_set_parameters(airframe: Airframe) -> Parameters:
    """The ``fail_poly_*`` parameters: S(0) after each single-rotor loss."""
    found = shipped(airframe)
    if found is not None:
        return dict(found["failures"])
    return cached_parameters("failures", airframe, _failure_parameters)


# -- whole polytopes -----------------------------------------------------------

POLYTOPE_KINDS = ("afs", "s0")
"""The attainable force set (paper section II-B) and S(tau = 0) (paper eq. 6)."""


def polytope_doc(p: Polytope) -> dict[str, Any]:
    """A polytope as JSON-ready data (arrays as nested lists of ``repr``-exact floats)."""
    return {"kind": p.kind, "airframe": p.airframe, "A": p.A.tolist(), "b": p.b.tolist(),
            "vertices": p.vertices.tolist(), "inner_points": p.inner_points.tolist(),
            "dimension": p.dimension, "n_flat": p.n_flat, "gap": p.gap,
            "relative_gap": p.relative_gap, "z_range": list(p.z_range), "scale": p.scale,
            "torque": p.torque.tolist()}


def polytope_from_doc(doc: dict[str, Any]) -> Polytope:
    """The inverse of :func:`polytope_doc`; raises ValueError on a malformed document."""
    from controller.force_sets import Polytope

    def arr(key: str, cols: int | None = 3) -> np.ndarray:
        a = np.array(doc[key], dtype=float)
        if cols is not None:
            a = a.reshape(-1, cols)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{key}: not finite")
        a.setflags(write=False)
        return a

    try:
        z_lo, z_hi = (float(z) for z in doc["z_range"])
        return Polytope(
            kind=str(doc["kind"]), airframe=str(doc["airframe"]), A=arr("A"),
            b=arr("b", None), vertices=arr("vertices"), inner_points=arr("inner_points"),
            dimension=int(doc["dimension"]), n_flat=int(doc["n_flat"]), gap=float(doc["gap"]),
            relative_gap=float(doc["relative_gap"]), z_range=(z_lo, z_hi),
            scale=float(doc["scale"]), torque=arr("torque", None))
    except (KeyError, TypeError) as e:
        raise ValueError(f"not a polytope document: {e}") from None


def compute_polytope(kind: str, airframe: Airframe) -> Polytope:
    """The polytope of ``kind`` (:data:`POLYTOPE_KINDS`) computed now, with the defaults."""
    from controller.force_sets import attainable_force_set, feasible_force_set

    if kind == "afs":
        return attainable_force_set(airframe)
    if kind == "s0":
        return feasible_force_set(airframe)
    raise ValueError(f"kind must be one of {POLYTOPE_KINDS}, got {kind!r}")


def shipped_path(name: str) -> Path:
    return SHIPPED_DIR / f"{name}.json"


def shipped(airframe: Airframe) -> dict[str, Any] | None:
    """The design-time sets of a shipped airframe, when ``airframe`` has exactly its numbers."""
    path = shipped_path(airframe.name)
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("airframe_digest") != airframe_digest(airframe):
        return None
    return doc


_MEMO: dict[tuple[str, str], Polytope] = {}
_MEMO_LOCK = threading.Lock()
_MEMO_SIZE = 16


def cached_polytope(kind: str, airframe: Airframe) -> Polytope:
    """The shipped polytope, else the cached one, else computed (and cached); the same
    object for equal airframe numbers within a process."""
    key = (kind, airframe_digest(airframe))
    with _MEMO_LOCK:
        hit = _MEMO.get(key)
    if hit is None:
        hit = _load_polytope(kind, airframe)
        with _MEMO_LOCK:
            if len(_MEMO) >= _MEMO_SIZE:
                _MEMO.pop(next(iter(_MEMO)))
            hit = _MEMO.setdefault(key, hit)
    return hit


def _load_polytope(kind: str, airframe: Airframe) -> Polytope:
    found = shipped(airframe)
    if found is not None:
        return polytope_from_doc(found[kind])
    path = cache_dir() / f"poly-{kind}-{cache_key('poly-' + kind, airframe)}.json"
    try:
        return polytope_from_doc(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError):
        pass
    poly = compute_polytope(kind, airframe)
    _write_doc(path, polytope_doc(poly))
    return poly


def force_sets(airframe: Airframe) -> tuple[Polytope, Polytope]:
    """(AFS, S(0)) of an airframe: shipped, cached or computed (see the module docstring)."""
    return cached_polytope("afs", airframe), cached_polytope("s0", airframe)


def _failure_parameters(airframe: Airframe) -> Parameters:
    from controller.failures import failure_polytopes

    return failure_parameters(failure_polytopes(airframe))
