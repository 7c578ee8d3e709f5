"""Flight from the ground and back with MAVSDK as the ground station (Action, Mission,
MissionRaw, Telemetry), as a script for PX4 SITL would fly it: boot landed and disarmed,
arm, take off to MIS_TAKEOFF_ALT, a raw mission with a 12 deg roll leg (FULLPOSE_ATTITUDE,
MAV_CMD_USER_1), return to launch, touch down and auto-disarm; land where it is; the Mission
plugin's plan uploaded, downloaded and flown; a go-to (DO_REPOSITION).

Oracles: what MAVSDK's Telemetry reports (landed state, arming, flight mode, relative
altitude), MAVSDK's mission progress, and the bridge's own state sampled every chunk
(``bridge.on_chunk``: attitude, touchdown, position within the paper's 2 cm where the vehicle
holds a point).  ``pytest -s`` prints the touchdown speed, the time from touchdown to disarm
and the mission's per-item timing.  Two PX4 behaviours MAVSDK relies on are guarded: the
mission state after a mission's end (MISSION_STATE_COMPLETE on the last item) and
DO_REPOSITION's heading in radians.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import pytest
from helpers import mavlink_harness as harness

os.environ["MAVLINK20"] = "1"

pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

SPEED = 4.0  # simulated s per wall s
ALT = 1.5  # m above home: the takeoff altitude and the missions' legs
ATTITUDE = 31010  # FULLPOSE_ATTITUDE (MAV_CMD_USER_1): param1 roll, param2 pitch, deg
FRAME_MISSION, FRAME_REL_ALT_INT = 2, 6  # MAV_FRAME_MISSION, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


# -- what the test sees ---------------------------------------------------------------------


def until(cond: Callable[[], bool], timeout: float, what: str,
          info: Callable[[], Any] = lambda: "") -> None:
    """Poll ``cond`` every 20 ms until true; fail after ``timeout`` wall seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return
        time.sleep(0.02)
    raise AssertionError(f"{what} not within {timeout} s: {info()}")


class Seen:
    """MAVSDK Telemetry's streams as the test saw them: each value with the wall time it
    changed to it (landed state, armed, flight mode, in air) and the latest position."""

    def __init__(self, telemetry: Any) -> None:
        self._lock = threading.Lock()
        self.landed: list[tuple[float, Any]] = []
        self.armed: list[tuple[float, bool]] = []
        self.modes: list[tuple[float, Any]] = []
        self.in_air: list[tuple[float, bool]] = []
        self.position: Any = None
        telemetry.subscribe_landed_state(lambda v, _: self._add(self.landed, v))
        telemetry.subscribe_armed(lambda v, _: self._add(self.armed, bool(v)))
        telemetry.subscribe_flight_mode(lambda v, _: self._add(self.modes, v))
        telemetry.subscribe_in_air(lambda v, _: self._add(self.in_air, bool(v)))
        telemetry.subscribe_position(lambda v, _: setattr(self, "position", v))

    def _add(self, history: list[tuple[float, Any]], value: Any) -> None:
        with self._lock:
            if not history or history[-1][1] != value:
                history.append((time.monotonic(), value))

    @staticmethod
    def last(history: list[tuple[float, Any]]) -> Any:
        return history[-1][1] if history else None

    @staticmethod
    def since(history: list[tuple[float, Any]], t0: float) -> list[Any]:
        """The values taken from wall time t0 on (the one in force then first)."""
        before = [v for t, v in history if t < t0][-1:]
        return before + [v for t, v in history if t >= t0]

    def rel_alt(self) -> float:
        return math.nan if self.position is None else float(self.position.relative_altitude_m)

    def __repr__(self) -> str:
        return (f"landed {[v.name for _, v in self.landed]}, armed {[v for _, v in self.armed]}"
                f", modes {[v.name for _, v in self.modes]}, rel alt {self.rel_alt():.3f}")


class Row(NamedTuple):
    t: float  # simulated s
    pos: tuple[float, float, float]  # NED m
    vz: float  # m/s down
    contact: float  # contact_flags[0]
    roll: float  # deg
    pitch: float  # deg
    mode: str
    current: int  # the mission item flown
    armed: bool


