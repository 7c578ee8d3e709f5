"""The mission executor and scenario missions against analytic oracles.

* a segment's trapezoidal profile: its duration L/v + v/a (a triangle 2 sqrt(L/a) when the
  line is short), the velocity the derivative of the position and the acceleration that of
  the velocity (numerically), never beyond the limits;
* a plan flown by a perfect vehicle: legs reached in order at the times the profiles say;
* landing at the landing speed, stopped below the ground; a return over the altitude and
  to the nearest of home and the rally points;
* the fence's point-in-polygon against the winding number computed independently;
* the shipped mission scenario: every leg reached and its tracking within the paper's 2 cm.
"""

import math

import numpy as np
import pytest

from orchestrator.mission import items as mi
from orchestrator.mission.executor import LAND_DEPTH, Executor, Settings, Vehicle, _Segment
from orchestrator.mission.fence import Fence
from orchestrator.mission.items import MissionItem
from orchestrator.scenario.parser import parse_scenario
from orchestrator.scenario.reader import ScenarioError

ACCURACY = 0.02  # the paper's position accuracy (m)
nan = math.nan


@pytest.mark.parametrize("length, speed, acc", [(2.0, 1.0, 2.0), (0.1, 1.0, 2.0),
                                                (5.0, 0.5, 0.25)])
def test_segment_profile_is_the_trapezoid(length, speed, acc):
    a, b = np.array([1.0, -2.0, -1.0]), np.array([1.0, -2.0, -1.0]) + length * np.array(
        [0.6, 0.0, -0.8])
    seg = _Segment(a, b, 3.0, speed, acc)
    expected = (length / speed + speed / acc if length >= speed ** 2 / acc
                else 2.0 * math.sqrt(length / acc))
    assert seg.duration == pytest.approx(expected, rel=1e-12)
    t = np.linspace(3.0, 3.0 + seg.duration, 2001)
    p, v, w = (np.array(x) for x in zip(*(seg.at(ti) for ti in t), strict=True))
    h = t[1] - t[0]
    assert np.abs(np.gradient(p, h, axis=0)[1:-1] - v[1:-1]).max() < 2 * acc * h
    # the acceleration the derivative of the velocity, away from its jumps (the corners)
    smooth = np.all(w[:-2] == w[2:], axis=1)
    dv = np.gradient(v, h, axis=0)[1:-1]
    assert np.abs(dv[smooth] - w[1:-1][smooth]).max() < 1e-6 * acc
    assert np.linalg.norm(v, axis=1).max() <= speed + 1e-12
    assert np.linalg.norm(w, axis=1).max() <= acc + 1e-12
    np.testing.assert_allclose(seg.at(t[-1])[0], b, atol=1e-12)
    np.testing.assert_allclose(seg.at(t[0])[0], a, atol=1e-12)


def perfect_flight(plan, settings, start, until=200.0, ground_z=None, dt=0.01):
    """Fly a plan with a vehicle that is where its reference is (landed on the ground)."""
    ex = Executor(plan, settings, np.array(start, float), np.zeros(3), home=np.array(start))
    t, track = 0.0, []
    landed = ground_z is not None and start[2] >= ground_z - 1e-9
    pos, euler = np.array(start, float), np.zeros(3)
    while not ex.finished and t < until:
        r = ex.update(t, Vehicle(pos, euler, landed))
        euler = r["euler_ref"]
        pos = r["pos_ref"].copy()
        if ground_z is not None:
            landed = pos[2] >= ground_z - 1e-9
            pos[2] = min(pos[2], ground_z)
        track.append((t, pos.copy(), r["vel_ref"].copy(), r["euler_ref"].copy()))
        t += dt
    return ex, track


