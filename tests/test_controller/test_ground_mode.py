"""The controller on the ground (fmu_src/controller/ground.c): the land detector, the rotors
idling when disarmed or landed with the reference not above, a takeoff shaped from where the
vehicle stands, a landing that ends with the rotors stopped, and no windup while waiting.
Closed-loop runs of the plant with its landing gear (tests/test_plant/test_ground_contact.py
checks the contact itself); oracles: physics (rest on the gear, first-order spin-down), the
paper's 2 cm, the controller's own declared climb limit, and time-shift invariance."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from orchestrator.master import run
from orchestrator.scenario.parser import parse_scenario
from plant import load_airframe

ACCURACY = 0.02  # the paper's position accuracy


def ground_run(z, seconds, airframe="paper_hexacopter", **extra):
    sc = parse_scenario({"name": "ground", "duration": seconds, "airframe": airframe,
                         "start": "ground", "reference": {"position": {"z": z}}, **extra})
    return sc, run(sc, progress=False)


def rest_z(airframe: str) -> float:
    af = load_airframe(airframe)
    return -af.gear.rest_height(af.mass, af.gravity)


@pytest.mark.parametrize("airframe", ["paper_hexacopter", "x8_coaxial"])
def test_a_takeoff_is_shaped_from_the_ground(airframe):
    """Landed at the start, the controller lifts off towards a hover 1 m up along its shaped
    reference: no thrust spike (the rotors' thrust, k_t sum omega^2, within 25 % of what the
    shaping's declared vertical acceleration limit needs, m (g + a_max)), the climb within
    its declared speed limit, then the hover within 2 cm without overshoot."""
    sc, r = ground_run(-1.0, 6.0, airframe)
    assert r.get("ctrl.landed")[0] == 1 and r.get("ctrl.idle")[0] == 0
    t, z, vz = r.time, r.get("plant.pos")[:, 2], r.get("plant.vel")[:, 2]
    af = sc.airframe
    thrust = af.k_t * np.sum(r.get("plant.omega") ** 2, axis=1)
    a_max = r.get("ctrl.ref_acc_limit")[0, 1]
    print(f"\n{airframe}: peak thrust {thrust.max() / (af.mass * af.gravity):.2f} x the weight "
          f"(acceleration limit {a_max:.2f} m/s^2)")
    assert thrust.max() <= 1.25 * af.mass * (af.gravity + a_max)  # (+ the motors' lag lead)
    limit = r.get("ctrl.ref_vel_limit")[0, 1]
    assert -vz.min() <= limit * 1.05
    assert np.all(z > -1.0 - ACCURACY)
    assert np.abs(r.get("plant.pos")[t >= 4] - [0.0, 0.0, -1.0]).max() < ACCURACY
    assert not r.get("ctrl.landed")[t > 1].any()


def test_a_landing_ends_with_the_rotors_stopped():
    """Hovering 1 m up, the reference descends through the ground: the vehicle touches down,
    the detector says landed within its 0.1 s (plus the settling of the gear), the rotors are
    commanded to omega_min (0 here) and spin down as their first-order lag says; it rests on
    its gear."""
    sc, r = ground_run({"type": "waypoints", "times": [2.0, 5.0], "values": [-1.0, 0.3]},
                       9.0)
    t, flags = r.time, r.get("plant.contact_flags")
    touchdown = t[np.flatnonzero((t > 2) & (flags > 0))[0]]
    landed = t[np.flatnonzero(r.get("ctrl.landed") > 0)[np.flatnonzero(
        r.get("ctrl.landed") > 0) > int(2 / 0.002)][0]]
    idle = r.get("ctrl.idle")
    speed = r.get("plant.vel")[np.flatnonzero(t == touchdown)[0] - 1, 2]
    print(f"\ntouchdown at {touchdown:.3f} s at {speed:.2f} m/s, landed {landed - touchdown:.3f} s "
          "later")
    assert 0.0 < landed - touchdown < 0.3
    k = round(landed / 0.002)
    assert idle[k] == 1 and np.all(r.get("ctrl.omega_cmd")[k:] == 0.0)
    af = sc.airframe
    omega = r.get("plant.omega")[:, :af.n_rotors]
    decay = omega[k + 250] / np.where(omega[k] > 0, omega[k], 1)
    assert decay == pytest.approx(np.exp(-0.5 / af.tau_motor), rel=1e-3)
    assert r.get("plant.pos")[-1, 2] == pytest.approx(rest_z("paper_hexacopter"), abs=1e-6)


def test_disarmed_nothing_spins_and_nothing_lifts():
    sc, _ = ground_run(-1.0, 0.1)
    sc = replace(sc, duration=2.0,
                 controller_parameters={**sc.controller_parameters, "armed": False})
    r = run(sc, progress=False)
    assert np.all(r.get("ctrl.idle") == 1)
    assert np.all(r.get("ctrl.omega_cmd") == 0.0) and np.all(r.get("plant.omega") == 0.0)
    assert np.all(r.get("plant.contact_flags") == 0b1111)
    assert r.get("plant.pos")[-1, 2] == pytest.approx(rest_z("paper_hexacopter"), abs=1e-9)


def test_waiting_on_the_ground_winds_nothing_up():
    """Landed, armed, the reference on the ground for 3 s (rotors idle), then 1 m up: the
    flight from then on is the flight of a vehicle that took off at once, shifted by 3 s (the
    controller restarts from the measurements every idle sample, so nothing accumulates while
    it waits; what differs is the QPs' warm start, within their tolerance: 0.1 mm, where 3 s
    of a wound-up thrust integrator would show as centimetres)."""
    ground = rest_z("paper_hexacopter")
    _, late = ground_run({"type": "steps", "initial": ground, "times": [3.0],
                          "values": [-1.0]}, 6.0)
    _, now = ground_run(-1.0, 3.0)
    shift = round(3.0 / 0.002)
    assert np.all(late.get("ctrl.idle")[:shift] == 1)
    diff = np.abs(late.get("plant.pos")[shift:] - now.get("plant.pos")).max()
    print(f"\nwaiting 3 s on the ground, then taking off: {diff:.2g} m from an instant takeoff")
    assert diff < 1e-4


def test_the_shipped_takeoff_and_landing():
    """takeoff_and_land: its timeline in order (the ground let go, liftoff, touchdown, landed
    and rotors idle together), the tilted leg flown within the paper's 2 cm at 15 deg of
    roll, and at the end the vehicle at rest on its gear with the rotors stopped."""
    from orchestrator.output.events import events
    from orchestrator.scenario.catalogue import load_scenario

    r = run(load_scenario("takeoff_and_land"), progress=False)
    assert r.meta["outcome"] == {"outcome": "completed"}
    timeline = [(e.time, e.text) for e in events(r, ("ground",))]
    texts = [text for _, text in timeline]
    assert texts == ["leaving the ground", "liftoff", "touchdown", "landed", "rotors idle"]
    times = dict((text, time) for time, text in timeline)
    assert times["leaving the ground"] < times["liftoff"] < 0.5
    assert times["landed"] == times["rotors idle"]
    assert 0.0 < times["landed"] - times["touchdown"] < 0.3
    t = r.time
    leg = (t > 4.0) & (t < 9.0)
    assert np.abs(r.get("plant.pos")[leg] - r.get("ctrl.pos_ref_s")[leg]).max() < ACCURACY
    assert np.degrees(r.get("plant.euler")[(t > 5.0) & (t < 7.0), 0]) == pytest.approx(
        15.0, abs=0.5)
    assert r.get("plant.pos")[-1, 2] == pytest.approx(rest_z("paper_hexacopter"), abs=1e-6)
    assert np.all(r.get("ctrl.omega_cmd")[-1] == 0.0)
