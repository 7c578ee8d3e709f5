"""Monte-Carlo robustness campaign (``fullpose sweep``).

Each case flies a scenario (default: the shipped hover at [0, 0, -3] m; any scenario file,
on any airframe) with a perturbed plant - mass x U(0.7, 1.3), each principal
inertia x U(0.5, 1.5), motor and servo time constants x U(0.7, 1.3) - a world-frame
acceleration disturbance step of amplitude U(0.5, 3) m/s^2 in a uniformly random direction,
applied at ``t_on`` = 1 s and removed at mid-run, and sensor noise (each channel's standard
deviation = U(0, 1) x the levels in :data:`NOISE`, seeded per case).  The controller keeps its
nominal mass and inertia (the model-mismatch case).  Cases are drawn from
``numpy.random.default_rng(seed)``: the table depends only on (seed, n, duration), not on how
many workers ran it.  Every case is flown by every design (H-infinity and baseline): the
comparison is on the same sampled plants and disturbances.

Metrics per run: max and RMS position error after the disturbance onset, recovery time (time
after the step on and after the step off until the error stays below the recovery band: 5 mm,
or 4x the RMS error of the undisturbed hover before the step when sensor noise makes that
larger; the larger of the two times), stable (finite and max error < ``diverged_bound``).

Workers (:class:`Worker`): the calling process (``workers=1``), each process of the local pool
and each Dask worker process instantiates the plant and controller FMUs once (one unzip, one
library load) and between cases only resets them (fmi2Reset) and sets the next case's start
values; the campaign's scenario is validated once per worker, and the perturbed vehicle is
an :class:`~plant.Airframe` the plant flies (the controller keeps the nominal one).  A worker
sends back only the case's row of metrics.
``reuse=False`` flies every case on freshly loaded FMUs instead: the previous path, and the
oracle the tests hold the reused one to, bit for bit.

The rotor-fault campaign (``fullpose sweep --faults``) flies on the same workers:
:mod:`orchestrator.sweep_faults`.
"""

from __future__ import annotations

import atexit
import dataclasses
import functools
import math
import multiprocessing.util
import os
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from orchestrator.scenario.model import Scenario
    from orchestrator.sim.fmu import FmuInstance

NOISE = {"noise_pos": 0.002, "noise_vel": 0.005, "noise_acc": 0.05, "noise_att": 0.002,
         "noise_rate": 0.005, "noise_ang_acc": 0.05}
T_ON = 1.0
RECOVERY_BAND = 0.005
# Recovery is measured against max(RECOVERY_BAND, NOISE_FLOOR_FACTOR x the RMS error between
# QUIET_FROM and T_ON): with sensor noise a fixed 5 mm band may never be re-entered for good,
# which would measure the noise, not the recovery.
NOISE_FLOOR_FACTOR = 4.0
QUIET_FROM = 0.25
DIVERGED_BOUND = 1.0
COLUMNS = ("case", "design", "mass_scale", "ixx_scale", "iyy_scale", "izz_scale",
           "tau_motor_scale", "tau_servo_scale", "dist_amp", "dist_x", "dist_y", "dist_z",
           "torque_amp", "torque_x", "torque_y", "torque_z", "delay",
           "noise_scale", "stable", "max_err", "rms_err", "recovery_time", "recovery_band",
           "wall_time")


