"""A place on Earth: the geodetic origin, global telemetry and global/body-offset setpoints.

The conversion (pymap3d) is checked against the WGS84 radii of curvature written out here
(an independent first-order oracle) and by round trips; the telemetry and setpoints against
pymavlink over real UDP and against MAVSDK (its mavsdk_server), with a Bridge in a thread.
"""

import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"

from helpers import mavlink_harness as harness
from helpers.mavlink_harness import POS_ONLY, free_port
from pymavlink import mavutil

from mavlink_bridge.geodesy import PX4_SITL_HOME, Origin, parse_origin
from mavlink_bridge.geometry import euler_to_quat

pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

ROOT = Path(__file__).resolve().parents[2]
POS_YAW = 0b0000_1001_1111_1000  # x, y, z and yaw used
ATT_ONLY = 0b0100_0111
A, F = 6378137.0, 1 / 298.257223563  # WGS84
E2 = F * (2 - F)
BASE = {"name": "o", "airframe": "paper_hexacopter", "duration": 1.0}  # a minimal scenario


def radii(lat_deg):
    """Meridian (M) and prime-vertical (N) radii of curvature of WGS84 at a latitude."""
    s2 = math.sin(math.radians(lat_deg)) ** 2
    return A * (1 - E2) / (1 - E2 * s2) ** 1.5, A / math.sqrt(1 - E2 * s2)


def oracle_ned(origin, lat, lon, alt):
    """First-order local NED of a nearby point (exact to well under 1 mm within 100 m)."""
    m, n = radii(origin.lat)
    return (math.radians(lat - origin.lat) * (m + origin.alt),
            math.radians(lon - origin.lon) * (n + origin.alt) * math.cos(math.radians(origin.lat)),
            origin.alt - alt)


# -- the conversion --------------------------------------------------------------------

def test_conversion_against_the_radii_of_curvature_and_round_trips():
    for o in (Origin(), Origin(0.0, 0.0, 0.0), Origin(-33.9, 151.2, 40.0)):
        for n, e in ((100.0, 0.0), (0.0, 100.0), (-70.0, 70.0)):
            lat, lon, alt = o.to_geodetic(n, e, -5.0)
            got = oracle_ned(o, lat, lon, alt)
            # the tangent plane leaves the ellipsoid by (n^2 + e^2) / 2R in height
            assert abs(got[0] - n) < 1e-3 and abs(got[1] - e) < 1e-3, (o, n, e, got)
            assert abs(got[2] + 5.0 + (n * n + e * e) / (2 * A)) < 2e-3, (o, got)
            back = o.to_ned(lat, lon, alt)
            assert max(abs(a - b) for a, b in zip(back, (n, e, -5.0), strict=True)) < 1e-6
    # the equator rule: one degree of latitude is 110.574 km there, of longitude 111.320 km
    o = Origin(0.0, 0.0, 0.0)
    assert abs(o.to_ned(0.01, 0.0, 0.0)[0] - 1105.74) < 0.01
    assert abs(o.to_ned(0.0, 0.01, 0.0)[1] - 1113.19) < 0.01
    assert Origin().to_geodetic(0, 0, 0) == pytest.approx(PX4_SITL_HOME, abs=1e-9)


