"""Rotor-fault detection from the INDI residual (the controller's detect.c), flown closed loop
through the FMUs with the controller never told of the fault (``fault_detection = "none"``).

Oracles and bounds from requirements, not from today's output:

* the truth of the fault is the plant's: the efficiency the scenario gives the faulty rotor.
  The detector must name that rotor and decide as being told would: lost below half an
  efficiency, else flown with an estimate within 0.05 of it (the fit is least squares on one
  rotor's own wrench);
* a lost rotor detected is a rotor reconfigured: the controller then flies the same
  single-failure force set it flies when told (``active_polytope``), and the vehicle is back
  within 5 mm of its reference, as when told;
* detection is worth having: the peak deviation with detection lies below the flight that
  is never told and never detects (no reconfiguration);
* no false alarm: every shipped scenario without a fault, with the sweep's sensor noise and
  120 Hz motion capture 5 ms late, and disturbances that are not rotor faults (a 7 N downward
  force, a 0.2 N m body torque) detect nothing.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from orchestrator.output.run_result import RunResult
from orchestrator.runner import prepare, run_scenario
from orchestrator.scenario.catalogue import scenario_names
from orchestrator.scenario.parser import parse_scenario
from orchestrator.sweep import NOISE

T_FAULT = 3.0
BAND = 0.005  # m: back within 5 mm
SENSORS = {**NOISE, "noise_seed": 11, "mocap_period": 1.0 / 120.0, "mocap_delay": 0.005}


def fly(data: dict[str, Any]) -> RunResult:
    base: dict[str, Any] = {"name": "fault", "duration": 7.0, "airframe": "paper_hexacopter",
                            "reference": {"position": {"x": 0.0, "y": 0.0, "z": -3.0}}}
    base.update(data)
    out = run_scenario(parse_scenario(base), None, timing=False, plots=False)
    assert out.metrics["outcome"] == "completed"
    return out.result


def faulty(kind: str, efficiency: float = 0.0, rotor: int = 1, detection: str = "none",
           detect: bool = True, sensors: bool = False) -> RunResult:
    data: dict[str, Any] = {"fault_detection": detection,
                            "fault": [{"time": T_FAULT, "rotor": rotor,
                                       "efficiency": efficiency}],
                            "controller": {"fault_detect": detect},
                            "reference": {"position": {"x": 0.0, "y": 0.0, "z": -3.0}}}
    if kind == "translation":  # 1.2 m/s through the fault
        data["reference"]["position"]["x"] = {"type": "sine", "amplitude": 1.5, "omega": 0.8}
    elif kind == "tilt20":
        data["reference"]["attitude"] = {"roll": math.radians(20.0), "pitch": 0.0, "yaw": 0.0}
    if sensors:
        data["plant"] = dict(SENSORS)
    return fly(data)


def position_error(r: RunResult) -> np.ndarray:
    return np.linalg.norm(r.get(r.judged("plant.pos")) - r.get("ref.pos_ref"), axis=1)


def detected_at(r: RunResult) -> float | None:
    k = np.nonzero(r.get("ctrl.rotors_detected"))[0]
    return float(r.time[k[0]]) if k.size else None


@pytest.mark.parametrize("kind", ["hover", "translation", "tilt20"])
def test_a_lost_rotor_is_detected_and_reconfigured(kind):
    told = faulty(kind, detection="immediate", detect=False)
    found = faulty(kind)
    never = faulty(kind, detect=False)
    t = found.time
    at = detected_at(found)
    assert at is not None and T_FAULT < at < T_FAULT + 0.1, at
    assert int(found.get("ctrl.rotors_detected")[-1]) == 0b1  # rotor 1 and no other
    est = found.get("ctrl.rotor_eff_est")[-1]
    assert est[0] == pytest.approx(0.0, abs=0.05)
    np.testing.assert_array_equal(est[1:], 1.0)
    # reconfigured as when told: rotor 1's single-failure force set, from the next sample
    k = int(np.searchsorted(t, at)) + 2
    assert np.all(found.get("ctrl.active_polytope")[k:] == 1)
    assert np.all(told.get("ctrl.active_polytope")[t >= T_FAULT + 0.01] == 1)
    e_found, e_never = position_error(found), position_error(never)
    after = t >= T_FAULT
    assert e_found[after].max() < e_never[after].max()
    assert e_found[t >= t[-1] - 1.0].max() < BAND  # recovered, as when told
    assert position_error(told)[t >= t[-1] - 1.0].max() < BAND


@pytest.mark.parametrize("efficiency", [0.3, 0.6])
def test_a_degraded_rotor_is_estimated(efficiency):
    r = faulty("hover", efficiency=efficiency, rotor=4, sensors=True)
    at = detected_at(r)
    assert at is not None and T_FAULT < at < T_FAULT + 0.1, at
    assert int(r.get("ctrl.rotors_detected")[-1]) == 1 << 3
    est = r.get("ctrl.rotor_eff_est")[-1]
    # below half the rotor is lost when told (the single-failure set), and so when detected;
    # above, it is flown with its efficiency: the estimate must be that efficiency
    lost = efficiency < 0.5
    assert (est[3] < 0.5) == lost
    if not lost:
        assert est[3] == pytest.approx(efficiency, abs=0.05)
    assert int(r.get("ctrl.rotors_lost")[-1]) == int(lost)
    assert position_error(r)[r.time >= r.time[-1] - 1.0].max() < BAND


def test_a_small_loss_is_left_to_indi():
    """A quarter of one rotor's thrust lost is below fault_loss_min (0.3): not a detection;
    INDI's increments absorb it."""
    r = faulty("hover", efficiency=0.75)
    assert detected_at(r) is None
    assert position_error(r)[r.time >= r.time[-1] - 1.0].max() < BAND


def test_detection_off_leaves_the_rotor_as_told():
    r = run_scenario(prepare("rotor_failure_no_reconfiguration"), None, timing=False,
                     plots=False).result
    assert detected_at(r) is None
    assert np.all(r.get("ctrl.rotor_eff_est") == 1.0)
    assert np.all(r.get("ctrl.active_polytope") == 0)


@pytest.mark.parametrize("name", [n for n in scenario_names() if "failure" not in n])
def test_no_false_alarm_over_the_shipped_scenarios(name):
    """With sensor noise and motion capture on: the residual carries noise, disturbances
    (scenario 3's steps up to 3 m/s^2) and model mismatch (the inertia corners), none of
    which is a rotor's signature."""
    settings = [f"plant.{k}={v}" for k, v in SENSORS.items()]
    out = run_scenario(prepare(name, settings=settings), None, timing=False, plots=False)
    assert out.metrics["outcome"] == "completed"
    r = out.result
    assert detected_at(r) is None, name
    assert np.all(r.get("ctrl.rotor_eff_est") == 1.0)


@pytest.mark.parametrize("disturbance", [{"force": {"z": {"type": "steps", "times": [2.0],
                                                           "values": [7.0]}}},
                                         {"torque": {"x": {"type": "steps", "times": [2.0],
                                                           "values": [0.2]}}}])
def test_a_disturbance_is_no_rotor_fault(disturbance):
    """A 7 N downward force (about one rotor's share of the weight) has no rotor's torque; a
    0.2 N m torque has no rotor's force."""
    r = fly({"disturbance": disturbance, "plant": dict(SENSORS)})
    assert np.abs(r.get("ctrl.indi_residual")).max() > 0.1  # the residual does see it
    assert detected_at(r) is None
