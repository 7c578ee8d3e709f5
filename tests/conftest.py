"""Shared fixtures for the FMU tests: where the FMU is, instances that clean up, recording."""

from __future__ import annotations

import shutil
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract

import plant
from controller import controller_fmu
from orchestrator.sim.fmu import FmuInstance

# helper modules of the tests (mavlink_harness.py) import by name: pytest's importlib mode
# does not put this folder on sys.path itself
sys.path.insert(0, str(Path(__file__).resolve().parent))

H = 0.002
"""Communication step of the co-simulation (500 Hz), s."""


@pytest.fixture(scope="session")
def plant_fmu() -> Path:
    """Path of the built MultirotorPlant FMU (plant.common.artifacts also finds the installed one
    when the source tree is imported first, as with `python -m pytest`)."""
    return plant.plant_fmu()


@pytest.fixture(scope="session")
def plant_unzip_dir(plant_fmu: Path) -> Iterator[str]:
    """The FMU extracted once: every instance of a session loads the same shared library,
    so instances share one copy of any global state the binary might (wrongly) keep."""
    root = tempfile.mkdtemp(prefix="plant_fmu_")
    extract(str(plant_fmu), root)
    yield root
    shutil.rmtree(root, ignore_errors=True)


@pytest.fixture(scope="session")
def dist(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Both FMUs built for every platform (``fullpose build-fmus --platforms all``), once per
    session: about 35 s with Zig's cache warm."""
    pytest.importorskip("ziglang", reason="the Zig cross compiler (pip install -e '.[test]')")
    from orchestrator.export.fmu_build import build_fmus
    from orchestrator.export.platforms import PLATFORMS

    folder = tmp_path_factory.mktemp("dist")
    report = build_fmus(PLATFORMS, folder)
    for name, seconds in report.seconds.items():
        print(f"{name}: {seconds:.1f} s")
    return folder


MakePlant = Callable[..., FmuInstance]


@contextmanager
def instances(fmu: Path, prefix: str, unzip_dir: str | None = None) -> Iterator[MakePlant]:
    """Factory of instances of one FMU: ``make(parameters=None, *, initialize=True, name=None,
    logging_on=False)`` returns an FmuInstance, initialized at t = 0 with the given start-value
    overrides (variable name -> value) unless ``initialize`` is False.  Every instance made is
    closed on leaving, even when initialization failed."""
    made: list[FmuInstance] = []

    def make(parameters: Mapping[str, float | int | bool] | None = None, *,
             initialize: bool = True, name: str | None = None,
             logging_on: bool = False) -> FmuInstance:
        inst = FmuInstance(fmu, name or f"{prefix}{len(made) + 1}", logging_on=logging_on,
                           unzip_dir=unzip_dir)
        made.append(inst)
        if initialize:
            inst.initialize(parameters=parameters)
        return inst

    try:
        yield make
    finally:
        for inst in made:
            inst.close()


@pytest.fixture
def make_plant(plant_fmu: Path, plant_unzip_dir: str) -> Iterator[MakePlant]:
    """Factory of plant instances (:func:`instances`), all from one extracted copy."""
    with instances(plant_fmu, "plant", plant_unzip_dir) as make:
        yield make


@pytest.fixture
def make_fmu(plant_fmu: Path) -> Iterator[Callable[..., FmuInstance]]:
    """Factory of either FMU: ``make_fmu(which="plant" | "controller", *, initialize=True,
    parameters=None)``, each instance closed after the test."""
    with instances(plant_fmu, "plant") as plant, \
            instances(controller_fmu(), "controller") as ctrl:

        def make(which: str = "plant", *, initialize: bool = True,
                 parameters: Mapping[str, float | int | bool] | None = None) -> FmuInstance:
            return (plant if which == "plant" else ctrl)(parameters, initialize=initialize)

        yield make


def record(inst: FmuInstance, n: int, outputs: Iterable[str], h: float = H,
           before_step: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """Step ``inst`` n times by h and record Real outputs.

    Returns name -> array of shape (n + 1, width) (row 0: the values before the first
    step; a scalar name gives width 1), plus ``"t"`` of shape (n + 1,).
    ``before_step(k)`` runs before step k (0-based), e.g. to write inputs.
    """
    names = list(outputs)
    signals = {name: inst.signal(name) for name in names}
    out = {name: np.empty((n + 1, len(sig.names))) for name, sig in signals.items()}
    t = np.empty(n + 1)
    t[0] = inst.time
    for name, sig in signals.items():
        out[name][0] = inst.read(sig)
    for k in range(n):
        if before_step is not None:
            before_step(k)
        inst.step(h)
        t[k + 1] = inst.time
        for name, sig in signals.items():
            out[name][k + 1] = inst.read(sig)
    out["t"] = t
    return out


Record = Callable[..., dict[str, np.ndarray]]


@pytest.fixture
def run_steps() -> Record:
    """The :func:`record` helper: ``run_steps(inst, n, ["pos", "quat"], h=0.002)``."""
    return record


def _piqp_solve(A, b, lb, ub, C=None, d=None, eps=1e-10):
    """min ||A x - b||^2 s.t. lb <= x <= ub, C x <= d with piqp (the independent oracle).

    Returns (status, x).  Equal bounds become equality rows (piqp's interior-point box
    needs lb < ub)."""
    import piqp

    n = A.shape[1]
    P = np.asfortranarray(2.0 * A.T @ A)
    c = -2.0 * A.T @ b
    eq = lb == ub
    Aeq = np.asfortranarray(np.eye(n)[eq]) if eq.any() else None
    beq = lb[eq].copy() if eq.any() else None
    lb = np.where(eq, -np.inf, lb)
    ub = np.where(eq, np.inf, ub)
    G = np.asfortranarray(C) if C is not None and C.size else None
    h = np.asarray(d, dtype=float) if G is not None else None
    solver = piqp.DenseSolver()
    solver.settings.eps_abs = eps
    solver.settings.eps_rel = eps
    solver.settings.max_iter = 500
    solver.setup(P=P, c=c, A=Aeq, b=beq, G=G, h_u=h, x_l=lb, x_u=ub)
    status = solver.solve()
    return status, np.array(solver.result.x)


@pytest.fixture(scope="session")
def piqp_solve():
    """The piqp oracle for least-squares QPs (see _piqp_solve)."""
    return _piqp_solve