def test_a_plan_flown_in_order_at_the_profiles_times():
    s = Settings(cruise=1.0, climb=0.5, acc_hor=2.0, acc_ver=1.0)
    plan = [MissionItem.local(0, mi.NAV_TAKEOFF, (0.0, 0.0, -2.0)),
            MissionItem.local(1, mi.FULLPOSE_ATTITUDE, None, (10.0, -5.0)),
            MissionItem.local(2, mi.NAV_WAYPOINT, (3.0, 0.0, -2.0), (1.5, 0.0, 0.0, 90.0)),
            MissionItem.local(3, mi.DO_CHANGE_SPEED, None, (1.0, 0.5, -1.0)),
            MissionItem.local(4, mi.NAV_WAYPOINT, (3.0, 4.0, -2.0), (0.0, 0.0, 0.0, nan)),
            MissionItem.local(5, mi.NAV_LOITER_TIME, (3.0, 4.0, -2.0), (2.0,))]
    ex, track = perfect_flight(plan, s, (0.0, 0.0, 0.0))
    assert ex.finished
    legs = {leg.seq: leg for leg in ex.legs}
    assert [leg.seq for leg in ex.legs] == [0, 1, 2, 3, 4, 5]

    def trapezoid(length, v, a):
        return length / v + v / a if length >= v * v / a else 2 * math.sqrt(length / a)

    dt = 0.01  # the update period: a leg ends on the first update after its time
    assert legs[0].reached == pytest.approx(trapezoid(2.0, 0.5, 1.0), abs=dt + 1e-9)
    assert legs[2].end - legs[2].start == pytest.approx(trapezoid(3.0, 1.0, 2.0) + 1.5,
                                                        abs=2 * dt)
    assert legs[4].end - legs[4].start == pytest.approx(trapezoid(4.0, 0.5, 2.0), abs=2 * dt)
    assert legs[5].end - legs[5].reached == pytest.approx(2.0, abs=dt + 1e-9)
    # the tilt from the attitude item on the legs after it; the heading from the waypoint
    euler = np.array([e for t, _, _, e in track if legs[2].start < t < legs[2].end])
    np.testing.assert_allclose(np.degrees(euler[-1]), [10.0, -5.0, 90.0], atol=1e-9)
    speed = max(np.linalg.norm(v) for t, _, v, _ in track if legs[4].start < t < legs[4].end)
    assert speed == pytest.approx(0.5, abs=1e-9)  # DO_CHANGE_SPEED


def test_landing_descends_at_the_landing_speed_and_stops_below_the_ground():
    s = Settings(land=0.4, acc_ver=1.0, ground_z=0.0)
    plan = [MissionItem.local(0, mi.NAV_LAND, (1.0, 0.0, 0.0))]
    ex, track = perfect_flight(plan, s, (0.0, 0.0, -1.0), ground_z=0.0)
    assert ex.finished and [e.kind for e in ex.events][-2:] == ["landed", "finished"]
    vz = np.array([v[2] for _, _, v, _ in track])
    assert vz.max() == pytest.approx(0.4, abs=1e-9)  # never faster than MPC_LAND_SPEED
    assert track[-1][1][0] == pytest.approx(1.0, abs=1e-9)  # over the landing point
    ex2 = Executor(plan, Settings(land=0.4, acc_ver=1.0, ground_z=0.0),
                   np.array([1.0, 0.0, -0.2]), np.zeros(3))
    for k in range(400):  # a vehicle stuck above the ground: the carrot stops at the depth
        r = ex2.update(k * 0.01, Vehicle(np.array([1.0, 0.0, -0.2]), np.zeros(3), False))
    assert r["pos_ref"][2] == pytest.approx(LAND_DEPTH, abs=1e-12)
    assert np.all(r["vel_ref"] == 0.0)


def test_return_climbs_first_and_goes_to_the_nearest_of_home_and_rally():
    s = Settings(rtl_alt=3.0, ground_z=0.0)
    plan = [MissionItem.local(0, mi.NAV_RETURN_TO_LAUNCH)]
    ex = Executor(plan, s, np.array([4.0, 0.0, -1.0]), np.zeros(3), home=np.zeros(3),
                  rally=[np.array([5.0, 1.0, 0.0])])
    zs, xs = [], []
    pos = np.array([4.0, 0.0, -1.0])
    for k in range(3000):
        r = ex.update(k * 0.01, Vehicle(pos, np.zeros(3), pos[2] >= 0.0))
        pos = np.minimum(r["pos_ref"], [np.inf, np.inf, 0.0])
        zs.append(pos[2])
        xs.append(pos[:2].copy())
        if ex.finished:
            break
    assert ex.finished
    assert min(zs) == pytest.approx(-3.0, abs=1e-9)  # climbed to RTL_RETURN_ALT first
    np.testing.assert_allclose(xs[-1], [5.0, 1.0], atol=1e-9)  # the rally point was nearer


def test_a_speed_above_the_limit_is_told_not_silently_clamped():
    s = Settings(speed_max=2.0)
    plan = [MissionItem.local(0, mi.DO_CHANGE_SPEED, None, (1.0, 9.0, -1.0)),
            MissionItem.local(1, mi.NAV_WAYPOINT, (1.0, 0.0, -1.0))]
    ex, _ = perfect_flight(plan, s, (0.0, 0.0, -1.0))
    notices = [e.text for e in ex.events if e.kind == "notice"]
    assert notices == ["speed 9 m/s above the limit 2: flying 2 m/s"]


def winding_number(poly: np.ndarray, n: float, e: float) -> int:
    """Independent oracle: the total angle the polygon's edges turn around the point."""
    ang = np.arctan2(poly[:, 1] - e, poly[:, 0] - n)
    d = np.diff(np.append(ang, ang[0]))
    d = (d + np.pi) % (2 * np.pi) - np.pi
    return round(d.sum() / (2 * np.pi))