class Chunks:
    """The bridge's state after every chunk (``bridge.on_chunk``; runs in the bridge's
    thread)."""

    def __init__(self, bridge: Any) -> None:
        self.rows: list[Row] = []
        bridge.on_chunk = self

    def __call__(self, b: Any) -> None:
        p = b.state["plant"]
        self.rows.append(Row(b.session.time, tuple(float(v) for v in p["pos"]),
                             float(p["vel"][2]), float(p["contact_flags"][0]),
                             math.degrees(float(p["euler"][0])),
                             math.degrees(float(p["euler"][1])), b.mode,
                             b.mission_current, bool(b.armed)))

    def touchdown(self, t0: float) -> tuple[Row, Row]:
        """(the first chunk in contact with the ground at or after simulated t0, the first
        disarmed one after it)."""
        rows = list(self.rows)
        touch = next((r for r in rows if r.t >= t0 and r.contact > 0), None)
        assert touch is not None, f"no ground contact after t = {t0:.2f} s"
        disarmed = next((r for r in rows if r.t >= touch.t and not r.armed), None)
        assert disarmed is not None, f"not disarmed after the touchdown at {touch.t:.2f} s"
        return touch, disarmed


def pos(bridge: Any) -> np.ndarray:
    return np.array(bridge.state["plant"]["pos"], float)


def texts(bridge: Any) -> list[str]:
    return list(bridge.events[-8:])


def plugins_for(system: Any, plugins: list[Any]) -> tuple[Any, Any, Any]:
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.telemetry import Telemetry

    action, telemetry = Action(system), Telemetry(system)
    plugins += [action, telemetry]
    return action, telemetry, Seen(telemetry)


def boot_on_ground(bridge: Any, telemetry: Any, seen: Seen) -> None:
    """Landed and disarmed at boot, as MAVSDK's Telemetry tells it."""
    from mavsdk.plugins.telemetry import LandedState

    until(lambda: Seen.last(seen.landed) == LandedState.ON_GROUND, 10.0, "ON_GROUND at boot",
          lambda: seen)
    until(lambda: seen.armed, 5.0, "armed state at boot", lambda: seen)
    assert telemetry.landed_state() == LandedState.ON_GROUND
    assert telemetry.armed() is False and not bridge.armed
    assert not telemetry.in_air()


def take_off(bridge: Any, action: Any, telemetry: Any, seen: Seen) -> float:
    """set_takeoff_altitude(ALT), arm, takeoff: TAKEOFF then HOLD, in air, at ALT (5 cm by
    telemetry, 2 cm by the bridge); the wall s it took."""
    from mavsdk.plugins.telemetry import FlightMode, LandedState

    rest = pos(bridge)
    action.set_takeoff_altitude(ALT)
    action.arm()
    until(lambda: Seen.last(seen.armed) is True, 5.0, "armed", lambda: seen)
    t0 = time.monotonic()
    action.takeoff()
    until(lambda: FlightMode.TAKEOFF in Seen.since(seen.modes, t0), 5.0, "TAKEOFF mode",
          lambda: (seen, texts(bridge)))
    until(lambda: Seen.since(seen.modes, t0)[-1] == FlightMode.HOLD, 30.0,
          "HOLD after the takeoff", lambda: (seen, texts(bridge)))
    until(lambda: telemetry.in_air()
          and abs(telemetry.position().relative_altitude_m - ALT) < 0.05, 10.0,
          f"in air at {ALT} m", lambda: (seen, str(telemetry.position())))
    # EXTENDED_SYS_STATE comes at its stream rate, the mode change at once
    until(lambda: Seen.last(seen.landed) == LandedState.IN_AIR, 3.0, "IN_AIR", lambda: seen)
    assert telemetry.flight_mode() == FlightMode.HOLD
    up = rest - [0.0, 0.0, ALT]
    until(lambda: np.linalg.norm(pos(bridge) - up) < 0.02, 10.0, "holding above the start",
          lambda: pos(bridge) - up)
    return time.monotonic() - t0


def land_and_disarm(bridge: Any, seen: Seen, chunks: Chunks, t_sim: float, t_wall: float,
                    timeout: float) -> tuple[float, float]:
    """LANDING, then ON_GROUND, then disarmed by the bridge itself (COM_DISARM_LAND); the
    touchdown speed (m/s) and the simulated s from touchdown to disarm."""
    from mavsdk.plugins.telemetry import LandedState

    until(lambda: Seen.last(seen.armed) is False, timeout, "auto-disarm",
          lambda: (seen, texts(bridge)))
    landed = Seen.since(seen.landed, t_wall)
    assert LandedState.LANDING in landed, seen
    assert landed[-1] == LandedState.ON_GROUND, seen
    assert LandedState.ON_GROUND in landed[landed.index(LandedState.LANDING):], seen
    assert "landing detected" in bridge.events and "disarmed: landed" in bridge.events
    touch, disarmed = chunks.touchdown(t_sim)
    assert 0.0 < touch.vz <= 0.5 + 0.05, touch  # at MPC_LAND_SPEED, no faster
    delay = disarmed.t - touch.t
    assert 2.0 - 1e-6 <= delay < 4.0, (touch, disarmed)  # detection + COM_DISARM_LAND 2 s
    return touch.vz, delay


