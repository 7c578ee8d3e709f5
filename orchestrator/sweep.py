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

**The rotor-fault campaign** (``Campaign(faults=True)``, ``fullpose sweep --faults``), on the
same workers: can the controller's fault detector (``fmu_src/controller/detect.c``) tell a lost
or weakened rotor from an unknown load?

Every case flies the campaign's scenario (default the hover) with the controller never told
of a fault (``fault_detection`` none: only its detector can find one), its nominal airframe and
the design's gains, and sensor noise as the disturbance campaign has it (each channel's
standard deviation = U(0, 1) x the levels in :data:`NOISE`, seeded per case).  Cases
alternate: even cases are **loads**, odd cases **faults** (half and half).

- **A load** is a non-empty random subset (each of the 15 equally likely) of: the plant's mass
  x U(0.7, 1.3) (from the start; the controller keeps the nominal mass); a payload of
  U(5, 15) % of the plant's mass hung at a random rotor's arm tip (a world-down force plus the
  body torque r_i x F it makes about the centre, r_i that rotor's position in the airframe,
  F taken at the reference attitude at the step); a body-torque step of U(0.05, 0.3) N m in a
  uniformly random direction; a world-frame force step of U(0.05, 0.3) x the nominal weight
  in a uniformly random direction.  The steps come on at :data:`T_LOAD` and stay.  None of
  these is a rotor fault.
- **A fault**: a random rotor at efficiency 0 (a total loss, a quarter of the faults) or
  U(0, 0.9) (a partial fault) from ``t_fault`` on.  Half the faults come with a load drawn as
  above: its steps at :data:`T_LOAD` and the fault at :data:`T_LOAD` + :data:`FAULT_AFTER_LOAD`,
  once the detector has had the load's event (one event, one explanation: a load and a fault
  stepping on in the same instant is outside what the detector claims).  Without a load the
  fault comes at :data:`T_LOAD`.

The draws come from a generator of their own, ``numpy.random.default_rng([seed, 2])``: the
case table depends only on (seed, n, noise, the airframe's rotor count), and the disturbance
campaign's draws are untouched.  Every case draws the same numbers whatever its kind.

Metrics per case, from the controller's outputs ``rotors_detected`` (bit i-1: the detector
concluded something about rotor i; a bit once set stays set) and ``rotor_eff_est``:

- ``detected``: the final ``rotors_detected`` bitmask.
- ``false_alarm`` (1/0): the detector concluded about a healthy rotor: a bit set for a rotor
  other than the faulty one (every rotor in a load case), or the faulty rotor's bit set before
  its fault.  ``false_lost`` (1/0): a healthy rotor's estimate below 0.15 (declared lost) at
  any sample.
- ``missed`` (1/0): a fault with a loss 1 - efficiency >= :data:`LOSS_MIN` (0.1, the
  detector's ``fault_loss_min``; every sampled fault) whose rotor's bit is not set by the end
  of the run.
- ``detect_time`` (s): from the fault to the first sample with the faulty rotor's bit set
  (NaN when missed or for a load).
- ``est`` and ``est_err``: the faulty rotor's final estimate and |estimate - true
  efficiency|, for detected faults (NaN otherwise); ``est_off`` (1/0): ``est_err`` >
  :data:`EST_TOL` (0.05).
- ``stable`` and ``max_err``: the run reached its end with the position error (truth) below
  :data:`DIVERGED_BOUND` after the first step; its largest value there.
  ``heading_err``: the largest heading error (truth, wrapped) after the first step; ``held``
  (1/0): stable and ``heading_err`` < :data:`HEADING_BOUND`.  A load the vehicle cannot
  hold (a yaw torque beyond what the rotors' drag gives a vehicle with vertical rotors spins
  it) leaves the detector's premises - the residual of a vehicle whose allocation saturates -
  and is counted among the cases, and reported apart too.

:func:`summarize_faults` counts these over the cases; estimate errors are over the detected
faults, detection times over the detected faults (and over the total losses alone).
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
    from orchestrator.scenario.model import Scenario, Vec3
    from orchestrator.sim.fmu import FmuInstance
    from plant import Airframe

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
    hover), optionally on another airframe (shipped name or file), for ``duration`` s;
    ``faults``: the rotor-fault campaign's cases (module docstring) instead of the disturbance
    campaign's."""

    scenario: str = "hover"
    airframe: str | None = None
    duration: float = 6.0
    faults: bool = False

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
    single run does (the reference the reused path is tested against, bit for bit).  A
    fault campaign's case goes to :func:`run_fault_case`."""
    if campaign.faults:
        return run_fault_case(case, design, params, campaign, worker)
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