def test_origin_option_and_scenario_field_reject_bad_values(tmp_path):
    assert parse_origin("47.1, 8.2, 400") == Origin(47.1, 8.2, 400.0)
    for bad, why in (("47,8", "LAT,LON,ALT"), ("a,b,c", "numbers"), ("95,8,400", "latitude"),
                     ("47,200,400", "longitude"), ("47,8,1e6", "altitude"),
                     ("nan,8,400", "latitude")):
        with pytest.raises(ValueError, match=why):
            parse_origin(bad)
    from orchestrator.scenario.parser import parse_scenario
    from orchestrator.scenario.reader import ScenarioError

    sc = parse_scenario({**BASE, "origin": [46.5, 7.5, 1500.0]})
    assert sc.origin == (46.5, 7.5, 1500.0)
    assert parse_scenario(BASE).origin is None
    for bad, why in (([46.5, 7.5], "3 numbers"), ([95.0, 7.5, 0.0], "latitude"),
                     (["x", 1, 2], "numbers"), ([1.0, 2.0, 20000.0], "altitude")):
        with pytest.raises(ScenarioError, match=why):
            parse_scenario({**BASE, "origin": bad})
    # the CLI takes the scenario's origin; --origin wins over it
    sc_file = tmp_path / "here.toml"
    sc_file.write_text('name = "here"\nairframe = "paper_hexacopter"\nduration = 1.0\n'
                       'origin = [46.5, 7.5, 1500.0]\n[reference.position]\nz = -3.0\n')
    gcs = f"udpout:127.0.0.1:{free_port()}"
    for extra, want in (([], "46.5000000, 7.5000000, 1500.00 m AMSL"),
                        (["--origin=-33.9,151.2,40"], "-33.9000000, 151.2000000, 40.00 m")):
        r = subprocess.run([sys.executable, "-m", "orchestrator.cli", "fly", str(sc_file),
                            "--gcs", gcs, "--duration", "0.05", *extra], cwd=ROOT,
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and want in r.stdout, r
    # the CLI: a bad --origin is an error message and exit status, not a traceback
    r = subprocess.run([sys.executable, "-m", "orchestrator.cli", "fly", "--origin", "95,8,4",
                        "--duration", "0.1"], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode != 0 and "latitude" in r.stderr and "Traceback" not in r.stderr, r


# -- pymavlink over UDP ------------------------------------------------------------------

class Flight(harness.Flight):
    def __init__(self, origin=None, speed=4.0):
        # these tests are about where the vehicle goes, not setpoint loss: a test process
        # stalled by a busy host, or a run of refused setpoints (which refresh nothing),
        # must not lose OFFBOARD (at speed 4, 1 s simulated is 0.25 s wall): the longest
        # timeout the parameter allows, set as `fullpose fly --limit` does
        super().__init__(speed, bridge_parameters={"FPB_SP_TIMEOUT": 60.0},
                         **({} if origin is None else {"origin": origin}))

    def command(self, cmd, *params, expect=0):
        return super().command(cmd, *params, expect=expect)

    def local(self, x, y, z, yaw=0.0, frame=1, mask=POS_ONLY):
        self.gcs.mav.set_position_target_local_ned_send(0, 1, 1, frame, mask, x, y, z,
                                                        0, 0, 0, 0, 0, 0, yaw, 0)

    def global_int(self, lat, lon, alt, frame, yaw=0.0, mask=POS_ONLY):
        self.gcs.mav.set_position_target_global_int_send(
            0, 1, 1, frame, mask, round(lat * 1e7), round(lon * 1e7), alt, 0, 0, 0, 0, 0, 0,
            yaw, 0)

    def settle(self, seconds, send):
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            send()
            while (m := self.gcs.recv_match(blocking=False)) is not None:
                if m.get_type() == "STATUSTEXT":
                    self.texts.append(m.text)
            time.sleep(0.02)

    def reach(self, want, send, tol=0.02, timeout=40.0):
        """Keep sending until the vehicle has stayed within tol of want for 2 s."""
        deadline = time.monotonic() + timeout
        since = None
        got = None
        while time.monotonic() < deadline:
            got = self.pos(send)
            if math.dist(got, want) < tol:
                since = since or time.monotonic()
                if time.monotonic() - since > 2.0:
                    return got
            else:
                since = None
        raise AssertionError(f"{want} not held: at {got}; {self.bridge.events[-5:]}")

    def pos(self, send):
        lp = self.wait("LOCAL_POSITION_NED", during=send)
        return (lp.x, lp.y, lp.z)


def pace(send, period=0.05):
    """``send``, at most once per ``period`` s of wall time (20 Hz: a client's stream)."""
    last = [-math.inf]

    def run():
        now = time.monotonic()
        if now - last[0] >= period:
            last[0] = now
            send()
    return run


flight = harness.flight_fixture(Flight)


def test_global_telemetry_home_battery_and_sensor_bits(flight):
    f = flight
    lat0, lon0, alt0 = PX4_SITL_HOME
    g = f.wait("GLOBAL_POSITION_INT")
    # the vehicle starts hovering 3 m above the origin (= home)
    assert abs(g.lat - round(lat0 * 1e7)) <= 1 and abs(g.lon - round(lon0 * 1e7)) <= 1, g
    assert abs(g.alt - (alt0 + 3.0) * 1000) < 20 and abs(g.relative_alt - 3000) < 20, g
    assert g.hdg < 36000 and abs(g.vz) < 10
    gps = f.wait("GPS_RAW_INT")
    assert gps.fix_type == mavutil.mavlink.GPS_FIX_TYPE_3D_FIX and gps.satellites_visible >= 6
    assert (gps.eph, gps.epv, gps.h_acc, gps.v_acc) == (70, 110, 900, 1780)  # PX4 SITL's
    f.command(512, mavutil.mavlink.MAVLINK_MSG_ID_HOME_POSITION)  # REQUEST_MESSAGE
    home = f.wait("HOME_POSITION", 3.0)
    assert (home.latitude, home.longitude, home.altitude) == (
        round(lat0 * 1e7), round(lon0 * 1e7), round(alt0 * 1000))
    # the older dedicated request (QGroundControl and MAVSDK send it): the same message
    f.command(mavutil.mavlink.MAV_CMD_GET_HOME_POSITION)
    again = f.wait("HOME_POSITION", 3.0)
    assert (again.latitude, again.longitude, again.altitude) == (
        home.latitude, home.longitude, home.altitude)
    origin = f.wait("GPS_GLOBAL_ORIGIN", 15.0)  # 0.1 Hz simulated, as PX4
    assert origin.latitude == home.latitude and origin.altitude == home.altitude
    hud = f.wait("VFR_HUD")
    assert abs(hud.alt - (alt0 + 3.0)) < 0.05 and abs(hud.climb) < 0.1
    alt = f.wait("ALTITUDE")
    assert abs(alt.altitude_relative - 3.0) < 0.05 and abs(alt.altitude_amsl - alt0 - 3) < 0.05
    st = f.wait("SYSTEM_TIME")
    assert abs(st.time_unix_usec / 1e6 - time.time()) < 5 and st.time_boot_ms > 0
    bat = f.wait("BATTERY_STATUS")
    volts = [v for v in bat.voltages if v != 65535]
    assert len(volts) == 4 and 16.0 < sum(volts) / 1000 <= 16.8, bat
    assert 0 < bat.current_battery < 6000 and 90 <= bat.battery_remaining <= 100, bat
    sys_ = f.wait("SYS_STATUS")
    assert sys_.voltage_battery != 65535 and 16000 < sys_.voltage_battery <= 16800, sys_
    for name in ("SENSOR_3D_GYRO", "SENSOR_3D_ACCEL", "SENSOR_3D_MAG", "SENSOR_GPS",
                 "SENSOR_ABSOLUTE_PRESSURE", "PREARM_CHECK", "SENSOR_BATTERY"):
        bit = getattr(mavutil.mavlink, "MAV_SYS_STATUS_" + name)
        for field in ("present", "enabled", "health"):
            assert getattr(sys_, f"onboard_control_sensors_{field}") & bit, (name, field)
    fence = mavutil.mavlink.MAV_SYS_STATUS_GEOFENCE
    assert not sys_.onboard_control_sensors_present & fence
    assert sys_.onboard_control_sensors_health & fence  # MAVProxy: no "fence breach"
    odo = f.wait("ODOMETRY")
    assert (odo.frame_id, odo.child_frame_id) == (mavutil.mavlink.MAV_FRAME_LOCAL_NED,
                                                   mavutil.mavlink.MAV_FRAME_BODY_FRD)


def test_global_int_setpoints_in_both_altitude_frames_and_terrain_refused(flight):
    f = flight
    o = Origin()
    f.command(400, 1)
    f.local(0.0, 0.0, -3.0)
    f.command(176, 1, 6, 0)  # OFFBOARD
    # 1.2 m north, 0.7 m west of the origin (computed by the oracle), 4.5 m AMSL above it
    m, n = radii(o.lat)
    lat = o.lat + math.degrees(1.2 / (m + o.alt))
    lon = o.lon + math.degrees(-0.7 / ((n + o.alt) * math.cos(math.radians(o.lat))))
    amsl = lambda: f.global_int(lat, lon, o.alt + 4.5, 5)  # noqa: E731  GLOBAL_INT: AMSL
    f.reach((1.2, -0.7, -4.5), amsl)
    relative = lambda: f.global_int(lat, lon, 2.5, 6)  # noqa: E731  RELATIVE_ALT: above home
    f.reach((1.2, -0.7, -2.5), relative)
    # each refused setpoint is sent until its reason arrives, as a client streams setpoints
    # (one datagram may wait behind the stream above, or be dropped, on a busy host)
    def refused(send, fragment):
        f.wait("STATUSTEXT", 10.0, lambda t: "rejected" in t.text and fragment in t.text,
               during=pace(send))

    refused(lambda: f.global_int(lat, lon, 2.5, 11), "terrain")
    refused(lambda: f.global_int(lat, lon, 2.5, 3), "frame 3")  # the float frame
    refused(lambda: f.global_int(lat + 0.01, lon, 2.5, 6), "above")  # 1.1 km: > FPB_SP_XY_MAX
    assert math.dist(f.pos(lambda: f.global_int(lat, lon, 2.5, 6)), (1.2, -0.7, -2.5)) < 0.05


def test_body_offset_ned_is_an_offset_in_the_body_frame(flight):
    f = flight
    yaw = math.pi / 2  # facing east: body forward = east
    f.command(400, 1)
    hold = lambda: f.local(0.0, 0.0, -3.0, yaw=yaw, mask=POS_YAW)  # noqa: E731
    hold()
    f.command(176, 1, 6, 0)
    deadline = time.monotonic() + 10.0  # the turn takes ~4 s simulated (1 s wall at 4x)
    while (abs(f.wait("ATTITUDE", during=hold).yaw - yaw) >= 0.01
           and time.monotonic() < deadline):
        pass
    assert abs(f.wait("ATTITUDE", during=hold).yaw - yaw) < 0.01
    before = f.pos(hold)
    # once: 1 m forward, 0.5 m right (= south), 0.4 m down in the body frame; then only the
    # attitude channel refreshes the link (it leaves the latched position alone)
    f.local(1.0, 0.5, 0.4, frame=9, mask=POS_ONLY)
    keep = lambda: f.gcs.mav.set_attitude_target_send(  # noqa: E731
        0, 1, 1, ATT_ONLY, euler_to_quat(0.0, 0.0, yaw), 0, 0, 0, 0.5, [0.0, 0.0, 0.0])
    f.reach((before[0] - 0.5, before[1] + 1.0, before[2] + 0.4), keep)


# -- MAVSDK --------------------------------------------------------------------------------

@pytest.mark.clients
def test_mavsdk_position_home_health_battery_and_set_position_global():
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.offboard import Offboard, PositionGlobalYaw
    from mavsdk.plugins.telemetry import Telemetry

    origin = Origin(46.518, 6.566, 400.0)  # not the default: the option is really used
    with harness.mavsdk_session(origin=origin) as (bridge, system, plugins):
        action, offboard, telemetry = Action(system), Offboard(system), Telemetry(system)
        plugins += [action, offboard, telemetry]
        seen = {}
        telemetry.subscribe_position(lambda p, _: seen.update(position=p))
        telemetry.subscribe_home(lambda p, _: seen.update(home=p))
        telemetry.subscribe_health_all_ok(lambda ok, _: seen.update(ok=ok))
        telemetry.subscribe_battery(lambda b, _: seen.update(battery=b))
        telemetry.subscribe_heading(lambda h, _: seen.update(heading=h))
        telemetry.subscribe_velocity_ned(lambda v, _: seen.update(velocity=v))
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and not (
                seen.get("ok") and {"position", "home", "battery", "heading",
                                     "velocity"} <= seen.keys()
                and math.isfinite(seen["battery"].current_battery_a)):  # BATTERY_STATUS
            time.sleep(0.1)
        assert seen.get("ok") is True, f"health_all_ok never true: {telemetry.health()}"
        p, h, b = seen["position"], seen["home"], seen["battery"]
        assert abs(p.latitude_deg - origin.lat) < 1e-6 and abs(p.longitude_deg - origin.lon) < 1e-6
        assert abs(p.absolute_altitude_m - 403.0) < 0.05 and abs(p.relative_altitude_m - 3) < 0.05
        assert abs(h.latitude_deg - origin.lat) < 1e-7 and abs(h.absolute_altitude_m - 400) < 1e-3
        assert 16.0 < b.voltage_v <= 16.8 and 90 <= b.remaining_percent <= 100, b
        assert 0 < b.current_battery_a < 60 and b.capacity_consumed_ah >= 0, b
        assert abs(seen["velocity"].down_m_s) < 0.1 and seen["heading"].heading_deg < 1.0
        print("MAVSDK:", p, h, b, telemetry.health(), sep="\n  ")
        action.arm()
        m, n = radii(origin.lat)
        lat = origin.lat + math.degrees(-0.8 / (m + origin.alt))
        lon = origin.lon + math.degrees(1.5 / ((n + origin.alt) *
                                               math.cos(math.radians(origin.lat))))
        target = PositionGlobalYaw(lat, lon, 3.8, 30.0, PositionGlobalYaw.AltitudeType.REL_HOME)
        offboard.set_position_global(target)
        offboard.start()
        want = (-0.8, 1.5, -3.8)
        deadline = time.monotonic() + 40.0
        err = math.inf
        while time.monotonic() < deadline:
            err = math.dist(bridge.session.state()["plant"]["pos"], want)
            if err < 0.02:
                time.sleep(2.0)  # settled, not passing through
                err = math.dist(bridge.session.state()["plant"]["pos"], want)
                if err < 0.02:
                    break
            time.sleep(0.1)
        assert err < 0.02, (bridge.session.state()["plant"]["pos"], bridge.events[-5:])
        yaw = math.degrees(bridge.session.state()["plant"]["euler"][2])
        assert abs(yaw - 30.0) < 1.0
        offboard.stop()
        action.disarm()


# -- MAVProxy ------------------------------------------------------------------------------

@pytest.mark.clients
def test_mavproxy_sees_the_global_position_and_no_fence_breach(tmp_path):
    # no GUI modules; the fence module is the one that printed "fence breach"
    out, fly_out = harness.mavproxy_session(
        tmp_path, ["--origin", "46.518,6.566,400", "--start", "air"], "fence",
        [("status GLOBAL_POSITION_INT", 1.0), ("status HOME_POSITION", 1.0)], settle=8.0)
    assert "origin              46.5180000, 6.5660000, 400.00 m AMSL" in fly_out, fly_out
    assert "Detected vehicle 1:1" in out, out
    assert "GLOBAL_POSITION_INT {" in out and "lat : 465180000" in out, out
    assert "relative_alt : 3000" in out or "relative_alt : 2999" in out, out
    assert "HOME_POSITION {" in out and "latitude : 465180000" in out, out
    assert "fence breach" not in out, out
