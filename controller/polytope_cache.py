"""The design tool's force sets of an airframe, shipped or computed once and kept on disk.

The controller FMU derives S(0) and every single-failure set from its airframe parameters
at initialization (fmu_src/controller/derive_sets.c), in milliseconds.  The scipy design tool
(:mod:`controller.force_sets`, a finer servo grid) is its oracle and computes the sets the
figures, the 3-D view and ``fullpose force-set`` show: the attainable force set and S(0) as
whole :class:`~controller.polytope.Polytope` objects, which take seconds per airframe.
They depend only on the rotors (:data:`SET_PARAMETERS`) and on the generator's code, so
they are cached by content: the key is a SHA-256 of those numbers and of the generator
modules' source, so an edited rotor or a changed algorithm can never be served a stale set,
while a change of mass, inertia or time constant keeps them.

The shipped airframes' sets are generated at design time and shipped beside this module
(``controller/airframe_sets/<airframe>.json``, written by ``python -m
controller.shipped_sets``, with the single-failure sets as controller parameters): they serve
an airframe whose rotor numbers are exactly the shipped ones, so a first run on a new machine
computes nothing, and runs pass them to the controller (:func:`design_set_parameters`).
Their freshness against the generator is a test (``--check``).  Polytopes are serialized as
JSON (``repr`` floats, so they read back bit-identical).

Location: ``$FULLPOSE_CACHE_DIR`` if set, else the platform's user cache folder
(``%LOCALAPPDATA%\\fullpose\\cache``, ``~/Library/Caches/fullpose``,
``$XDG_CACHE_HOME/fullpose`` or ``~/.cache/fullpose``).  Entries are written atomically; an
unreadable or corrupt entry is recomputed, an unwritable folder only costs the caching.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import sys
import tempfile
import threading
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from controller.fmu_parameters import Parameters, s0_parameters
from plant import Airframe

if TYPE_CHECKING:
    from controller.polytope import Polytope

_GENERATORS = ("controller.force_sets", "controller.polytope", "controller.failures",
               "controller.fmu_parameters",
               "controller.polytope_cache", "plant.effectiveness")
"""The modules whose code decides the sets: their source is part of every key."""
_FORMAT = 2
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


SET_PARAMETERS = ("n_rotors", "k_t", "k_d", "omega_min", "omega_max", "rotor_pos", "rotor_dir",
                  "rotor_gamma", "alpha_min", "alpha_max", "beta_min", "beta_max")
"""The airframe parameters the force sets depend on (eq. 5-6: the rotors and their limits);
mass, inertia, gravity and the actuator time constants do not enter them."""


def _numbers(airframe: Airframe) -> dict[str, Any]:
    """The airframe's numbers that decide its force sets (:data:`SET_PARAMETERS`)."""
    return {k: (v if isinstance(v, (bool, int)) else repr(float(v)))
            for k, v in sorted(airframe.fmu_parameters().items())
            if k.split("[")[0] in SET_PARAMETERS}


def cache_key(kind: str, airframe: Airframe) -> str:
    """Content address of one kind of polytope parameters of an airframe."""
    doc = {"format": _FORMAT, "kind": kind, "generator": _generator_digest(),
           "rotors": _numbers(airframe)}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def rotors_digest(airframe: Airframe) -> str:
    """SHA-256 of the numbers the force sets depend on: what a shipped set file is valid
    for (a heavier vehicle with the same rotors keeps its sets)."""
    return hashlib.sha256(json.dumps(_numbers(airframe), sort_keys=True).encode()).hexdigest()


def _write_doc(path: Path, doc: dict[str, Any]) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(doc, f)
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only cache folder costs the next run the computation, nothing else


def design_set_parameters(airframe: Airframe) -> Mapping[str, float | int]:
    """The controller's ``poly_*`` and ``fail_poly_*`` parameters from the design tool, for
    an airframe whose rotors are a shipped airframe's (its design-time sets, computed at a
    finer servo grid than the controller's own derivation); empty for any other airframe,
    whose controller derives every set itself at initialization.  Read once per rotor set
    within a process (a sweep builds every case's start values), handed out read-only."""
    path = _shipped_index().get(rotors_digest(airframe))
    return MappingProxyType({} if path is None else _design_sets_of(path))


@cache
def _design_sets_of(path: Path) -> Parameters:
    """The parameters of the shipped sets file at path (read once)."""
    doc = json.loads(path.read_text(encoding="utf-8"))
    params = dict(s0_parameters(polytope_from_doc(doc["s0"])))
    params.update(doc["failures"])
    return params


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
    from controller.polytope import Polytope

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
    """The shipped design-time sets file of the airframe called name."""
    return SHIPPED_DIR / f"{name}.json"


@cache
def _shipped_index() -> dict[str, Path]:
    """Shipped set files by the rotors digest they record (read once per process)."""
    index: dict[str, Path] = {}
    for path in sorted(SHIPPED_DIR.glob("*.json")):
        try:
            digest = json.loads(path.read_text(encoding="utf-8")).get("rotors_digest")
        except (OSError, ValueError, AttributeError):
            continue
        if isinstance(digest, str):
            index.setdefault(digest, path)
    return index


def shipped(airframe: Airframe) -> dict[str, Any] | None:
    """The design-time sets of the shipped airframe whose rotors ``airframe`` has exactly
    (whatever its name, mass or inertia), or None."""
    digest = rotors_digest(airframe)
    path = _shipped_index().get(digest)
    if path is None:
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("rotors_digest") != digest:
        return None
    return doc


_MEMO: dict[tuple[str, str], Polytope] = {}
_MEMO_LOCK = threading.Lock()
_MEMO_SIZE = 16


def cached_polytope(kind: str, airframe: Airframe) -> Polytope:
    """The shipped polytope, else the cached one, else computed (and cached); the same
    object for equal airframe numbers within a process."""
    key = (kind, rotors_digest(airframe))
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