Task = tuple[dict[str, float], str, dict[str, float], Campaign, bool]
"""(case, design, the design's controller parameters, the campaign, reuse FMUs)."""


def _task(args: Task) -> dict[str, Any]:
    case, design, params, campaign, reuse = args
    return run_case(case, design, params, campaign, process_worker() if reuse else None)


def _batch(tasks: Sequence[Task]) -> list[dict[str, Any]]:
    return [_task(t) for t in tasks]


def run_sweep(n: int, seed: int = 0, duration: float = 6.0, workers: int = 1,
              dask: str | Any | None = None, progress: bool | None = None,
              design_set: Sequence[str] = ("hinf", "baseline"),
              noise: float = 1.0, reuse: bool = True, torque: float = 0.0,
              delay: bool = False, scenario: str | Path = "hover",
              airframe: str | Path | None = None, faults: bool = False) -> list[dict[str, Any]]:
    """All (case, design) runs of ``scenario`` (default the hover; on ``airframe`` when
    given), sorted by (case, design); identical for any worker count and with or without
    ``reuse`` (each worker's FMUs instantiated once and reset between cases;
    ``reuse=False``: fresh FMUs loaded for every case).  The scenario and airframe are
    validated here first, so a mistake is one error, not one per worker.  ``faults``: the
    rotor-fault campaign (module docstring; no ``torque`` or ``delay``)."""
    params = designs()
    unknown = [d for d in design_set if d not in params]
    if unknown or not design_set:
        raise ValueError(f"unknown design(s) {unknown or '(none)'}; known: {', '.join(params)}")
    campaign = Campaign(str(scenario), None if airframe is None else str(airframe),
                        float(duration), faults)
    base = campaign.base()
    tasks: list[Task] = [(c, d, params[d], campaign, reuse)
                         for c in _cases(n, seed, noise, torque, delay, campaign, base)
                         for d in design_set]
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


def _cases(n: int, seed: int, noise: float, torque: float, delay: bool, campaign: Campaign,
           base: Scenario) -> list[dict[str, float]]:
    """The campaign's sampled cases (a fault campaign's rotors are the base airframe's)."""
    if not campaign.faults:
        return sample_cases(n, seed, noise, torque, delay)
    if torque or delay:
        raise ValueError("the fault campaign takes neither a torque step amplitude nor the "
                         "delay (its loads are its own)")
    if campaign.duration < FAULT_MIN_DURATION:
        raise ValueError(f"the fault campaign needs a duration of at least "
                         f"{FAULT_MIN_DURATION:g} s, "
                         f"got {campaign.duration:g}")
    return sample_fault_cases(n, seed, noise, base.airframe.n_rotors)


def _in_process(tasks: Sequence[Task], bar: Callable[..., None]) -> list[dict[str, Any]]:
    rows = []
    with Worker() as w:
        for case, design, params, campaign, reuse in tasks:
            rows.append(run_case(case, design, params, campaign, w if reuse else None))
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
    for campaign in {t[3] for t in tasks}:
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


# -- the rotor-fault campaign (module docstring) ------------------------------------------