def sample_cases(n: int, seed: int = 0, noise: float = 1.0, torque: float = 0.0,
                 delay: bool = False) -> list[dict[str, float]]:
    """n cases from ``seed``; ``noise`` scales every case's sensor noise (0: none) and leaves
    the other draws unchanged, so the same plants and disturbances can be flown noise-free.
    ``torque`` > 0 adds a body-torque step of amplitude U(0.2, 1) x ``torque`` N m in a
    uniformly random direction, on and off with the acceleration step, drawn from a generator
    of its own (seed, 1): the other draws stay those of the same seed without it.  ``delay``
    flies every case with the Jacobi coupling: the command one sample late."""
    rng = np.random.default_rng(seed)
    trng = np.random.default_rng([seed, 1])
    cases = []
    for i in range(n):
        t = trng.standard_normal(3)
        t /= np.linalg.norm(t)
        t_amp = torque * trng.uniform(0.2, 1.0)
        d = rng.standard_normal(3)
        d /= np.linalg.norm(d)
        cases.append({
            "case": i, "seed": int(rng.integers(1, 2**31 - 1)),
            "mass_scale": rng.uniform(0.7, 1.3),
            "ixx_scale": rng.uniform(0.5, 1.5), "iyy_scale": rng.uniform(0.5, 1.5),
            "izz_scale": rng.uniform(0.5, 1.5),
            "tau_motor_scale": rng.uniform(0.7, 1.3), "tau_servo_scale": rng.uniform(0.7, 1.3),
            "dist_amp": rng.uniform(0.5, 3.0), "dist_x": d[0], "dist_y": d[1], "dist_z": d[2],
            "torque_amp": t_amp, "torque_x": t[0], "torque_y": t[1], "torque_z": t[2],
            "delay": int(delay), "noise_scale": noise * rng.uniform(0.0, 1.0)})
    return cases