# -- the tests --------------------------------------------------------------------------------


@pytest.mark.clients
def test_mavsdk_ground_takeoff_tilted_raw_mission_return_and_auto_disarm():
    """The issue's "done when" script: boot on the ground, take off, a raw mission with a
    12 deg roll leg, return to launch, land and disarm by itself where it started."""
    from mavsdk.plugins.mission_raw import MissionItem, MissionRaw
    from mavsdk.plugins.telemetry import FlightMode

    with harness.mavsdk_session(start="ground", speed=SPEED, duration=600.0) as (
            bridge, system, plugins):
        action, telemetry, seen = plugins_for(system, plugins)
        raw = MissionRaw(system)
        plugins.append(raw)
        chunks = Chunks(bridge)
        rest = pos(bridge)
        boot_on_ground(bridge, telemetry, seen)
        took = take_off(bridge, action, telemetry, seen)

        origin = bridge.origin
        wp1, wp2 = rest + np.array([1.0, 0.0, -ALT]), rest + np.array([1.0, 1.0, -ALT])

        def waypoint(seq: int, p: np.ndarray, hold: float) -> Any:
            lat, lon, _ = origin.to_geodetic(*(float(v) for v in p))
            return MissionItem(seq=seq, frame=FRAME_REL_ALT_INT, command=16, current=0,
                               autocontinue=1, param1=hold, param2=0.03, param3=0.0,
                               param4=math.nan, x=round(lat * 1e7), y=round(lon * 1e7), z=ALT,
                               mission_type=0)

        def attitude(seq: int, roll: float, pitch: float) -> Any:
            # MAVSDK wants exactly one item marked current (CURRENT_INVALID otherwise)
            return MissionItem(seq=seq, frame=FRAME_MISSION, command=ATTITUDE,
                               current=int(seq == 0), autocontinue=1, param1=roll,
                               param2=pitch, mission_type=0)

        items = [attitude(0, 12.0, 0.0), waypoint(1, wp1, 1.0),  # flown at 12 deg of roll
                 attitude(2, 0.0, 0.0), waypoint(3, wp2, 0.5)]  # level again
        raw.upload_mission(items)
        progress: list[tuple[float, float, int, int]] = []  # (wall, sim, current, total)
        raw.subscribe_mission_progress(lambda p, _: progress.append(
            (time.monotonic(), bridge.session.time, p.current, p.total)))
        t_start = time.monotonic()
        raw.start_mission()
        until(lambda: any(c == len(items) and n == len(items) for _, _, c, n in progress),
              40.0, "mission progress to the end", lambda: (progress, texts(bridge)))
        until(lambda: Seen.since(seen.modes, t_start)[-1] == FlightMode.HOLD
              and FlightMode.MISSION in Seen.since(seen.modes, t_start), 5.0,
              "MISSION, then HOLD at its end", lambda: seen)
        assert "mission finished" in bridge.events
        until(lambda: np.linalg.norm(pos(bridge) - wp2) < 0.02, 10.0,
              "holding at the last waypoint", lambda: pos(bridge) - wp2)
        # the tilted leg: the roll reached 12 deg; level again on the next
        tilted = [r.roll for r in list(chunks.rows) if r.mode == "MISSION" and r.current == 1]
        level = [r.roll for r in list(chunks.rows) if r.mode == "MISSION" and r.current == 3]
        assert tilted and max(tilted) == pytest.approx(12.0, abs=0.5), max(tilted, default=None)
        assert abs(level[-1]) < 0.5, level[-1]

        # return to launch: back home, down, disarmed by itself
        t_sim, t_wall = bridge.session.time, time.monotonic()
        action.return_to_launch()
        until(lambda: FlightMode.RETURN_TO_LAUNCH in Seen.since(seen.modes, t_wall), 5.0,
              "RETURN_TO_LAUNCH mode", lambda: seen)
        speed, delay = land_and_disarm(bridge, seen, chunks, t_sim, t_wall, 40.0)
        assert np.hypot(*(pos(bridge)[:2] - rest[:2])) < 0.02, pos(bridge) - rest
        assert not telemetry.armed() and not telemetry.in_air()
        end = raw.mission_progress()

        print(f"\n[raw mission] takeoff {took:.2f} s wall; tilt max {max(tilted):.2f} deg")
        t0_wall, t0_sim = t_start, progress[0][1] if progress else math.nan
        for wall, sim, c, n in progress:
            print(f"  progress {c}/{n} at +{wall - t0_wall:.2f} s wall, "
                  f"+{sim - t0_sim:.2f} s simulated")
        print(f"  after the end: mission_progress() {end.current}/{end.total}, "
              f"is_mission_finished() {raw.is_mission_finished()}")
        print(f"  RTL: touchdown at {speed:.3f} m/s down, disarmed {delay:.2f} s simulated "
              f"({delay / SPEED:.2f} s wall) after touchdown; home within "
              f"{100 * np.hypot(*(pos(bridge)[:2] - rest[:2])):.2f} cm")