T_LOAD = T_ON  # s: the loads' steps (and a fault without a load)
FAULT_AFTER_LOAD = 1.0  # s: a fault after its case's load
LOSS_MIN = 0.1  # a fault losing this share of efficiency or more must be detected
EST_TOL = 0.05  # largest estimate error the issue accepts
LOST_BELOW = 0.15  # an estimate below this declares the rotor lost (detect.c's threshold)
HEADING_BOUND = 0.5  # rad: a heading error beyond it is a load the vehicle did not hold
TOTAL_SHARE = 0.25  # the share of faults that are total losses (efficiency 0)
FAULT_MIN_DURATION = T_LOAD + FAULT_AFTER_LOAD + 0.5  # s: half a second after a late fault
FAULT_DURATION = 4.0  # s: the fault campaign's default duration
LOAD_PARTS = ("mass", "payload", "torque", "force")
FAULT_COLUMNS = ("case", "design", "kind", "mass_scale", "payload_share", "payload_rotor",
                 "torque_amp", "torque_x", "torque_y", "torque_z", "force_amp", "force_x",
                 "force_y", "force_z", "fault_rotor", "fault_eff", "t_fault", "noise_scale",
                 "stable", "max_err", "heading_err", "held", "detected", "detect_time", "est",
                 "est_err", "false_alarm", "false_lost", "missed", "est_off", "wall_time")


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def sample_fault_cases(n: int, seed: int = 0, noise: float = 1.0,
                       n_rotors: int = 6) -> list[dict[str, float]]:
    """n cases (even: loads, odd: faults) from ``default_rng([seed, 2])``, rotors numbered
    1..``n_rotors``; ``noise`` scales every case's sensor noise (0: none) and leaves the
    other draws unchanged.  Absent parts are neutral (mass scale 1, amplitudes 0, rotor 0)."""
    rng = np.random.default_rng([seed, 2])
    return [_draw(rng, i, noise, n_rotors) for i in range(n)]


def _draw(rng: np.random.Generator, i: int, noise: float, n_rotors: int) -> dict[str, float]:
    """Case i's draws, the same numbers in the same order for either kind."""
    parts, with_load = int(rng.integers(1, 16)), bool(rng.random() < 0.5)
    mass, share = rng.uniform(0.7, 1.3), rng.uniform(0.05, 0.15)
    payload_rotor = int(rng.integers(1, n_rotors + 1))
    t_amp, t_dir = rng.uniform(0.05, 0.3), _unit(rng)
    f_amp, f_dir = rng.uniform(0.05, 0.3), _unit(rng)
    fault_rotor = int(rng.integers(1, n_rotors + 1))
    total, eff = bool(rng.random() < TOTAL_SHARE), rng.uniform(0.0, 0.9)
    noise_scale, noise_seed = noise * rng.uniform(0.0, 1.0), int(rng.integers(1, 2**31 - 1))
    fault = i % 2 == 1
    load = not fault or with_load
    on = {p: load and bool(parts >> k & 1) for k, p in enumerate(LOAD_PARTS)}
    return {"case": i, "seed": noise_seed, "fault": int(fault),
            "mass_scale": mass if on["mass"] else 1.0,
            "payload_share": share if on["payload"] else 0.0,
            "payload_rotor": payload_rotor if on["payload"] else 0,
            "torque_amp": t_amp if on["torque"] else 0.0,
            "torque_x": t_dir[0], "torque_y": t_dir[1], "torque_z": t_dir[2],
            "force_amp": f_amp if on["force"] else 0.0,
            "force_x": f_dir[0], "force_y": f_dir[1], "force_z": f_dir[2],
            "fault_rotor": fault_rotor if fault else 0,
            "fault_eff": (0.0 if total else eff) if fault else 1.0,
            "t_fault": (T_LOAD + FAULT_AFTER_LOAD if load else T_LOAD) if fault else math.nan,
            "noise_scale": noise_scale}


def rot_zyx(euler: np.ndarray) -> np.ndarray:
    """R = Rz(psi) Ry(theta) Rx(phi) of Euler angles [phi, theta, psi] (body FRD -> world
    NED)."""
    (cf, ct, cp), (sf, st, sp) = np.cos(euler), np.sin(euler)
    rz = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cf, -sf], [0.0, sf, cf]])
    return rz @ ry @ rx


