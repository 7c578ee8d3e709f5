"""Flight from the ground and back over real MAVLink 2 on UDP (pymavlink as the ground
station), as PX4 SITL flies it: boot landed and disarmed, arm, take off, go to, a mission
uploaded with the mission protocol (a tilted leg among its items), return, land and
auto-disarm; the geofence; a shipped non-paper airframe (the X8) from the ground.

Oracles: the MAVLink messages the bridge sends (EXTENDED_SYS_STATE's landed state, HEARTBEAT
modes and arming, MISSION_ITEM_REACHED in order, COMMAND_ACK results), and positions
against the commanded ones within the paper's 2 cm where the vehicle holds a point.
"""

import math
import os
import time

import numpy as np
import pytest
from helpers.mavlink_harness import Flight
from pymavlink.dialects.v20 import common as mav

os.environ["MAVLINK20"] = "1"
pytestmark = pytest.mark.mavlink

nan = math.nan
TAKEOFF, LOITER, MISSION, RTL, LAND = ((4 << 16) | (s << 24) for s in (2, 3, 4, 5, 6))
ON_GROUND, IN_AIR = mav.MAV_LANDED_STATE_ON_GROUND, mav.MAV_LANDED_STATE_IN_AIR
ARMED = mav.MAV_MODE_FLAG_SAFETY_ARMED


def landed_state(f: Flight) -> int:
    return int(f.wait("EXTENDED_SYS_STATE", 3.0).landed_state)


