"""Ground contact of the plant FMU (fmu_src/plant/contact.h) against physics computed here:
statics for the load each foot carries, the free fall and a 1-DOF spring-damper integrated by
scipy for the drop, Coulomb's law for sliding, the moment about the feet's edge for tipping,
the mechanical energy for the whole motion.  The vehicle is the paper hexacopter with its
shipped landing gear (plant/airframes/paper_hexacopter.toml), rotors stopped unless said.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from orchestrator.sim.fmu import FmuError
from orchestrator.sim.start_values import Pose, plant_start_values
from plant import load_airframe
from plant.airframe import parse_airframe, resolve_airframe
from plant.common.toml_reader import read_toml

AF = load_airframe("paper_hexacopter")
GEAR = AF.gear
H = 0.002
G = AF.gravity
M = AF.mass
FOOT_Z = 0.1  # the feet's height below the centre of gravity
K, C, MU = GEAR.stiffness, GEAR.damping, GEAR.friction
A = float(abs(GEAR.points[0, 0]))  # half the feet's square side


def params(z: float = -FOOT_Z, euler=(0.0, 0.0, 0.0), vel=(0.0, 0.0, 0.0), **extra):
    """The plant at z (centre of gravity, NED), rotors stopped (no trim)."""
    p = plant_start_values(AF, Pose.of((0.0, 0.0, z), euler, vel),
                           overrides={"init_trim": False})
    for i in range(8):
        p[f"omega0[{i + 1}]"] = 0.0
    p.update(extra)
    return p


def stopped(inst):
    for i in range(AF.n_rotors):
        inst.set(f"omega_cmd[{i + 1}]", 0.0)


OUT = ["pos", "vel", "euler", "rate", "contact_force"]


def fly(make_plant, run_steps, seconds, before=None, **kw):
    inst = make_plant(params(**kw))
    stopped(inst)
    step = None if before is None else (lambda k: before(inst, k))
    return inst, run_steps(inst, round(seconds / H), OUT, before_step=step)


def test_the_weight_is_shared_among_the_feet_as_statics_says(make_plant, run_steps):
    """Resting level on four symmetric feet: each carries m g / 4 and sinks m g / (4 k)."""
    inst, rec = fly(make_plant, run_steps, 1.0)
    forces = rec["contact_force"][-1, :4]
    assert forces == pytest.approx([M * G / 4] * 4, rel=1e-9)
    assert rec["contact_force"][-1, 4:].tolist() == [0.0] * 4
    assert rec["pos"][-1, 2] == pytest.approx(-FOOT_Z + M * G / (4 * K), abs=1e-9)
    assert inst.get("landed") is True and inst.get("contact_flags") == 0b1111


def rotation(euler) -> np.ndarray:
    """R_B^W = Rz(psi) Ry(theta) Rx(phi)."""
    (cf, sf), (ct, st), (cp, sp) = ((math.cos(a), math.sin(a)) for a in euler)
    return np.array([[ct * cp, sf * st * cp - cf * sp, cf * st * cp + sf * sp],
                     [ct * sp, sf * st * sp + cf * cp, cf * st * sp - sf * cp],
                     [-st, sf * ct, cf * ct]])


def test_three_feet_off_centre_carry_what_the_moments_say(make_plant, run_steps):
    """Three feet around a centre of gravity off their centroid: the loads solve the force
    and the two moment balances about the centre of gravity (statically determinate), with
    the lever arms of the pose the vehicle settles in; numpy's solve is the oracle."""
    feet = np.array([[0.12, 0.02, 0.1], [-0.05, 0.10, 0.1], [-0.06, -0.09, 0.1]])
    extra: dict[str, float | int] = {"n_contacts": 3}
    for i in range(8):
        for j in range(3):
            extra[f"contact_pos[{i + 1},{j + 1}]"] = float(feet[i, j]) if i < 3 else 0.0
    _, rec = fly(make_plant, run_steps, 1.5, **extra)
    arms = feet @ rotation(rec["euler"][-1]).T  # world lever arms at rest
    # sum F = m g; moments of the vertical loads about the centre of gravity vanish
    expected = np.linalg.solve(np.vstack([np.ones(3), arms[:, 1], arms[:, 0]]),
                               [M * G, 0.0, 0.0])
    assert rec["contact_force"][-1, :3] == pytest.approx(expected, rel=1e-3)
    assert rec["contact_force"][-1, :3].sum() == pytest.approx(M * G, rel=1e-9)


