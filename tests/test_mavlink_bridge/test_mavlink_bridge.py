"""The bridge against pymavlink clients on 127.0.0.1: full pose, parameters, commands,
failsafe, signing and bounded fuzz.  The bridge runs in a thread at 4x speed; every
wait is bounded in wall time."""

import itertools
import math
import os
import socket
import time

import pytest

os.environ["MAVLINK20"] = "1"

from helpers import mavlink_harness as harness
from helpers.mavlink_harness import ATT_ONLY, POS_ONLY
from pymavlink import mavutil

from controller.gains_defaults import controller_parameters

pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

KEY = bytes(range(32))


class Flight(harness.Flight):
    """A bridge in a thread and a pymavlink ground station listening for it."""

    def __init__(self, speed=4.0, key=None, duration=60.0):
        super().__init__(speed, signing_key=key, duration=duration)


flight = harness.flight_fixture(Flight)


stream = harness.stream


def test_full_pose_from_position_and_attitude_setpoints(flight):
    f = flight
    f.command(400, 1, expect=0)  # arm
    target_pos, target_att = (0.8, -0.4, -3.6), (math.radians(8), math.radians(-5), 0.05)

    def send():
        f.position(*target_pos, yaw=target_att[2])
        f.attitude(*target_att)

    send()
    f.offboard(expect=0)
    stream(f, 4.0, send)  # 16 s simulated
    hb = f.wait("HEARTBEAT", 3.0, lambda m: (m.custom_mode >> 16) & 0xFF == 6, during=send)
    assert hb.base_mode & 128  # armed
    assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4
    lp = f.wait("LOCAL_POSITION_NED", during=send)
    att = f.wait("ATTITUDE", during=send)
    err = math.dist((lp.x, lp.y, lp.z), target_pos)
    assert err < 0.05, (lp, err)
    for got, want in zip((att.roll, att.pitch, att.yaw), target_att, strict=True):
        assert abs(got - want) < math.radians(1.0), att
    tgt = f.wait("ATTITUDE_TARGET", during=send)  # echoes the commanded feasible attitude mu_c
    assert abs(tgt.q[1] - math.sin(target_att[0] / 2)) < 0.02
    f.wait("POSITION_TARGET_LOCAL_NED", 3.0, lambda m: abs(m.x - target_pos[0]) < 1e-4,
           during=send)
    for kind in ("ATTITUDE_QUATERNION", "ODOMETRY", "SYS_STATUS", "EXTENDED_SYS_STATE",
                 "ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW"):
        f.wait(kind)
    stats = f.bridge.stats
    assert stats.achieved_speed > 3.5


def test_offboard_refused_without_setpoint_then_failsafe_on_loss(flight):
    f = flight
    f.command(400, 1, expect=0)
    f.offboard(expect=mavutil.mavlink.MAV_RESULT_TEMPORARILY_REJECTED)
    f.position(0.5, 0.0, -3.0)
    f.offboard(expect=0)
    stream(f, 1.0, lambda: f.position(0.5, 0.0, -3.0))
    assert f.bridge.mode == "OFFBOARD"
    # stop streaming: 1 s simulated (PX4's COM_OF_LOSS_T) = 0.25 s wall at 4x
    hb = f.wait("HEARTBEAT", 3.0, lambda m: (m.custom_mode >> 16) & 0xFF == 4)
    assert (hb.custom_mode >> 24) & 0xFF == 3  # AUTO.LOITER
    f.wait("STATUSTEXT", 2.0, lambda m: "offboard lost" in m.text) if not any(
        "offboard lost" in t for t in f.texts) else None
    x_hold = f.bridge.ref.pos[0]
    time.sleep(1.0)
    lp = f.wait("LOCAL_POSITION_NED")
    assert abs(lp.x - x_hold) < 0.05  # holds where it was


def test_parameters_round_trip_and_unsupported_command(flight):
    f = flight
    f.gcs.mav.param_request_read_send(1, 1, b"FP_KPOS_D1", -1)
    pv = f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "FP_KPOS_D1")
    shipped = controller_parameters()["K_pos_D[1]"]  # the synthesis' result file
    assert pv.param_value == pytest.approx(shipped, rel=1e-6)
    f.gcs.mav.param_set_send(1, 1, b"FP_KPOS_D1", 1.8, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
    pv = f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "FP_KPOS_D1")
    assert pv.param_value == pytest.approx(1.8, rel=1e-6)
    assert f.bridge.session.ctrl_inst.get("K_pos_D[1]") == pytest.approx(1.8, rel=1e-6)
    # out of range: refused, the old value reported, the loop flies on
    f.gcs.mav.param_set_send(1, 1, b"FP_KPOS_A1", 1.5, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
    pv = f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "FP_KPOS_A1")
    assert pv.param_value == pytest.approx(controller_parameters()["K_pos_A[1]"], rel=1e-6)
    f.gcs.mav.param_request_list_send(1, 1)
    pv = f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "FPB_SP_TIMEOUT")
    assert pv.param_count == len(f.bridge.params)
    # a takeoff needs the vehicle armed (tests/test_mavlink_bridge/test_mavlink_ground.py flies it)
    f.command(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, expect=mavutil.mavlink.MAV_RESULT_DENIED)
    f.command(mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 32, 1e6, expect=0)
    assert f.bridge.endpoints[0].intervals[32] == pytest.approx(1.0)
    f.command(mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE, 148, expect=0)
    f.wait("AUTOPILOT_VERSION")
    f.gcs.mav.timesync_send(0, 12345)
    f.wait("TIMESYNC", 3.0, lambda m: m.ts1 == 12345 and m.tc1 > 0)
    t = f.bridge.session.time
    f.wait("HEARTBEAT")
    assert f.bridge.session.time > t