def load_wrench(case: dict[str, float], plant: Airframe, nominal: Airframe,
                euler: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The load's stepped (world force N, body torque N m): the force step, the payload's
    weight at its rotor's arm tip (force and the torque r_i x F, F in the body frame at Euler
    angles ``euler``) and the torque step."""
    weight = nominal.mass * nominal.gravity
    force = case["force_amp"] * weight * np.array([case[k] for k in ("force_x", "force_y",
                                                                      "force_z")])
    torque = case["torque_amp"] * np.array([case[k] for k in ("torque_x", "torque_y",
                                                              "torque_z")])
    rotor = int(case["payload_rotor"])
    if rotor > 0:
        f_pay = np.array([0.0, 0.0, case["payload_share"] * plant.mass * plant.gravity])
        force = force + f_pay
        torque = torque + np.cross(plant.positions[rotor - 1], rot_zyx(euler).T @ f_pay)
    return force, torque


def fault_scenario(base: Scenario, case: dict[str, float], params: dict[str, float],
                   duration: float, matched: bool = False) -> Scenario:
    """The scenario of one case: ``base`` with the plant flying its airframe at the case's
    mass, the load's steps from :data:`T_LOAD`, the fault, sensor noise, the design's gains,
    the controller never told of the fault (``matched``: told the plant's mass)."""
    from orchestrator.scenario.model import Fault

    af, given = base.airframe, base.plant_parameters
    vehicle = dataclasses.replace(af, mass=float(given.get("mass", af.mass)) * case["mass_scale"])
    plant: dict[str, Any] = {k: v for k, v in given.items() if k != "mass"}
    for name, level in NOISE.items():
        plant[name] = level * case["noise_scale"]
    plant["noise_seed"] = int(case["seed"])
    euler = base.references(np.array([T_LOAD]))["euler_ref"][0]
    force, torque = load_wrench(case, vehicle, af, euler)
    faults: tuple[Fault, ...] = ()
    if case["fault"]:
        faults = (Fault(float(case["t_fault"]), int(case["fault_rotor"]),
                        float(case["fault_eff"])),)
    return dataclasses.replace(
        base, airframe=vehicle if matched else af, plant_airframe=vehicle,
        plant_parameters=plant, faults=faults,
        fault_detection=None, duration=duration,
        force=_stepped(force), torque=_stepped(torque),
        controller_parameters={**base.controller_parameters, **params})


def _stepped(v: np.ndarray) -> Vec3:
    """Three steps from 0 to v's components at :data:`T_LOAD`."""
    from orchestrator.scenario.signals import Steps

    x, y, z = (Steps((T_LOAD,), (float(c),)) for c in v)
    return x, y, z


def run_fault_case(case: dict[str, float], design: str, params: dict[str, float],
                   campaign: Campaign, worker: Worker | None = None) -> dict[str, Any]:
    """One closed-loop run of a fault-campaign case; returns its table row (on the worker's
    FMUs, reset, or on fresh ones without a worker)."""
    from orchestrator.master import CoSimulation
    from orchestrator.sim.engine import RunError
    from orchestrator.sim.fmu import FmuError

    t0 = time.perf_counter()
    base = worker.base(campaign) if worker is not None else campaign.base()
    sc = fault_scenario(base, case, params, campaign.duration, design.endswith(MATCHED))
    sim = CoSimulation(sc, fmus=worker.fmus() if worker is not None else None)
    row: dict[str, Any] = {k: case[k] for k in FAULT_COLUMNS if k in case}
    row.update(design=design, kind="fault" if case["fault"] else "load")
    try:
        res = sim.run()
        t = np.asarray(res.time)
        err = np.linalg.norm(res.get(res.judged("plant.pos")) - res.get("ref.pos_ref"), axis=1)
        yaw = res.get(res.judged("plant.euler"))[:, 2] - res.get("ref.euler_ref")[:, 2]
        mask = res.get("ctrl.rotors_detected").astype(np.int64)
        est = np.asarray(res.get("ctrl.rotor_eff_est"))[:, :base.airframe.n_rotors]
        complete = len(t) >= sc.n_steps
    except (RunError, FmuError):  # a diverged plant may make an FMU refuse a step
        t, err, yaw, complete = np.zeros(1), np.array([math.inf]), np.zeros(1), False
        mask, est = np.zeros(1, np.int64), np.ones((1, base.airframe.n_rotors))
    row.update(flight_metrics(t, err, yaw, complete))
    row.update(detection_metrics(t, mask, est, case))
    row["wall_time"] = time.perf_counter() - t0
    return row


def flight_metrics(t: np.ndarray, err: np.ndarray, yaw: np.ndarray,
                   complete: bool) -> dict[str, Any]:
    """stable, max_err, heading_err, held (module docstring) of one run: position error
    ``err`` and heading error ``yaw`` (rad, unwrapped) at times ``t``; ``complete``: the run
    reached its end."""
    after = t >= T_LOAD
    if not after.any():  # a run refused before the first step: judged on what there is
        after = np.ones(len(t), dtype=bool)
    e, wrapped = err[after], np.abs(np.angle(np.exp(1j * yaw[after])))
    mx = float(np.max(e)) if np.all(np.isfinite(e)) else math.inf
    head = float(np.max(wrapped)) if np.all(np.isfinite(wrapped)) else math.inf
    stable = complete and mx < DIVERGED_BOUND
    return {"stable": int(stable), "max_err": mx, "heading_err": head,
            "held": int(stable and head < HEADING_BOUND)}


def detection_metrics(t: np.ndarray, mask: np.ndarray, est: np.ndarray,
                      case: dict[str, float]) -> dict[str, Any]:
    """detected, detect_time, est, est_err, false_alarm, false_lost, missed, est_off (module
    docstring) of one run: ``mask`` the ``rotors_detected`` bitmask at times ``t``, ``est``
    the estimates (len(t), rotors)."""
    rotor = int(case["fault_rotor"])
    bit = 1 << (rotor - 1) if rotor else 0
    healthy = np.ones(est.shape[1], dtype=bool)
    if rotor:
        healthy[rotor - 1] = False
    final = int(mask[-1])
    before = mask[t < case["t_fault"]] if rotor else mask[:0]
    out: dict[str, Any] = {
        "detected": final,
        "false_alarm": int(bool(final & ~bit) or bool(np.any((before & bit) != 0))),
        "false_lost": int(bool(np.any(est[:, healthy] < LOST_BELOW))),
        "missed": 0, "detect_time": math.nan, "est": math.nan, "est_err": math.nan,
        "est_off": 0}
    if not rotor:
        return out
    seen = np.nonzero(((mask & bit) != 0) & (t >= case["t_fault"]))[0]
    if not seen.size:
        out["missed"] = int(1.0 - case["fault_eff"] >= LOSS_MIN)
        return out
    e = float(est[-1, rotor - 1])
    out.update(detect_time=float(t[seen[0]] - case["t_fault"]), est=e,
               est_err=abs(e - case["fault_eff"]))
    out["est_off"] = int(out["est_err"] > EST_TOL)
    return out


def summarize_faults(rows: Sequence[dict[str, Any]]) -> dict[str, float]:
    """Over the rows: cases of each kind, total losses, runs not stable and not held, false
    alarms (in load and in fault cases), healthy rotors declared lost, missed detections (all,
    and in the cases held), estimates off by more than :data:`EST_TOL`, estimate error mean
    and max, detection time median, p95 and max (over the detected faults; ``lost_time_*``:
    over the total losses detected)."""
    loads = [r for r in rows if r["kind"] == "load"]
    faults = [r for r in rows if r["kind"] == "fault"]
    found = [r for r in faults if not math.isnan(r["detect_time"])]
    err = np.array([r["est_err"] for r in found])
    dt = np.array([r["detect_time"] for r in found])
    lost = np.array([r["detect_time"] for r in found if r["fault_eff"] == 0.0])
    return {"cases": len(rows), "loads": len(loads), "faults": len(faults),
            "total_losses": sum(r["fault_eff"] == 0.0 for r in faults),
            "unstable": sum(not r["stable"] for r in rows),
            "not_held": sum(not r["held"] for r in rows),
            "false_alarms_load": sum(r["false_alarm"] for r in loads),
            "false_alarms_fault": sum(r["false_alarm"] for r in faults),
            "false_alarms": sum(r["false_alarm"] for r in rows),
            "false_alarms_held": sum(r["false_alarm"] for r in rows if r["held"]),
            "false_lost": sum(r["false_lost"] for r in rows),
            "missed": sum(r["missed"] for r in faults),
            "missed_held": sum(r["missed"] for r in faults if r["held"]),
            "missed_total": sum(r["missed"] for r in faults if r["fault_eff"] == 0.0),
            "detected": len(found), "est_off": sum(r["est_off"] for r in faults),
            "est_err_mean": _stat(err, np.mean), "est_err_max": _stat(err, np.max),
            "detect_time_median": _stat(dt, np.median),
            "detect_time_p95": _stat(dt, lambda a: np.percentile(a, 95)),
            "detect_time_max": _stat(dt, np.max),
            "lost_time_median": _stat(lost, np.median), "lost_time_max": _stat(lost, np.max)}


def _stat(a: np.ndarray, f: Callable[[np.ndarray], Any]) -> float:
    return float(f(a)) if a.size else math.nan