def test_fence_zones_against_the_winding_number():
    poly = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [2.0, 1.0], [0.0, 4.0]])  # concave
    vertices = [MissionItem.local(i, mi.FENCE_POLYGON_VERTEX_INCLUSION, (p[0], p[1], 0.0),
                                  (5.0,), mission_type=mi.FENCE) for i, p in enumerate(poly)]
    circle = MissionItem.local(5, mi.FENCE_CIRCLE_INCLUSION, (10.0, 10.0, 0.0), (1.0,),
                               mission_type=mi.FENCE)
    assert mi.check_plan([*vertices, circle]) is None
    fence = Fence.from_items([*vertices, circle], None, 0.0)
    rng = np.random.default_rng(7)
    for n, e in rng.uniform(-1.0, 5.0, size=(400, 2)):
        assert fence.contains((n, e, -1.0)) == (winding_number(poly, n, e) != 0), (n, e)
    assert fence.contains((10.5, 10.5, 0.0)) and not fence.contains((11.0, 11.0, 0.0))
    assert Fence().contains((1e6, 0.0, 0.0))  # no zone, no breach
    assert "incomplete" in mi.check_plan(vertices[:4])


SCENARIO = """
name = "m"
duration = 10.0
airframe = "paper_hexacopter"
start = "ground"
[mission]
start = [0.0, 0.0, 0.0]
[[mission.item]]
command = "NAV_TAKEOFF"
position = [0.0, 0.0, -1.0]
"""


@pytest.mark.parametrize("extra, field, reason", [
    ('[[mission.item]]\ncommand = "NAV_ORBIT"\n', "mission.item[2].command",
     "expected one of"),
    ('[[mission.item]]\ncommand = "NAV_WAYPOINT"\n', "mission.item[2].position", "missing"),
    ('[[mission.item]]\ncommand = "NAV_WAYPOINT"\nposition = [1, 2, 3]\nhold = -1\n',
     "mission.item[2].hold", ">= 0"),
    ('[[mission.item]]\ncommand = "FULLPOSE_ATTITUDE"\nroll_deg = 95\n', "mission.item[2]",
     "beyond 80 deg"),
    ('[reference.position]\nz = -1.0\n', "mission", "not both"),
])
def test_scenario_mission_errors_name_the_field(extra, field, reason):
    import tomllib

    data = tomllib.loads(SCENARIO + extra)
    with pytest.raises(ScenarioError) as e:
        parse_scenario(data, "m.toml")
    assert f"field '{field}'" in str(e.value) and reason in str(e.value), str(e.value)


def test_shipped_mission_scenario_reaches_every_leg_within_the_paper_accuracy():
    from orchestrator.master import run
    from orchestrator.output.metrics import compute_metrics
    from orchestrator.scenario.catalogue import load_scenario

    r = run(load_scenario("mission_full_pose"), progress=False)
    record = r.meta["mission"]
    assert record["finished"]
    assert [e["kind"] for e in record["events"]][-2:] == ["landed", "finished"]
    m = compute_metrics(r)
    legs = {leg["command"] + str(leg["seq"]): leg for leg in m["mission_legs"]}
    for name, leg in legs.items():
        assert leg["reached"] is not None, name
        if not name.startswith("NAV_TAKEOFF"):  # the climb off the gear: see below
            assert leg["position_error"]["max"] < ACCURACY, (name, leg)
            assert leg["attitude_error"]["max"] < 1.0, (name, leg)
    t = r.time
    roll = np.degrees(r.get("plant.euler")[:, 0])
    tilted = legs["NAV_WAYPOINT4"]
    on_leg = (t > tilted["start"] + 1.0) & (t < tilted["reached"])
    assert roll[on_leg] == pytest.approx(15.0, abs=0.5)
    # the takeoff off the gear lags the shaped climb by the motors' spin-up (as the
    # takeoff_and_land scenario), the rest of the run within the accuracy
    assert legs["NAV_TAKEOFF0"]["position_error"]["max"] < 0.03
    # landed, then disarmed 2 s later as the bridge's COM_DISARM_LAND: the rotors stopped
    from orchestrator.mission_feed import DISARM_AFTER
    from orchestrator.output.events import events

    finished = next(e["time"] for e in record["events"] if e["kind"] == "finished")
    assert record["disarmed"] == pytest.approx(finished + DISARM_AFTER, abs=0.011)
    assert np.all(r.get("ctrl.omega_cmd")[t > record["disarmed"] + 0.01] == 0.0)
    texts = [e.text for e in events(r, ("mission",))]
    assert texts[:2] == ["item 0 NAV_TAKEOFF", "item 0 reached"]
    assert texts[-2:] == ["mission finished", "disarmed"]