@pytest.mark.clients
def test_mavsdk_ground_land_where_it_is_and_auto_disarm():
    """action.land() after a takeoff: down where it is, ON_GROUND, disarmed by itself."""
    from mavsdk.plugins.telemetry import FlightMode

    with harness.mavsdk_session(start="ground", speed=SPEED, duration=600.0) as (
            bridge, system, plugins):
        action, telemetry, seen = plugins_for(system, plugins)
        chunks = Chunks(bridge)
        boot_on_ground(bridge, telemetry, seen)
        take_off(bridge, action, telemetry, seen)
        above = pos(bridge)
        t_sim, t_wall = bridge.session.time, time.monotonic()
        action.land()
        until(lambda: FlightMode.LAND in Seen.since(seen.modes, t_wall), 5.0, "LAND mode",
              lambda: seen)
        speed, delay = land_and_disarm(bridge, seen, chunks, t_sim, t_wall, 30.0)
        assert np.hypot(*(pos(bridge)[:2] - above[:2])) < 0.02, pos(bridge) - above
        assert not telemetry.in_air()
        print(f"\n[land] touchdown at {speed:.3f} m/s down, disarmed {delay:.2f} s simulated "
              f"({delay / SPEED:.2f} s wall) after touchdown")


class MissionNotFinished(AssertionError):
    """MAVSDK's Mission plugin does not see the end of a mission the bridge flew to its end."""


@pytest.mark.clients
def test_mavsdk_ground_mission_plugin_upload_download_and_fly():
    """The Mission plugin's plan (3 waypoints, nothing but NAV_WAYPOINT items) accepted,
    downloaded with the same positions, flown to the end: progress 3/3, is_mission_finished."""
    from mavsdk.plugins.mission import Mission, MissionError, MissionItem, MissionPlan

    with harness.mavsdk_session(start="ground", speed=SPEED, duration=600.0) as (
            bridge, system, plugins):
        action, telemetry, seen = plugins_for(system, plugins)
        mission = Mission(system)
        plugins.append(mission)
        rest = pos(bridge)
        origin = bridge.origin
        boot_on_ground(bridge, telemetry, seen)
        take_off(bridge, action, telemetry, seen)

        points = [rest + d for d in ([0.8, 0.0, -ALT], [0.8, 0.8, -ALT], [0.0, 0.8, -ALT])]
        geo = [origin.to_geodetic(*(float(v) for v in p)) for p in points]
        # no speed, gimbal, camera, loiter or vehicle action: MAVSDK adds no items to the
        # NAV_WAYPOINTs (hold 0.5 s, acceptance radius 1 m: MAVSDK's defaults)
        plan = MissionPlan([MissionItem(
            latitude_deg=lat, longitude_deg=lon, relative_altitude_m=ALT,
            speed_m_s=math.nan, is_fly_through=False, gimbal_pitch_deg=math.nan,
            gimbal_yaw_deg=math.nan, camera_action=MissionItem.CameraAction.NONE,
            loiter_time_s=math.nan, acceptance_radius_m=math.nan, yaw_deg=math.nan,
            vehicle_action=MissionItem.VehicleAction.NONE) for lat, lon, _ in geo])
        mission.set_return_to_launch_after_mission(False)
        try:
            mission.upload_mission(plan)
        except MissionError as e:
            pytest.fail(f"Mission plugin upload refused: {e}; bridge said {texts(bridge)}")
        assert [it.command for it in bridge.plans[0]] == [16, 16, 16], bridge.plans[0]
        back = mission.download_mission().mission_items
        assert len(back) == 3, [str(i) for i in back]
        for got, (lat, lon, _) in zip(back, geo, strict=True):
            assert got.latitude_deg == pytest.approx(lat, abs=1.5e-7), str(got)
            assert got.longitude_deg == pytest.approx(lon, abs=1.5e-7), str(got)
            assert got.relative_altitude_m == pytest.approx(ALT, abs=1e-3), str(got)

        progress: list[tuple[float, float, int, int]] = []
        mission.subscribe_mission_progress(lambda p, _: progress.append(
            (time.monotonic(), bridge.session.time, p.current, p.total)))
        t_start = time.monotonic()
        mission.start_mission()
        # flown by the bridge: each item reached in order, then the end, holding at the last
        until(lambda: "mission finished" in bridge.events, 30.0, "the bridge's mission end",
              lambda: (progress, texts(bridge)))
        until(lambda: np.linalg.norm(pos(bridge) - points[-1]) < 0.02, 10.0,
              "holding at the last waypoint", lambda: pos(bridge) - points[-1])
        print(f"\n[mission plugin] uploaded as {[str(it) for it in bridge.plans[0]][:1]} ...")
        for wall, sim, c, n in progress:
            print(f"  progress {c}/{n} at +{wall - t_start:.2f} s wall, "
                  f"+{sim - progress[0][1]:.2f} s simulated")
        # ... and as MAVSDK sees it (MISSION_CURRENT comes at 1 Hz of simulated time)
        try:
            until(lambda: mission.is_mission_finished()
                  and any(c == n == 3 for _, _, c, n in progress), 2.0,
                  "MAVSDK's mission end", lambda: (progress, mission.is_mission_finished()))
        except AssertionError as e:
            raise MissionNotFinished(str(e)) from None
        p = mission.mission_progress()
        assert (p.current, p.total) == (3, 3), str(p)