DASK_CONFIG: dict[str, Any] = {
    "distributed.admin.tick.interval": "200ms",  # the event-loop watchdog (default 20 ms)
    "distributed.worker.profile.enabled": False,  # the statistical profiler (every 10 ms)
    "distributed.worker.memory.monitor-interval": "1s",  # (100 ms)
    "distributed.admin.system-monitor.interval": "2s",  # (500 ms)
    "distributed.scheduler.work-stealing": False,  # uniform tasks, handed out in order
    # Dask's nanny gives its workers MALLOC_TRIM_THRESHOLD_=65536, which also fixes glibc's
    # mmap threshold at 128 KiB: every run's arrays then come as fresh zeroed pages (1,193
    # page faults and 1.6 ms of kernel time per 6 s run, measured).  glibc's own behaviour
    # for arrays below 32 MiB; the BLAS thread pins as Dask sets them.
    "distributed.nanny.pre-spawn-environ": {
        "MALLOC_TRIM_THRESHOLD_": 2**30, "MALLOC_MMAP_THRESHOLD_": 2**25,
        "OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1},
}
"""Dask settings for a cluster that runs sweeps: ``with dask.config.set(DASK_CONFIG):`` around
creating a LocalCluster, or the matching ``DASK_DISTRIBUTED__...`` environment variables for
``dask scheduler`` / ``dask worker``.  An idle default LocalCluster of 2 workers burns about
0.2 cores (watchdog ticks, monitors, profiling), a tenth of a 2-core machine; with these
about 0.04 (docs/orchestrator.md)."""

MATCHED = "_matched"
BASE_DESIGNS = ("hinf", "baseline", "prototype")


def designs() -> dict[str, dict[str, float]]:
    """Controller parameter overrides of the designs a sweep can fly (hinf: the shipped
    defaults; baseline: P blocks at the same crossovers; prototype: the hand-tuned P blocks
    2.2, 6, 9, 20 1/s).  ``NAME_matched`` is
    NAME with the controller told the perturbed plant's true mass and inertia (the reference
    for what the model mismatch costs)."""
    return {name: dict(p) for name, p in _designs().items()}


@functools.cache
def _designs() -> dict[str, dict[str, float]]:
    """designs(), computed once per process (the baseline's crossover tuning takes ~0.5 s)."""
    from controller import baseline, gains_defaults

    base = dict(zip(BASE_DESIGNS, (gains_defaults.controller_parameters(),
                                   baseline.controller_parameters(),
                                   baseline.controller_parameters(baseline.PROTOTYPE)),
                    strict=True))
    return {**base, **{name + MATCHED: p for name, p in base.items()}}


def perturbed(base: Scenario, case: dict[str, float], design: str,
              params: dict[str, float], duration: float) -> Scenario:
    """The scenario of one (case, design): the base scenario with the plant flying a
    perturbed copy of its :class:`~plant.Airframe` (mass, principal inertias and actuator
    time constants scaled by the case's factors, from the values the base scenario flies),
    the disturbance step and sensor noise, the design's gains; the controller keeps the
    nominal airframe (``NAME_matched``: it is told the perturbed mass and inertia).  It
    differs from ``base`` only in the plant's airframe, parameters and disturbances, never
    in the pose or the references."""
    from orchestrator.scenario.signals import Steps

    af = base.airframe
    given = base.plant_parameters
    inertia = np.array(af.inertia, dtype=float)
    for i, key in enumerate(("ixx_scale", "iyy_scale", "izz_scale")):
        name = f"inertia[{i + 1},{i + 1}]"
        inertia[i, i] = float(given.get(name, inertia[i, i])) * case[key]
    vehicle = dataclasses.replace(
        af, mass=float(given.get("mass", af.mass)) * case["mass_scale"], inertia=inertia,
        tau_motor=float(given.get("tau_motor", af.tau_motor)) * case["tau_motor_scale"],
        tau_servo=float(given.get("tau_servo", af.tau_servo)) * case["tau_servo_scale"])
    scaled = {"mass", "tau_motor", "tau_servo"} | {f"inertia[{i},{i}]" for i in (1, 2, 3)}
    plant: dict[str, Any] = {k: v for k, v in given.items() if k not in scaled}
    for name, level in NOISE.items():
        plant[name] = level * case["noise_scale"]
    plant["noise_seed"] = int(case["seed"])
    amp = case["dist_amp"]
    t_off = _t_off(duration)
    acc_x, acc_y, acc_z = (Steps((T_ON, t_off), (amp * case[k], 0.0))
                           for k in ("dist_x", "dist_y", "dist_z"))
    t_amp = case.get("torque_amp", 0.0)
    torque = base.torque
    if t_amp > 0:
        torque = (Steps((T_ON, t_off), (t_amp * case["torque_x"], 0.0)),
                  Steps((T_ON, t_off), (t_amp * case["torque_y"], 0.0)),
                  Steps((T_ON, t_off), (t_amp * case["torque_z"], 0.0)))
    told = af
    if design.endswith(MATCHED):
        told = dataclasses.replace(af, mass=vehicle.mass, inertia=vehicle.inertia)
    return dataclasses.replace(base, airframe=told, plant_airframe=vehicle,
                               acceleration=(acc_x, acc_y, acc_z), torque=torque,
                               coupling="jacobi" if case.get("delay") else base.coupling,
                               plant_parameters=plant,
                               controller_parameters={**base.controller_parameters, **params})


@dataclasses.dataclass(frozen=True)
class Campaign:
    """What every case of a sweep flies: a scenario (shipped name or file, default the
    hover), optionally on another airframe (shipped name or file), for ``duration`` s."""

    scenario: str = "hover"
    airframe: str | None = None
    duration: float = 6.0

    def base(self) -> Scenario:
        """The campaign's scenario, validated (nothing runs)."""
        from orchestrator.runner import prepare

        return prepare(self.scenario, self.duration, airframe=self.airframe)


def _t_off(duration: float) -> float:
    return T_ON + 0.5 * (duration - T_ON)


def run_case(case: dict[str, float], design: str, params: dict[str, float],
             campaign: Campaign, worker: Worker | None = None) -> dict[str, Any]:
    """One closed-loop run; returns a table row.  With a ``worker`` the run uses its FMU
    instances, reset (fmi2Reset) from the previous case; without, it loads fresh FMUs as a
    single run does (the reference the reused path is tested against, bit for bit)."""
    from orchestrator.master import CoSimulation
    from orchestrator.sim.engine import RunError
    from orchestrator.sim.fmu import FmuError

    t0 = time.perf_counter()
    duration = campaign.duration
    base = worker.base(campaign) if worker is not None else campaign.base()
    sc = perturbed(base, case, design, params, duration)
    sim = CoSimulation(sc, fmus=worker.fmus() if worker is not None else None)
    row: dict[str, Any] = {k: case[k] for k in COLUMNS if k in case}
    row["design"] = design
    try:
        res = sim.run()
        t = np.asarray(res.time)
        pos = res.get(res.judged("plant.pos"))  # with sensor noise: the truth
        err = np.linalg.norm(np.asarray(pos) - np.asarray(res.get("ref.pos_ref")),
                             axis=1)
    except (RunError, FmuError):  # a diverged plant may make an FMU refuse a step
        t, err = np.array([0.0]), np.array([np.inf])
    row.update(case_metrics(t, err, len(t) >= sc.n_steps, duration))
    row["wall_time"] = time.perf_counter() - t0
    return row


def case_metrics(t: np.ndarray, err: np.ndarray, complete: bool,
                 duration: float) -> dict[str, Any]:
    """stable, max_err, rms_err, recovery_time, recovery_band of one run's position error
    ``err`` at times ``t`` (``complete``: the run reached its end)."""
    after = t >= T_ON
    e = err[after] if after.any() else err
    finite = bool(np.all(np.isfinite(e))) and complete
    mx = float(np.max(e)) if finite else math.inf
    out: dict[str, Any] = {"stable": int(finite and mx < DIVERGED_BOUND), "max_err": mx,
                           "rms_err": float(np.sqrt(np.mean(e ** 2))) if finite else math.inf}
    rec, band = 0.0, RECOVERY_BAND
    if finite:
        quiet = err[(t >= QUIET_FROM) & (t < T_ON)]
        if quiet.size:  # the sensor-noise floor before the disturbance, as seen undisturbed
            band = max(band, NOISE_FLOOR_FACTOR * float(np.sqrt(np.mean(quiet ** 2))))
        t_off = _t_off(duration)
        for start, stop in ((T_ON, t_off), (t_off, duration + 1.0)):
            m = (t >= start) & (t < stop)
            bad = np.nonzero(err[m] > band)[0]
            if len(bad):
                rec = max(rec, float(t[m][bad[-1]] - start))
    out["recovery_time"] = rec if finite else math.inf
    out["recovery_band"] = band
    return out


class Worker:
    """What one worker keeps from case to case: the plant and controller FMU instantiated
    once (one unzip, one library load), reset with fmi2Reset before every case and then
    given the case's start values; the campaign's validated scenario once per campaign.
    ``with Worker() as w`` closes the instances."""

    def __init__(self, inherited: Worker | None = None) -> None:
        """``inherited``: the parent's worker a forked child starts from: its instances
        (copied into this process by the fork, so nothing is unzipped or loaded again) and
        its scenarios, used here but never closed here (the files are the parent's)."""
        self.pid = os.getpid()
        self._fmus: tuple[FmuInstance, FmuInstance] | None = None
        self._bases: dict[Campaign, Scenario] = {}
        self._owns_fmus = True
        if inherited is not None:
            self._fmus, self._owns_fmus = inherited._fmus, False
            self._bases = dict(inherited._bases)

    def fmus(self) -> tuple[FmuInstance, FmuInstance]:
        """(plant, controller) in the Instantiated state, ready for a run: instantiated at
        the first call, reset at every call (whatever the previous run left: completed,
        lost, refused).  A pair that cannot be reset (an FMU gone Fatal) is replaced."""
        from orchestrator.sim.fmu import FmuError

        if self._fmus is None:
            self._fmus, self._owns_fmus = _instantiate(), True
        try:
            for inst in self._fmus:
                inst.reset()
        except FmuError:
            self.close()
            self._fmus, self._owns_fmus = _instantiate(), True
        return self._fmus

    def base(self, campaign: Campaign) -> Scenario:
        """The campaign's scenario, validated once per worker."""
        found = self._bases.get(campaign)
        if found is None:
            found = self._bases[campaign] = campaign.base()
        return found

    def close(self) -> None:
        """Frees the instances (in the process that made them only: a forked child's copy
        must not remove its parent's unzipped files)."""
        fmus, self._fmus = self._fmus, None
        if fmus is not None and os.getpid() == self.pid and self._owns_fmus:
            for inst in fmus:
                inst.close()

    def __enter__(self) -> Worker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _instantiate() -> tuple[FmuInstance, FmuInstance]:
    from controller import controller_fmu
    from orchestrator.sim.fmu import FmuInstance
    from plant import plant_fmu

    plant = FmuInstance(plant_fmu(), "plant")
    try:
        return plant, FmuInstance(controller_fmu(), "controller")
    except BaseException:
        plant.close()
        raise


_LOCAL = threading.local()


def process_worker() -> Worker:
    """This process's worker (one per thread), made at its first case and closed when the
    process exits; a forked child makes its own."""
    w: Worker | None = getattr(_LOCAL, "worker", None)
    if w is None or w.pid != os.getpid():
        w = _LOCAL.worker = Worker(inherited=w)
        atexit.register(w.close)
        multiprocessing.util.Finalize(None, w.close, exitpriority=0)  # pool workers' exit
    return w


CaseRun = Callable[[dict[str, float], str, dict[str, float], Campaign, Worker | None],
                   dict[str, Any]]
"""One case's closed-loop run, (case, design, the design's controller parameters, the
campaign, the worker or None) -> the case's table row: :func:`run_case`, or the fault
campaign's :func:`orchestrator.sweep_faults.run_fault_case`."""

Task = tuple[CaseRun, dict[str, float], str, dict[str, float], Campaign, bool]
"""(the run, case, design, the design's controller parameters, the campaign, reuse FMUs)."""


def _task(args: Task) -> dict[str, Any]:
    run, case, design, params, campaign, reuse = args
    return run(case, design, params, campaign, process_worker() if reuse else None)


def _batch(tasks: Sequence[Task]) -> list[dict[str, Any]]:
    return [_task(t) for t in tasks]


def run_sweep(n: int, seed: int = 0, duration: float = 6.0, workers: int = 1,
              dask: str | Any | None = None, progress: bool | None = None,
              design_set: Sequence[str] = ("hinf", "baseline"),
              noise: float = 1.0, reuse: bool = True, torque: float = 0.0,
              delay: bool = False, scenario: str | Path = "hover",
              airframe: str | Path | None = None) -> list[dict[str, Any]]:
    """All (case, design) runs of ``scenario`` (default the hover; on ``airframe`` when
    given), sorted by (case, design); identical for any worker count and with or without
    ``reuse`` (each worker's FMUs instantiated once and reset between cases;
    ``reuse=False``: fresh FMUs loaded for every case).  The scenario and airframe are
    validated here first, so a mistake is one error, not one per worker.  The rotor-fault
    campaign: :func:`orchestrator.sweep_faults.run_fault_sweep`."""
    campaign = Campaign(str(scenario), None if airframe is None else str(airframe),
                        float(duration))
    return run_campaign(run_case, lambda base: sample_cases(n, seed, noise, torque, delay),
                        campaign, design_set, workers, dask, progress, reuse)


def run_campaign(run: CaseRun, draw: Callable[[Scenario], list[dict[str, float]]],
                 campaign: Campaign, design_set: Sequence[str], workers: int = 1,
                 dask: str | Any | None = None, progress: bool | None = None,
                 reuse: bool = True) -> list[dict[str, Any]]:
    """Every (case, design) run of ``campaign``, each flown by ``run``, the cases drawn by
    ``draw`` from the campaign's scenario once it is validated (the designs first), sorted by
    (case, design); on ``workers`` local processes or the Dask cluster ``dask`` as
    :func:`run_sweep` describes."""
    params = designs()
    unknown = [d for d in design_set if d not in params]
    if unknown or not design_set:
        raise ValueError(f"unknown design(s) {unknown or '(none)'}; known: {', '.join(params)}")
    base = campaign.base()
    tasks: list[Task] = [(run, c, d, params[d], campaign, reuse)
                         for c in draw(base) for d in design_set]
    if progress is None:
        progress = sys.stderr.isatty()
    bar = _bar(len(tasks), progress)
    workers = min(workers, max(1, len(tasks) // 2))  # no worker without two runs to fly
    if dask is not None:
        rows = _on_dask(dask, tasks, bar)
    elif workers <= 1:
        rows = _in_process(tasks, bar)
    else:
        rows = _on_pool(workers, tasks, bar)
    bar(0, close=True)
    rows.sort(key=lambda r: (r["case"], r["design"]))
    return rows


def _in_process(tasks: Sequence[Task], bar: Callable[..., None]) -> list[dict[str, Any]]:
    rows = []
    with Worker() as w:
        for run, case, design, params, campaign, reuse in tasks:
            rows.append(run(case, design, params, campaign, w if reuse else None))
            bar(1)
    return rows


def _chunks(tasks: Sequence[Task], workers: int) -> list[list[Task]]:
    """Guided self-scheduling: each batch is 1 / (4 x workers) of the tasks still to hand
    out, so batches shrink towards the end: few messages (a Dask task costs milliseconds of
    scheduling), and the last ones single tasks, so no worker idles long at the end."""
    out, i, n = [], 0, len(tasks)
    while i < n:
        size = max(1, (n - i) // (4 * max(workers, 1)))
        out.append(list(tasks[i:i + size]))
        i += size
    return out


def _on_pool(workers: int, tasks: Sequence[Task],
             bar: Callable[..., None]) -> list[dict[str, Any]]:
    from orchestrator import (
        master,  # noqa: F401
        runner,  # noqa: F401  (forked workers inherit them)
    )

    # this process's FMU instances, the campaign's scenario and what building start values
    # reads once (the modelDescription, the design sets), made before the workers fork so
    # that they start flying at once: a forked worker adopts copies of all of them (a
    # spawned one, where fork is not the start method, makes its own)
    from orchestrator.sim.start_values import start_values

    parent = process_worker()
    parent.fmus()
    for campaign in {t[4] for t in tasks}:
        start_values(parent.base(campaign).airframe)  # (its caches: variables, design sets)
    rows: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=workers) as ex:
        for done in ex.map(_batch, _chunks(tasks, workers)):
            rows += done
            bar(len(done))
    return rows


def _on_dask(dask: str | Any, tasks: Sequence[Task],
             bar: Callable[..., None]) -> list[dict[str, Any]]:
    from dask.distributed import Client, as_completed

    client: Any = dask if hasattr(dask, "submit") else Client(dask)
    rows: list[dict[str, Any]] = []
    try:
        threads = sum(client.nthreads().values())
        futs = [client.submit(_batch, b, pure=False) for b in _chunks(tasks, threads)]
        for _, done in as_completed(futs, with_results=True):
            rows += done
            bar(len(done))
    finally:
        if client is not dask:
            client.close()
    return rows


def _bar(total: int, enabled: bool) -> Callable[..., None]:
    if not enabled:
        return lambda k, close=False: None
    from tqdm import tqdm

    pb = tqdm(total=total, unit="run", file=sys.stderr)

    def step(k: int, close: bool = False) -> None:
        if k:
            pb.update(k)
        if close:
            pb.close()
    return step


def default_workers() -> int:
    """The processes this one may run on."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
               else os.cpu_count() or 1)

