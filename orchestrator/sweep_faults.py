"""The rotor-fault campaign (``fullpose sweep --faults``, :func:`run_fault_sweep`), flown on the
disturbance campaign's workers (:mod:`orchestrator.sweep`): can the controller's fault
detector (``fmu_src/controller/detect.c``) tell a lost or weakened rotor from an unknown load?

Every case flies the campaign's scenario (default the hover) with the controller never told
of a fault (``fault_detection`` none: only its detector can find one), its nominal airframe and
the design's gains, and sensor noise as the disturbance campaign has it (each channel's
standard deviation = U(0, 1) x the levels in :data:`~orchestrator.sweep.NOISE`, seeded per
case).  Cases alternate: even cases are **loads**, odd cases **faults** (half and half).

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
  :data:`~orchestrator.sweep.DIVERGED_BOUND` after the first step; its largest value there.
  ``heading_err``: the largest heading error (truth, wrapped) after the first step; ``held``
  (1/0): stable and ``heading_err`` < :data:`HEADING_BOUND`.  A load the vehicle cannot
  hold (a yaw torque beyond what the rotors' drag gives a vehicle with vertical rotors spins
  it) leaves the detector's premises - the residual of a vehicle whose allocation saturates -
  and is counted among the cases, and reported apart too.

:func:`summarize_faults` counts these over the cases; estimate errors are over the detected
faults, detection times over the detected faults (and over the total losses alone).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from orchestrator.sweep import (
    DIVERGED_BOUND,
    MATCHED,
    NOISE,
    T_ON,
    Campaign,
    Worker,
    run_campaign,
)

if TYPE_CHECKING:
    from orchestrator.scenario.model import Scenario, Vec3
    from plant import Airframe

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


def run_fault_sweep(n: int, seed: int = 0, duration: float = 6.0, workers: int = 1,
                    dask: str | Any | None = None, progress: bool | None = None,
                    design_set: Sequence[str] = ("hinf", "baseline"), noise: float = 1.0,
                    reuse: bool = True, scenario: str | Path = "hover",
                    airframe: str | Path | None = None) -> list[dict[str, Any]]:
    """All (case, design) runs of the fault campaign (module docstring) on ``scenario``
    (default the hover; on ``airframe`` when given), sorted by (case, design), flown as
    :func:`~orchestrator.sweep.run_sweep` flies its cases: identical for any worker count and
    with or without ``reuse``; the designs, scenario and airframe validated first, then the
    duration (at least :data:`FAULT_MIN_DURATION`)."""
    campaign = Campaign(str(scenario), None if airframe is None else str(airframe),
                        float(duration))

    def draw(base: Scenario) -> list[dict[str, float]]:
        """The cases, on the rotors of the campaign's airframe."""
        if campaign.duration < FAULT_MIN_DURATION:
            raise ValueError(f"the fault campaign needs a duration of at least "
                             f"{FAULT_MIN_DURATION:g} s, "
                             f"got {campaign.duration:g}")
        return sample_fault_cases(n, seed, noise, base.airframe.n_rotors)

    return run_campaign(run_fault_case, draw, campaign, design_set, workers, dask, progress,
                        reuse)


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
