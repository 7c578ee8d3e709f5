"""Benchmark: what the fault detector and the reference shaping reach (prints figures,
asserts nothing; the tests hold the requirements).

Tables, all flown through the FMUs on the paper hexacopter at 3 m unless said:

1. a lost rotor (rotor 1 at 3 s): detection delay and the peak error and time back within
   5 mm, the controller told at once, never told but detecting, or neither - in hover, in
   translation (x = 1.5 sin 0.8t) and at 20 deg roll;
2. a weakened rotor (rotor 4 at efficiency 0.3, 0.5, 0.7 from 3 s), ideal sensors and the
   sweep's sensor noise: detection delay and estimate;
3. unknown loads that look like a rotor's deficit (mass +15/30 %, a payload at an arm tip,
   forces with torques): rotors concluded (should be none);
4. steps of 1, 3, 5, 10 m in x: time to within 1 cm and its ratio to 2 sqrt(L / a_max),
   a_max the level acceleration of the airframe's feasible-force set at the hover force;
   peak tilt, sag, overshoot, largest error against the shaped reference; and a 3 rad
   heading step: time to within 1 deg.

Usage: python tests/bench/bench_faults_and_steps.py [--airframe NAME] [--quick]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from orchestrator.master import run
from orchestrator.scenario.parser import parse_scenario
from orchestrator.sweep import NOISE

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test_controller"))
from test_fault_detection import LOADS
from test_reference_shaping import level_acceleration

T_FAULT = 3.0


def fly(data: dict[str, Any], airframe: str) -> Any:
    base: dict[str, Any] = {"name": "bench", "duration": 7.0, "airframe": airframe,
                            "reference": {"position": {"x": 0.0, "y": 0.0, "z": -3.0}}}
    base.update(data)
    return run(parse_scenario(base), progress=False)


def first_detection(r: Any) -> float | None:
    k = np.flatnonzero(r.get("ctrl.rotors_detected"))
    return None if k.size == 0 else float(r.time[k[0]])


def within(t: np.ndarray, err: np.ndarray, band: float, t0: float) -> float | None:
    out = np.flatnonzero((err > band) & (t >= t0))
    if out.size == 0:
        return 0.0
    return None if out[-1] + 1 >= t.size else float(t[out[-1] + 1] - t0)


def fmt(x: float | None, spec: str = ".3f", unit: str = "") -> str:
    return "never" if x is None else f"{x:{spec}}{unit}"


def lost_rotor_table(airframe: str) -> None:
    print("== 1. rotor 1 lost at 3 s: detection delay; peak error, back within 5 mm after ==")
    kinds: dict[str, dict[str, Any]] = {
        "hover": {},
        "translation": {"position": {"x": {"type": "sine", "amplitude": 1.5, "omega": 0.8},
                                     "y": 0.0, "z": -3.0}},
        "20 deg roll": {"attitude": {"roll": math.radians(20.0), "pitch": 0.0, "yaw": 0.0}},
    }
    for name, ref in kinds.items():
        cells = []
        for mode in ("told", "detected", "neither"):
            data: dict[str, Any] = {
                "fault": [{"time": T_FAULT, "rotor": 1, "efficiency": 0.0}],
                "fault_detection": "immediate" if mode == "told" else "none",
                "controller": {"fault_detect": mode == "detected"},
                "reference": {"position": {"x": 0.0, "y": 0.0, "z": -3.0}, **ref}}
            r = fly(data, airframe)
            err = np.linalg.norm(r.get(r.judged("plant.pos")) - r.get("ref.pos_ref"), axis=1)
            t = r.time
            peak = err[t >= T_FAULT].max() * 1e3
            back = within(t, err, 0.005, T_FAULT)
            det = first_detection(r)
            delay = None if det is None else (det - T_FAULT) * 1e3
            lead = "" if mode != "detected" else f"{fmt(delay, '.0f', ' ms')}; "
            cells.append(f"{mode}: {lead}{peak:.1f} mm, {fmt(back, '.2f', ' s')}")
        print(f"  {name:12s} " + " | ".join(cells))


def weak_rotor_table(airframe: str) -> None:
    print("== 2. rotor 4 weakened at 3 s: detection delay, estimate ==")
    for sensors in (False, True):
        cells = []
        for eff in (0.3, 0.5, 0.7):
            data: dict[str, Any] = {"fault": [{"time": T_FAULT, "rotor": 4, "efficiency": eff}],
                                    "fault_detection": "none"}
            if sensors:
                data["plant"] = {**NOISE, "noise_seed": 11}
            r = fly(data, airframe)
            det = first_detection(r)
            est = r.get("ctrl.rotor_eff_est")[-1, 3]
            delay = None if det is None else (det - T_FAULT) * 1e3
            cells.append(f"{eff}: {fmt(delay, '.0f', ' ms')}, est {est:.3f}")
        print(f"  {'sensor noise' if sensors else 'ideal':12s} " + " | ".join(cells))


def loads_table(airframe: str) -> None:
    print("== 3. unknown loads (step at 2 s): rotors concluded, ideal / sensor noise ==")
    for name, (plant, dist) in LOADS.items():
        cells = []
        for sensors in (False, True):
            r = fly({"duration": 5.0, "disturbance": dist, "fault_detection": "none",
                     "plant": {**plant, **({**NOISE, "noise_seed": 11} if sensors else {})}},
                    airframe)
            cells.append(f"{int(r.get('ctrl.rotors_detected')[-1]):#x}")
        print(f"  {name:38s} " + " / ".join(cells))


def step_table(airframe: str, lengths: tuple[float, ...]) -> None:
    a_max = level_acceleration(airframe)
    print(f"== 4. steps in x (a_max = {a_max:.2f} m/s^2, level, from the force set) ==")
    for length in lengths:
        r = fly({"duration": float(math.ceil(4.0 + 4.0 * math.sqrt(length / max(a_max, 1.0)))),
                 "reference": {"position": {"x": {"type": "steps", "times": [1.0],
                                                  "values": [length]}, "y": 0.0, "z": -3.0}}},
                airframe)
        t, pos = r.time, r.get(r.judged("plant.pos"))
        eul = r.get(r.judged("plant.euler"))
        err = np.linalg.norm(pos - [length, 0.0, -3.0], axis=1)
        t1 = within(t, err, 0.01, 1.0)
        bound = 2.0 * math.sqrt(length / a_max) if a_max > 0 else math.inf
        tilt = np.degrees(np.arccos(np.clip(np.cos(eul[:, 0]) * np.cos(eul[:, 1]), -1, 1)))
        shaped = np.linalg.norm(pos - r.get("ctrl.pos_ref_s"), axis=1).max() * 1e3
        ratio = None if t1 is None else t1 / bound
        print(f"  {length:4.0f} m: 1 cm after {fmt(t1, '.3f', ' s')} ({fmt(ratio, '.2f', 'x')} "
              f"of {bound:.3f} s), tilt {tilt.max():.1f} deg, sag "
              f"{np.abs(pos[:, 2] + 3.0).max() * 1e3:.1f} mm, overshoot "
              f"{max((pos[:, 0] - length).max(), 0.0) * 1e3:.1f} mm, error vs shaped "
              f"{shaped:.1f} mm")
    r = fly({"duration": 6.0, "reference": {
        "position": {"x": 0.0, "y": 0.0, "z": -3.0},
        "attitude": {"roll": 0.0, "pitch": 0.0,
                     "yaw": {"type": "steps", "times": [1.0], "values": [3.0]}}}}, airframe)
    psi = r.get(r.judged("plant.euler"))[:, 2]
    err = np.degrees(np.abs(np.angle(np.exp(1j * (psi - 3.0)))))
    perr = np.linalg.norm(r.get(r.judged("plant.pos")) - [0.0, 0.0, -3.0], axis=1).max()
    print(f"  heading 3 rad: within 1 deg after {fmt(within(r.time, err, 1.0, 1.0), '.3f', ' s')}"
          f", position error {perr * 1e3:.1f} mm (limits: rate "
          f"{r.get('ctrl.ref_att_rate_limit')[-1, 2]:.2f} rad/s, acceleration "
          f"{r.get('ctrl.ref_att_acc_limit')[-1, 2]:.2f} rad/s^2)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--airframe", default="paper_hexacopter")
    ap.add_argument("--quick", action="store_true", help="the step table only")
    args = ap.parse_args()
    if not args.quick:
        lost_rotor_table(args.airframe)
        weak_rotor_table(args.airframe)
        loads_table(args.airframe)
    step_table(args.airframe, (1.0, 3.0, 5.0, 10.0))


if __name__ == "__main__":
    main()