def until(f: Flight, cond, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return
        f.drain()
        time.sleep(0.02)
    raise AssertionError(f"{what} not within {timeout} s (texts {f.texts[-6:]})")


def settle(f: Flight, seconds: float) -> None:
    """Wait, reading what comes meanwhile: a socket left unread for a second at speed 4 fills
    its buffer with telemetry, and the kernel then drops the replies that follow."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        f.drain()
        time.sleep(0.01)


def pos(f: Flight) -> np.ndarray:
    return np.array(f.bridge.state["plant"]["pos"], float)


def upload(f: Flight, items: list[mav.MAVLink_mission_item_int_message], kind: int = 0) -> int:
    """The mission protocol as a ground station runs it: the result of the final ack."""
    f.gcs.mav.mission_count_send(1, 1, len(items), kind)
    while True:
        m = f.gcs.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
                             blocking=True, timeout=5.0)
        assert m is not None, "no request or ack"
        if m.get_type() == "MISSION_ACK":
            return int(m.type)
        it = items[m.seq]
        f.gcs.mav.send(it)


def item(seq: int, command: int, x: float = 0.0, y: float = 0.0, z: float = 0.0,
         p: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
         frame: int = mav.MAV_FRAME_LOCAL_NED, kind: int = 0
         ) -> mav.MAVLink_mission_item_int_message:
    xi, yi = (round(x * 1e4), round(y * 1e4)) if frame == mav.MAV_FRAME_LOCAL_NED else \
        (round(x * 1e7), round(y * 1e7))
    return mav.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, *p, xi, yi,
                                                z, kind)


@pytest.fixture
def ground():
    f = Flight(speed=4.0, start="ground", duration=600.0)
    yield f
    f.close()


def test_boots_landed_disarmed_takes_off_lands_and_disarms(ground):
    f = ground
    rest = pos(f)
    assert landed_state(f) == ON_GROUND
    hb = f.wait("HEARTBEAT", 3.0)
    assert not hb.base_mode & ARMED and hb.custom_mode == LOITER
    # disarmed: a takeoff is refused with the reason, nothing moves
    f.command(22, 0, 0, 0, nan, nan, nan, nan, expect=mav.MAV_RESULT_DENIED)
    assert "takeoff refused: disarmed: arm first" in f.texts
    f.command(400, 1, expect=0)
    assert landed_state(f) == ON_GROUND  # armed, idling on the gear
    # MAVSDK's set_takeoff_altitude writes MIS_TAKEOFF_ALT; NAV_TAKEOFF with NaN altitude
    f.gcs.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", 1.5, mav.MAV_PARAM_TYPE_REAL32)
    f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    f.command(22, 0, 0, 0, nan, nan, nan, nan, expect=0)
    f.wait("HEARTBEAT", 3.0, lambda m: m.custom_mode == TAKEOFF)
    # the takeoff ends in AUTO.LOITER at 1.5 m above home (home: where it rested)
    f.wait("HEARTBEAT", 20.0, lambda m: m.custom_mode == LOITER)
    assert landed_state(f) == IN_AIR
    settle(f, 1.0)
    p = pos(f)
    assert abs(p[2] - (rest[2] - 1.5)) < 0.02 and np.hypot(*(p[:2] - rest[:2])) < 0.02
    # disarming in flight is refused (the rotors would stop)
    f.command(400, 0, expect=mav.MAV_RESULT_DENIED)
    assert f.bridge.armed
    f.command(21, 0, 0, 0, nan, nan, nan, nan, expect=0)
    f.wait("HEARTBEAT", 3.0, lambda m: m.custom_mode == LAND)
    touch = []
    f.bridge.on_chunk = lambda b: touch.append((b.session.time, b.state["plant"]["vel"][2],
                                                b.state["plant"]["contact_flags"][0]))
    # touchdown detected, then disarmed after COM_DISARM_LAND (2 s)
    f.wait("HEARTBEAT", 30.0, lambda m: not m.base_mode & ARMED)
    f.bridge.on_chunk = None
    f.wait("STATUSTEXT", 3.0, lambda m: m.text == "disarmed: landed")
    assert "landing detected" in f.texts
    assert landed_state(f) == ON_GROUND
    first = next(i for i, (_, _, c) in enumerate(touch) if c > 0)
    # the touchdown at the landing speed (MPC_LAND_SPEED 0.5 m/s), no faster
    assert 0.0 < touch[first][1] <= 0.5 + 0.05, touch[first]
    assert np.hypot(*(pos(f)[:2] - rest[:2])) < 0.02


def test_mission_with_a_tilted_leg_flown_to_the_end(ground):
    f = ground
    rest = pos(f)
    items = [item(0, 22, 0.0, 0.0, -1.5),  # NAV_TAKEOFF to 1.5 m
             item(1, 31010, p=(12.0, 0.0, 0.0, 0.0), frame=mav.MAV_FRAME_MISSION),
             item(2, 16, 1.0, 0.0, -1.5, p=(0.5, 0.03, 0.0, nan)),  # tilted 12 deg roll
             item(3, 31010, p=(0.0, 0.0, 0.0, 0.0), frame=mav.MAV_FRAME_MISSION),
             item(4, 178, p=(1.0, 0.5, -1.0, 0.0), frame=mav.MAV_FRAME_MISSION),
             item(5, 16, 1.0, 1.0, -1.5, p=(0.0, 0.0, 0.0, 90.0)),
             item(6, 20, frame=mav.MAV_FRAME_MISSION)]  # RTL: home, land
    assert upload(f, items) == mav.MAV_MISSION_ACCEPTED
    f.gcs.mav.param_set_send(1, 1, b"RTL_RETURN_ALT", 1.5, mav.MAV_PARAM_TYPE_REAL32)
    f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "RTL_RETURN_ALT")
    f.command(400, 1, expect=0)
    f.command(300, 0, 0, expect=0)  # MISSION_START
    f.wait("HEARTBEAT", 3.0, lambda m: m.custom_mode == MISSION)
    reached, tilt = [], []

    def watch(b):
        if b.mode == "MISSION" and b.mission_current == 2 and b.auto is not None \
                and b.auto.phase == "":
            tilt.append(math.degrees(b.state["plant"]["euler"][0]))

    f.bridge.on_chunk = watch
    deadline = time.monotonic() + 60.0
    while len(reached) < 4 and time.monotonic() < deadline:  # the positioned items
        m = f.gcs.recv_match(type="MISSION_ITEM_REACHED", blocking=True, timeout=0.5)
        if m is not None and m.get_type() == "MISSION_ITEM_REACHED":
            reached.append(m.seq)
    f.bridge.on_chunk = None
    assert reached == [0, 2, 5, 6], reached  # in order, each once
    assert max(tilt) == pytest.approx(12.0, abs=0.5)  # the leg flown at 12 deg of roll
    f.wait("HEARTBEAT", 20.0, lambda m: not m.base_mode & ARMED)
    assert np.hypot(*(pos(f)[:2] - rest[:2])) < 0.02  # back home
    assert landed_state(f) == ON_GROUND


def test_goto_pause_speed_home_and_geofence(ground):
    f = ground
    f.command(400, 1, expect=0)
    f.command(22, 0, 0, 0, nan, nan, nan, f.bridge.home_alt + 1.5, expect=0)  # AMSL
    f.wait("HEARTBEAT", 20.0, lambda m: m.custom_mode == LOITER)
    origin = f.bridge.origin
    lat, lon, alt = origin.to_geodetic(1.0, 0.5, -1.5)
    # QGroundControl's Go-to: DO_REPOSITION as COMMAND_INT in the global frame
    f.gcs.mav.command_int_send(1, 1, mav.MAV_FRAME_GLOBAL, 192, 0, 0, -1, 1, 0, nan,
                               round(lat * 1e7), round(lon * 1e7), alt)
    assert f.wait("COMMAND_ACK", 3.0, lambda m: m.command == 192).result == 0
    until(f, lambda: np.linalg.norm(pos(f) - [1.0, 0.5, -1.5]) < 0.02, 20.0, "go-to")
    # a speed above MPC_XY_VEL_MAX is refused, not clamped
    f.command(178, 1, 50.0, -1, expect=mav.MAV_RESULT_DENIED)
    f.command(178, 1, 0.5, -1, expect=0)
    # Pause as QGroundControl sends it: DO_REPOSITION with every position NaN
    lat, lon, alt = origin.to_geodetic(-1.0, 0.5, -1.5)
    f.gcs.mav.command_int_send(1, 1, mav.MAV_FRAME_GLOBAL, 192, 0, 0, -1, 1, 0, nan,
                               round(lat * 1e7), round(lon * 1e7), alt)
    f.wait("COMMAND_ACK", 3.0, lambda m: m.command == 192)
    settle(f, 0.5)
    f.command(192, -1, 1, 0, nan, nan, nan, nan, expect=0)
    settle(f, 1.0)
    held = pos(f)
    settle(f, 1.0)
    assert np.linalg.norm(pos(f) - held) < 0.02 and held[0] > -0.9  # stopped short
    # DO_SET_HOME here: HOME_POSITION follows
    f.command(179, 1, expect=0)
    home = f.wait("HOME_POSITION", 5.0, lambda m: abs(m.x - held[0]) < 0.05)
    assert home.y == pytest.approx(held[1], abs=0.05)
    # a fence: a 2 m circle around the origin; a go-to outside breaches it: hold (GF_ACTION 2)
    lat0, lon0, _ = origin.to_geodetic(0.0, 0.0, 0.0)
    fence = [item(0, 5003, lat0, lon0, 0.0, p=(2.0, 0, 0, 0), frame=mav.MAV_FRAME_GLOBAL_INT,
                  kind=1)]
    assert upload(f, fence, kind=1) == mav.MAV_MISSION_ACCEPTED
    lat, lon, alt = origin.to_geodetic(3.0, 0.0, -1.5)
    f.command(192, -1, 1, 0, nan, lat, lon, alt, expect=0)
    f.wait("STATUSTEXT", 15.0, lambda m: "geofence breached: hold" in m.text)
    f.wait("HEARTBEAT", 3.0, lambda m: m.custom_mode == LOITER)
    settle(f, 1.5)
    assert 1.9 < np.hypot(*pos(f)[:2]) < 2.6  # stopped just past the fence


def test_x8_takes_off_and_lands_from_the_ground():
    f = Flight(speed=4.0, start="ground", airframe="x8_coaxial")
    try:
        rest = pos(f)
        assert landed_state(f) == ON_GROUND
        f.command(400, 1, expect=0)
        f.command(22, 0, 0, 0, nan, nan, nan, nan, expect=0)
        f.wait("HEARTBEAT", 20.0, lambda m: m.custom_mode == LOITER)
        settle(f, 1.0)
        assert abs(pos(f)[2] - (rest[2] - 2.5)) < 0.02  # MIS_TAKEOFF_ALT's default
        f.command(20, expect=0)  # RTL: home is below, so it lands there
        f.wait("HEARTBEAT", 40.0, lambda m: not m.base_mode & ARMED)
        f.wait("STATUSTEXT", 3.0, lambda m: m.text == "disarmed: landed")
        assert np.linalg.norm(pos(f) - rest) < 0.02
    finally:
        f.close()


def test_preflight_auto_disarm(ground):
    f = ground
    f.gcs.mav.param_set_send(1, 1, b"COM_DISARM_PRFLT", 1.0, mav.MAV_PARAM_TYPE_REAL32)
    f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "COM_DISARM_PRFLT")
    f.command(400, 1, expect=0)
    f.wait("HEARTBEAT", 10.0, lambda m: not m.base_mode & ARMED)
    f.wait("STATUSTEXT", 3.0, lambda m: m.text == "disarmed: no takeoff")