def drop_oracle(height: float, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """The level drop as one mass on four parallel spring-dampers that never pull, integrated
    by scipy: (times, centre-of-gravity z)."""
    ground = -FOOT_Z

    def f(_t, y):
        z, v = y
        d = z - ground
        fn = max(0.0, 4 * (K * d + C * v)) if d > 0 else 0.0
        return [v, G - fn / M]

    t = np.arange(round(seconds / H) + 1) * H
    sol = solve_ivp(f, (0, seconds), [ground - height, 0.0], t_eval=t, rtol=1e-10,
                    atol=1e-12, max_step=1e-4)
    return t, sol.y[0]


def test_a_drop_of_half_a_metre_touches_down_at_free_fall_speed_and_settles(make_plant,
                                                                             run_steps):
    _, rec = fly(make_plant, run_steps, 1.5, z=-FOOT_Z - 0.5)
    z, vz, fn = rec["pos"][:, 2], rec["vel"][:, 2], rec["contact_force"][:, :4].sum(axis=1)
    first = int(np.argmax(fn > 0))
    # free fall until then: v = g t, z = z0 + g t^2 / 2 (RK4 is exact on it)
    t = rec["t"][:first]
    assert vz[:first] == pytest.approx(G * t, abs=1e-9)
    touchdown = math.sqrt(2 * G * 0.5)
    print(f"\ntouchdown speed {touchdown:.4f} m/s (free fall from 0.5 m)")
    # the whole drop against scipy's integration of the same contact law
    _, z_ref = drop_oracle(0.5, 1.5)
    # (RK4 steps across the touchdown's kink: 0.3 mm of a 17 mm penetration)
    print(f"largest difference to scipy's integration {np.abs(z - z_ref).max() * 1e3:.2f} mm")
    assert np.abs(z - z_ref).max() < 1e-3
    # critically damped heave: the feet never leave the ground again, no bounce
    assert np.all(z[first:] > -FOOT_Z)
    peak = z[first:].max() - (-FOOT_Z)
    settle = rec["t"][first + np.argmax(np.abs(z[first:] - z[-1]) < 1e-4)] - rec["t"][first]
    print(f"peak penetration {peak * 1e3:.1f} mm, within 0.1 mm of rest {settle:.3f} s after "
          "touchdown")
    assert settle < 0.25  # critically damped at omega = sqrt(4 k / m) = 70 rad/s
    assert z[-1] == pytest.approx(-FOOT_Z + M * G / (4 * K), abs=1e-7)


def test_energy_never_grows_in_a_tilted_spinning_drop(make_plant, run_steps):
    """A drop at 15 deg of roll, yawing at 2 rad/s and drifting sideways at 1 m/s: contact,
    friction and tipping only dissipate, so the mechanical energy (kinetic, gravity and the
    feet's normal springs, from the pose) never rises by more than the friction springs can
    hold, (mu F_n)^2 / 2k per foot."""
    _, rec = fly(make_plant, run_steps, 2.0, z=-FOOT_Z - 0.3,
                 euler=(math.radians(15), 0.0, 0.0), vel=(1.0, 0.0, 0.0), **{"rate0[3]": 2.0})
    total = []
    for v, w, p, e in zip(rec["vel"], rec["rate"], rec["pos"], rec["euler"], strict=True):
        depth = np.clip(p[2] + (GEAR.points @ rotation(e).T)[:, 2], 0.0, None)
        total.append(0.5 * M * v @ v + 0.5 * w @ AF.inertia @ w - M * G * p[2]
                     + 0.5 * K * np.sum(depth ** 2))
    total = np.array(total)
    held = 4 * (MU * rec["contact_force"].max()) ** 2 / (2 * K)
    assert (rec["contact_force"].sum(axis=1) > 0).any()
    assert np.diff(total).max() < held
    assert total[-1] < total[0] - 0.9 * M * G * 0.3  # the drop's energy is gone
    assert np.all(np.isfinite(rec["pos"])) and np.all(np.isfinite(rec["contact_force"]))
    # it comes to rest on its feet
    assert np.abs(rec["vel"][-1]).max() < 1e-3 and abs(rec["euler"][-1, 0]) < 0.05


@pytest.mark.parametrize("share", [0.8, 1.5])
def test_a_push_slides_the_vehicle_only_beyond_coulombs_limit(make_plant, run_steps, share):
    """A horizontal force F at rest: below mu m g it stays (no creep), above it the vehicle
    slides with the acceleration (F - mu m g) / m."""
    force = share * MU * M * G

    def push(inst, k):
        if k == 100:
            inst.set("f_d[1]", force)

    _, rec = fly(make_plant, run_steps, 1.2, before=push)
    x, vx = rec["pos"][:, 0], rec["vel"][:, 0]
    if share < 1:
        # held by static friction: it yields elastically (the feet's springs and the tilt they
        # allow, a few millimetres) and stops there, no creep
        assert np.abs(x).max() < 5e-3
        assert abs(x[-1] - x[-101]) < 1e-6 and abs(vx[-1]) < 1e-6
    else:
        late = slice(300, None)  # sliding steadily
        slope = np.polyfit(rec["t"][late], vx[late], 1)[0]
        assert slope == pytest.approx((force - MU * M * G) / M, rel=0.01)
        assert abs(rec["euler"][-1, 1]) < math.radians(2)  # slides, does not tip


@pytest.mark.parametrize("share", [0.8, 1.3])
def test_a_roll_torque_tips_the_vehicle_only_beyond_the_weights_moment(make_plant, run_steps,
                                                                       share):
    """A roll torque at rest against the weight's moment about the feet's edge, m g a."""
    torque = share * M * G * A

    def twist(inst, k):
        if k == 100:
            inst.set("tau_d[1]", torque)

    _, rec = fly(make_plant, run_steps, 1.5, before=twist)
    roll = rec["euler"][:, 0]
    if share < 1:
        # it leans on its springs, as linear statics says: tau / (sum_i y_i^2 k), and holds
        lean = torque / (np.sum(GEAR.points[:, 1] ** 2) * K)
        assert roll[-1] == pytest.approx(lean, rel=0.1)
        assert abs(roll[-1] - roll[-101]) < 1e-6
    else:
        assert np.abs(roll).max() > math.radians(30)


@pytest.mark.parametrize(("extra", "message"), [
    ({"contact_stiffness": 1e7}, "too fast for RK4 at h_internal"),
    ({"contact_stiffness": -1.0}, "contact_stiffness"),
    ({"n_contacts": 9}, "n_contacts"),
    ({"contact_pos[2,3]": float("nan")}, "contact_pos[2,3]"),
])
def test_bad_contact_parameters_are_refused_by_name(make_plant, extra, message):
    with pytest.raises(FmuError) as err:
        make_plant(params(**extra))
    assert message in str(err.value)


def test_hard_crashes_stay_finite(make_plant, run_steps):
    """Thrown at the ground at up to 15 m/s, upside down, spinning at up to 20 rad/s: large
    forces, never NaN."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        euler = rng.uniform(-math.pi, math.pi, 3) * [1, 0.49, 1]
        vel = (*rng.uniform(-5, 5, 2), rng.uniform(5, 15))
        inst = make_plant(params(z=-0.35, euler=tuple(euler), vel=vel,
                                 **{f"rate0[{i}]": float(rng.uniform(-20, 20))
                                    for i in (1, 2, 3)}))
        stopped(inst)
        rec = run_steps(inst, 250, OUT)
        for name in OUT:
            assert np.all(np.isfinite(rec[name])), name
        assert rec["contact_force"].max() > 0


def test_a_start_inside_the_ground_is_refused_with_where_to_start(make_plant):
    """At the origin the feet would start 10 cm under the ground (the ground would throw the
    vehicle up): refused, saying how high to start."""
    with pytest.raises(FmuError) as err:
        make_plant(params(z=0.0))
    assert "contact point 1 of the landing gear starts 0.1 m below the ground" in str(err.value)
    assert "pos0[3] <= -0.1 m" in str(err.value)
    make_plant(params(z=0.0, ground_z=0.5))  # a ground lower down: fine


def test_the_airframe_file_gives_the_gear_or_says_what_is_wrong(tmp_path):
    doc = read_toml(resolve_airframe("paper_hexacopter"), ValueError)
    assert AF.plant_parameters()["n_contacts"] == 4
    for gear, field in (({"points": [[0.1, 0.1]]}, "points"),
                        ({"points": [[0.1, 0.1, -0.1]]}, "points"),
                        ({"points": [[0.1, 0.1, 0.1]], "stiffness": 0.0}, "stiffness"),
                        ({"points": [[0.1, 0.1, 0.1]], "spring": 1}, "spring")):
        gear = {"stiffness": 800.0, "damping": 20.0, **gear}
        with pytest.raises(Exception, match=f"landing_gear.{field}"):
            parse_airframe({**doc, "landing_gear": gear}, "x.toml")
    without = {k: v for k, v in doc.items() if k != "landing_gear"}
    assert parse_airframe(without, "x.toml").plant_parameters() == {"n_contacts": 0}


# -- a closed-loop run that starts on the ground (scenario field start = "ground") ----------


def test_a_run_starting_on_the_ground_rests_then_lifts_off_on_the_x8():
    """``start = "ground"``: the X8 rests level on its gear at the first row, its weight on
    the feet as statics says, rotors stopped; the controller then lifts it to the reference
    1 m up and holds it there (the paper's 2 cm)."""
    from orchestrator.master import run
    from orchestrator.scenario.parser import parse_scenario

    sc = parse_scenario({"name": "from_ground", "duration": 5.0, "airframe": "x8_coaxial",
                         "start": "ground", "reference": {"position": {"z": -1.0}}})
    r = run(sc, progress=False)
    x8 = load_airframe("x8_coaxial")
    forces = r.get("plant.contact_force")
    assert forces.shape[1] == 4  # the gear's four feet only
    assert forces[0] == pytest.approx([x8.mass * x8.gravity / 4] * 4, rel=1e-9)
    assert np.abs(r.get("plant.omega")[0]).max() == 0.0
    assert r.get("plant.pos")[0, 2] == pytest.approx(-x8.gear.rest_height(x8.mass, x8.gravity))
    airborne = np.flatnonzero(r.get("plant.contact_flags") == 0)
    assert airborne.size and airborne[0] * 0.002 < 0.5  # lifted off within half a second
    tail = r.get("plant.pos")[r.time >= 3.0]
    assert np.abs(tail - [0.0, 0.0, -1.0]).max() < 0.02
    assert r.meta["outcome"] == {"outcome": "completed"}


def test_start_on_the_ground_needs_a_gear(tmp_path):
    from orchestrator.scenario.parser import parse_scenario, with_overrides
    from orchestrator.scenario.reader import ScenarioError

    frame = tmp_path / "bare.toml"
    doc = read_toml(resolve_airframe("quadrotor"), ValueError)
    text = resolve_airframe("quadrotor").read_text()
    frame.write_text(text[:text.index("[landing_gear]")])
    assert "landing_gear" in doc
    with pytest.raises(ScenarioError, match="'ground' needs a landing gear"):
        parse_scenario({"name": "g", "duration": 1.0, "airframe": str(frame),
                        "start": "ground"})
    sc = parse_scenario({"name": "g", "duration": 1.0, "airframe": "quadrotor",
                         "start": "ground"})
    with pytest.raises(ScenarioError, match="'ground' needs a landing gear"):
        with_overrides(sc, airframe=frame)