def test_bad_setpoints_rejected_with_a_reason(flight):
    f = flight
    f.command(400, 1, expect=0)
    f.position(0.0, 0.0, -3.0)
    f.offboard(expect=0)
    f.position(float("nan"), 0.0, -3.0)
    f.wait("STATUSTEXT", 3.0, lambda m: "rejected" in m.text and "not finite" in m.text)
    f.position(1e6, 0.0, -3.0)
    f.wait("STATUSTEXT", 3.0, lambda m: "rejected" in m.text and "above" in m.text)
    f.gcs.mav.set_attitude_target_send(0, 1, 1, ATT_ONLY, [float("inf"), 0, 0, 0], 0, 0, 0,
                                       0.5, [0.0, 0.0, 0.0])
    f.wait("STATUSTEXT", 3.0, lambda m: "ATTITUDE_TARGET rejected" in m.text)
    # wrong target system: ignored silently
    f.gcs.mav.set_position_target_local_ned_send(0, 7, 1, 1, POS_ONLY, 5, 5, -3, 0, 0, 0, 0,
                                                 0, 0, 0, 0)
    stream(f, 0.5, lambda: f.position(0.0, 0.0, -3.0))
    assert abs(f.bridge.ref.pos[0]) < 1e-9


def test_fuzz_and_flood_keep_the_pace():
    f = Flight(speed=1.0, duration=60.0)
    try:
        f.command(400, 1, expect=0)
        f.position(0.3, 0.0, -3.0)
        f.offboard(expect=0)
        dest = f.bridge.endpoints[0].sock.getsockname()
        datagrams = harness.fuzz_datagrams(f.gcs.mav)
        raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sent = 0
        t0 = time.monotonic()
        lag0 = f.bridge.stats.max_lag
        while time.monotonic() - t0 < 4.0 and sent < 40000:
            for data in itertools.islice(datagrams, 50):
                raw.sendto(data, dest)
                sent += 1
            time.sleep(0.001)
        raw.close()
        wall = time.monotonic() - t0
        stream(f, 1.0, lambda: f.position(0.3, 0.0, -3.0))
        stats = f.bridge.stats
        print(f"\nfuzz: {sent} datagrams in {wall:.2f} s ({sent / wall:.0f}/s); bridge handled "
              f"{stats.datagrams}, peak {stats.max_rx_rate:.0f}/s, malformed {stats.malformed}; "
              f"max lag {1e3 * stats.max_lag:.1f} ms (before {1e3 * lag0:.1f} ms)")
        assert sent >= 5000
        assert stats.datagrams >= 5000
        assert stats.malformed > 500
        assert stats.max_lag < 0.1  # never more than 100 ms behind wall time
        assert f.bridge.mode == "OFFBOARD"
        lp = f.wait("LOCAL_POSITION_NED")
        assert abs(lp.x - 0.3) < 0.05 and abs(lp.z + 3.0) < 0.05
        assert f.thread.is_alive()
    finally:
        f.close()


def signed_client(port, key, stamp=None, link_id=0, system=255):
    c = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=system,
                                   source_component=190, dialect="common")
    if key is not None:
        c.setup_signing(key, sign_outgoing=True, initial_timestamp=stamp, link_id=link_id)
    return c


def test_signing_accepts_signed_and_refuses_the_rest():
    f = Flight(key=KEY)
    try:
        dest = f.bridge.endpoints[0].sock.getsockname()[1]
        refused = f.bridge.signing.refused
        # our own telemetry is signed
        hb = f.wait("HEARTBEAT")
        assert hb.get_signed() or hb._header.incompat_flags & 1
        unsigned = signed_client(dest, None)
        unsigned.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        unsigned.mav.heartbeat_send(6, 8, 0, 0, 0)  # allowed unsigned, no effect
        wrong = signed_client(dest, bytes(32 - i for i in range(32)), system=250)
        wrong.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        stale_stamp = int((time.time() - 1420070400 - 600) * 100_000)
        stale = signed_client(dest, KEY, stamp=stale_stamp, system=251)
        stale.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        time.sleep(0.5)
        assert not f.bridge.armed
        assert refused.get("unsigned", 0) >= 1
        assert refused.get("bad signature", 0) >= 1
        assert refused.get("stale timestamp", 0) >= 1
        good = signed_client(dest, KEY, system=252)
        good.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        deadline = time.monotonic() + 3
        while not f.bridge.armed and time.monotonic() < deadline:
            time.sleep(0.02)
        assert f.bridge.armed
        # replay: the very same signed datagram again (disarm), sent twice
        msg = good.mav.command_long_encode(1, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0)
        buf = msg.pack(good.mav)
        raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        raw.sendto(buf, ("127.0.0.1", dest))
        deadline = time.monotonic() + 3
        while f.bridge.armed and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not f.bridge.armed  # the first copy is genuine
        good.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)  # arm again
        time.sleep(0.3)
        assert f.bridge.armed
        raw.sendto(buf, ("127.0.0.1", dest))  # the replayed disarm
        time.sleep(0.3)
        assert f.bridge.armed
        assert refused.get("replayed", 0) >= 1
        # SETUP_SIGNING, even signed, is refused while armed (and with --signing-key: see
        # tests/test_mavlink_bridge/test_mavlink_safety.py for the policy)
        new_key = bytes([7] * 32)
        good.mav.setup_signing_send(1, 1, list(new_key), 0)
        time.sleep(0.3)
        assert f.bridge.signing.key == KEY
        assert any("SETUP_SIGNING refused: armed" in t for t in f.bridge.events)
        raw.close()
        for c in (unsigned, wrong, stale, good):
            c.close()
        assert f.thread.is_alive()
    finally:
        f.close()