def goto(bridge: Any, action: Any, goal: np.ndarray, yaw_deg: float) -> float:
    """action.goto_location to the local point goal (its altitude AMSL): there within 2 cm,
    in HOLD; the wall s it took."""
    lat, lon, alt = bridge.origin.to_geodetic(*(float(v) for v in goal))
    t0 = time.monotonic()
    action.goto_location(lat, lon, alt, yaw_deg)
    until(lambda: np.linalg.norm(pos(bridge) - goal) < 0.02, 20.0, "the go-to",
          lambda: (pos(bridge) - goal, texts(bridge)))
    assert bridge.mode == "HOLD"
    return time.monotonic() - t0


def heading(bridge: Any) -> float:
    return math.degrees(float(bridge.state["plant"]["euler"][2]))


@pytest.mark.clients
def test_mavsdk_ground_goto_location():
    """action.goto_location (DO_REPOSITION, altitude AMSL) after a takeoff: there within
    2 cm, holding (HOLD), heading north as asked."""
    from mavsdk.plugins.telemetry import FlightMode

    with harness.mavsdk_session(start="ground", speed=SPEED, duration=600.0) as (
            bridge, system, plugins):
        action, telemetry, seen = plugins_for(system, plugins)
        rest = pos(bridge)
        boot_on_ground(bridge, telemetry, seen)
        take_off(bridge, action, telemetry, seen)
        took = goto(bridge, action, rest + np.array([-0.5, 0.4, -2.0]), 0.0)
        assert telemetry.flight_mode() == FlightMode.HOLD
        until(lambda: abs(telemetry.position().relative_altitude_m - 2.0) < 0.05, 3.0,
              "2 m above home by telemetry", lambda: str(telemetry.position()))
        assert abs(heading(bridge)) < 0.5, heading(bridge)
        print(f"\n[go-to] within 2 cm after {took:.2f} s wall")


class HeadingNotFlown(AssertionError):
    """The go-to's heading is not the one MAVSDK asked for."""


@pytest.mark.clients
def test_mavsdk_ground_goto_location_heading():
    """action.goto_location with a heading (yaw_deg 30): there, facing 30 deg."""
    with harness.mavsdk_session(start="ground", speed=SPEED, duration=600.0) as (
            bridge, system, plugins):
        action, telemetry, seen = plugins_for(system, plugins)
        rest = pos(bridge)
        boot_on_ground(bridge, telemetry, seen)
        take_off(bridge, action, telemetry, seen)
        goto(bridge, action, rest + np.array([0.5, 0.0, -ALT]), 30.0)
        try:
            until(lambda: abs(heading(bridge) - 30.0) < 0.5, 3.0, "heading 30 deg",
                  lambda: f"heading {heading(bridge):.3f} deg")
        except AssertionError as e:
            raise HeadingNotFlown(str(e)) from None
