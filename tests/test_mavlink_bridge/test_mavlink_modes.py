"""Modes, identity and the small protocols, from clients' side: SET_MODE and DO_SET_MODE
with PX4's encoding, commands with NaN/inf params, MAVLink FTP, PING, mission / fence /
rally downloads, unknown parameters, and pymavlink replays of the requests
QGroundControl and MAVROS send on connect (their sources: docs/mavlink.md, "Identity").
The bridge runs in a thread at 4x speed on 127.0.0.1; every wait is bounded in wall
time and no bound depends on a fast machine (replies are immediate in the protocol)."""

import math
import os
import re
import struct
import time
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"

from helpers import mavlink_harness as harness
from helpers.mavlink_harness import POS_ONLY
from pymavlink.dialects.v20 import common as mav

pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

ROOT = Path(__file__).resolve().parents[2]
CUSTOM = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
OFFBOARD = 6 << 16
HOLD = (4 << 16) | (3 << 24)  # AUTO.LOITER
MANUAL = 1 << 16
RTL = (4 << 16) | (5 << 24)
LAND = (4 << 16) | (6 << 24)
PRECLAND = (4 << 16) | (9 << 24)
FOLLOW = (4 << 16) | (8 << 24)  # AUTO.FOLLOW_TARGET
FTP_HEADER = struct.Struct("<HBBBBBBI")



def param_value(pv):
    """A PARAM_VALUE's value as a client reads it: INT32 byte-wise (PX4's encoding, which
    AUTOPILOT_VERSION announces with MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)."""
    if pv.param_type == mav.MAV_PARAM_TYPE_INT32:
        return struct.unpack("<i", struct.pack("<f", pv.param_value))[0]
    return pv.param_value

class Ground(harness.Flight):
    """A bridge in a thread and one pymavlink client (system/component as given)."""

    def __init__(self, system=255, component=190, speed=4.0, dialect="common"):
        self._last_setpoint = -math.inf
        super().__init__(speed, system, component, dialect)

    def collect(self, seconds):
        out = []
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            m = self.gcs.recv_match(blocking=True, timeout=0.02)
            if m is not None:
                if m.get_type() == "STATUSTEXT":
                    self.texts.append(m.text)
                out.append(m)
        return out

    def text(self, fragment, timeout=5.0):
        if any(fragment in t for t in self.texts):
            return
        self.wait("STATUSTEXT", timeout, lambda m: fragment in m.text)

    def command(self, cmd, *params, expect=None, kind="long"):
        p = list(params) + [0.0] * (7 - len(params))
        if kind == "long":
            self.gcs.mav.command_long_send(1, 1, cmd, 0, *p)
        else:
            self.gcs.mav.command_int_send(1, 1, 0, cmd, 0, 0, *p[:4], int(p[4]), int(p[5]),
                                          p[6])
        ack = self.wait("COMMAND_ACK", 5.0, lambda m: m.command == cmd)
        assert (ack.target_system, ack.target_component) == self.src
        if expect is not None:
            assert ack.result == expect, ack
        return ack

    def setpoint(self):
        """A hold setpoint, at most one per 20 ms (50 Hz, as offboard examples stream)."""
        now = time.monotonic()
        if now - self._last_setpoint < 0.02:
            return
        self._last_setpoint = now
        self.gcs.mav.set_position_target_local_ned_send(0, 1, 1, 1, POS_ONLY, 0.0, 0.0, -3.0,
                                                        0, 0, 0, 0, 0, 0, 0.0, 0)

    def set_mode(self, custom_mode, base_mode=CUSTOM, during=None):
        """SET_MODE as MAVROS and QGroundControl send it; returns (ack, heartbeat or None)."""
        self.gcs.mav.set_mode_send(1, base_mode, custom_mode)
        ack = self.wait("COMMAND_ACK", 5.0, lambda m: m.command == 176, during=during)
        hb = None
        if ack.result == mav.MAV_RESULT_ACCEPTED:
            hb = self.wait("HEARTBEAT", 5.0, lambda m: m.custom_mode == custom_mode,
                           during=during)
        return ack, hb


@pytest.fixture
def ground():
    g = Ground()
    yield g
    g.close()


def test_set_mode_offboard_hold_and_refusals(ground):
    g = ground
    g.command(400, 1, expect=0)
    g.setpoint()
    ack, hb = g.set_mode(OFFBOARD, during=g.setpoint)
    assert ack.result == mav.MAV_RESULT_ACCEPTED and hb.base_mode & CUSTOM
    assert g.bridge.mode == "OFFBOARD"
    ack, hb = g.set_mode(HOLD)
    assert ack.result == mav.MAV_RESULT_ACCEPTED and g.bridge.mode == "HOLD"
    for custom, name in ((MANUAL, "MANUAL refused: needs sticks"),
                         (PRECLAND, "AUTO.PRECLAND refused: no landing target"),
                         (FOLLOW, "AUTO.FOLLOW_TARGET refused: not simulated")):
        ack, _ = g.set_mode(custom)
        assert ack.result == mav.MAV_RESULT_DENIED
        g.text(name)
    ack, _ = g.set_mode(OFFBOARD, base_mode=0)  # PX4's encoding needs the custom flag
    assert ack.result == mav.MAV_RESULT_DENIED
    g.text("no CUSTOM_MODE flag")
    hb = g.wait("HEARTBEAT", 5.0)
    assert hb.custom_mode == HOLD  # refusals change nothing
    assert g.thread.is_alive()


def test_do_set_mode_is_the_same_road(ground):
    g = ground
    g.command(176, CUSTOM, 1, 0, expect=mav.MAV_RESULT_DENIED)  # MANUAL
    g.text("MANUAL refused")
    g.command(176, CUSTOM, 3, 0, expect=mav.MAV_RESULT_ACCEPTED, kind="int")  # POSCTL
    g.wait("HEARTBEAT", 5.0, lambda m: (m.custom_mode >> 16) & 0xFF == 3)
    g.command(176, CUSTOM, 4, 3, expect=mav.MAV_RESULT_ACCEPTED)
    g.wait("HEARTBEAT", 5.0, lambda m: m.custom_mode == HOLD)
    g.command(176, CUSTOM, 6, 0, expect=mav.MAV_RESULT_TEMPORARILY_REJECTED)
    g.text("offboard refused: no recent setpoint")


def test_every_command_is_acked_including_nan_and_inf(ground):
    g = ground
    nan, inf = math.nan, math.inf
    g.command(176, CUSTOM, nan, 0, expect=mav.MAV_RESULT_DENIED)
    g.text("command 176 denied: param2 is nan")
    g.command(176, nan, 4, 3, expect=mav.MAV_RESULT_DENIED, kind="int")
    g.command(511, 30, inf, expect=mav.MAV_RESULT_DENIED)
    g.text("param2 is inf")
    g.command(512, nan, expect=mav.MAV_RESULT_DENIED)
    g.command(400, -inf, expect=mav.MAV_RESULT_DENIED)
    # NaN where the command does not use the param (reserved / "no change"): accepted
    g.command(400, 0, nan, nan, nan, nan, nan, nan, expect=mav.MAV_RESULT_ACCEPTED)
    g.command(512, 148, nan, nan, nan, nan, nan, nan, expect=mav.MAV_RESULT_ACCEPTED)
    g.wait("AUTOPILOT_VERSION", 5.0)
    g.command(31000, nan, inf, expect=mav.MAV_RESULT_UNSUPPORTED)  # MAV_CMD_USER_1
    g.command(31000, 1, kind="int", expect=mav.MAV_RESULT_UNSUPPORTED)
    assert g.thread.is_alive() and g.bridge.stats.ignored == 0


def ftp_request(g, seq, opcode, data=b"", session=0, offset=0):
    head = FTP_HEADER.pack(seq, session, opcode, len(data), 0, 0, 0, offset)
    g.gcs.mav.file_transfer_protocol_send(0, 1, 1, list((head + data).ljust(251, b"\0")))
    reply = g.wait("FILE_TRANSFER_PROTOCOL", 5.0,
                   lambda m: FTP_HEADER.unpack_from(bytes(m.payload))[0] == (seq + 1) & 0xFFFF)
    assert (reply.target_system, reply.target_component) == g.src
    raw = bytes(reply.payload)
    _, _, op, size, req, _, _, _ = FTP_HEADER.unpack_from(raw)
    return op, req, raw[FTP_HEADER.size:FTP_HEADER.size + size]


def test_ftp_is_answered_with_a_nak_at_once(ground):
    g = ground
    # MAVProxy's param module asks for @PARAM/param.pck (OpenFileRO) at connect
    op, req, data = ftp_request(g, 7, 4, b"@PARAM/param.pck\0")
    assert (op, req, data) == (129, 4, bytes([10]))  # NAK, FileNotFound
    assert ftp_request(g, 9, 3, b"/\0") == (129, 3, bytes([10]))  # ListDirectory
    assert ftp_request(g, 11, 5, session=3) == (129, 5, bytes([4]))  # Read: InvalidSession
    assert ftp_request(g, 13, 1, session=3) == (129, 1, bytes([4]))  # Terminate
    assert ftp_request(g, 15, 77) == (129, 77, bytes([7]))  # UnknownCommand
    assert ftp_request(g, 65535, 2) == (128, 2, b"")  # ResetSessions: ACK, seq wraps


def test_ping_is_answered_to_the_sender(ground):
    g = ground
    g.gcs.mav.ping_send(123456789, 42, 0, 0)
    pong = g.wait("PING", 5.0, lambda m: m.seq == 42)
    assert (pong.time_usec, pong.target_system, pong.target_component) == (123456789, 255, 190)
    g.gcs.mav.ping_send(1, 43, 1, 1)  # a reply to a ping of ours: not answered
    assert not [m for m in g.collect(1.0) if m.get_type() == "PING"]


def test_empty_mission_fence_rally_and_refused_upload(ground):
    g = ground
    for kind in (0, 1, 2):
        g.gcs.mav.mission_request_list_send(1, 1, kind)
        count = g.wait("MISSION_COUNT", 5.0, lambda m, k=kind: m.mission_type == k)
        assert count.count == 0 and (count.target_system, count.target_component) == g.src
        g.gcs.mav.mission_ack_send(1, 1, 0, kind)  # the client ends the download
    g.gcs.mav.mission_request_int_send(1, 1, 0, 0)
    ack = g.wait("MISSION_ACK", 5.0)
    assert ack.type == mav.MAV_MISSION_INVALID_SEQUENCE
    g.gcs.mav.mission_count_send(1, 1, 3, 0)
    assert g.wait("MISSION_REQUEST_INT", 5.0).seq == 0
    g.gcs.mav.mission_item_int_send(1, 1, 0, 2, 34, 0, 1, 5, 1, 0, 0, 0, 0, 0, 0)  # DO_ORBIT
    ack = g.wait("MISSION_ACK", 5.0)
    assert ack.type == mav.MAV_MISSION_UNSUPPORTED
    g.text("mission upload refused: item 0: orbits not supported")
    g.gcs.mav.mission_count_send(1, 1, 0, 1)  # clearing the fence: what we hold
    ack = g.wait("MISSION_ACK", 5.0)
    assert ack.type == mav.MAV_MISSION_ACCEPTED and ack.mission_type == 1
    g.gcs.mav.mission_clear_all_send(1, 1, 2)
    assert g.wait("MISSION_ACK", 5.0).type == mav.MAV_MISSION_ACCEPTED
    assert g.thread.is_alive() and g.bridge.stats.ignored == 0


def test_unknown_parameter_and_identity_parameters(ground):
    g = ground
    g.gcs.mav.param_request_read_send(1, 1, b"NO_SUCH_PARAM", -1)
    err = g.wait("PARAM_ERROR", 5.0)
    assert err.param_id == "NO_SUCH_PARAM" and err.error == mav.MAV_PARAM_ERROR_DOES_NOT_EXIST
    g.text("unknown param: NO_SUCH_PARAM")
    g.gcs.mav.param_request_read_send(1, 1, b"", 30000)
    assert g.wait("PARAM_ERROR", 5.0).param_index == 30000
    g.gcs.mav.param_request_read_send(1, 1, b"SYS_AUTOSTART", -1)
    pv = g.wait("PARAM_VALUE", 5.0, lambda m: m.param_id == "SYS_AUTOSTART")
    assert param_value(pv) == 4001
    g.gcs.mav.param_set_send(1, 1, b"SYS_AUTOSTART", 13000, mav.MAV_PARAM_TYPE_REAL32)
    pv = g.wait("PARAM_VALUE", 5.0, lambda m: m.param_id == "SYS_AUTOSTART")
    assert param_value(pv) == 4001  # read-only: the value in force


def test_actuator_control_target_is_told_unsupported_once(ground):
    g = ground
    for _ in range(20):
        g.gcs.mav.set_actuator_control_target_send(0, 0, 1, 1, [0.0] * 8)
        time.sleep(0.01)
    g.collect(1.0)
    told = [t for t in g.texts if "SET_ACTUATOR_CONTROL_TARGET not supported" in t]
    assert len(told) == 1, g.texts


def test_qgroundcontrol_connect_sequence_replayed():
    """InitialConnectStateMachine (src/Vehicle/InitialConnectStateMachine.cc): AUTOPILOT_
    VERSION, component metadata, standard modes, parameters, mission, fence, rally; then
    the flight-mode menu and the Hold / RTL / Land buttons (PX4FirmwarePlugin::
    setFlightMode, guidedModeRTL, guidedModeLand: SET_MODE).  The development dialect:
    AVAILABLE_MODES and CURRENT_MODE are not in the installed common.xml yet."""
    g = Ground(dialect="development")
    try:
        qgc_sequence(g)
    finally:
        g.close()


def qgc_sequence(g):
    g.gcs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    g.command(512, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, expect=0)
    ver = g.wait("AUTOPILOT_VERSION", 5.0)
    major, minor = ver.flight_sw_version >> 24, (ver.flight_sw_version >> 16) & 0xFF
    assert (major, minor) >= (1, 4) and ver.flight_sw_version != 0  # "supports PX4 Pro 1.4.1"
    # not OFFICIAL: no "not running latest stable" comparison with GitHub's releases
    assert ver.flight_sw_version & 0xFF != mav.FIRMWARE_VERSION_TYPE_OFFICIAL
    for bit in (mav.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE,
                mav.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY, mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT):
        assert ver.capabilities & bit
    assert not ver.capabilities & mav.MAV_PROTOCOL_CAPABILITY_FTP
    for msg_id in (397, 395):  # COMPONENT_METADATA, COMPONENT_INFORMATION
        assert g.command(512, msg_id).result != mav.MAV_RESULT_ACCEPTED  # answered: not here
    # StandardModes::request: AVAILABLE_MODES, all of them (param2 0), one per mode
    g.command(512, 435, 0, expect=0)
    listed, total = {}, 1
    while len(listed) < total:
        m = g.wait("AVAILABLE_MODES", 5.0)
        total = m.number_modes
        listed[m.mode_index] = m
    assert sorted(listed) == list(range(1, total + 1))  # done at mode_index == number_modes
    selectable = {m.custom_mode for m in listed.values() if not m.properties & 2}
    takeoff, mission = (4 << 16) | (2 << 24), (4 << 16) | (4 << 24)
    # the modes flown here
    assert selectable == {HOLD, 3 << 16, OFFBOARD, takeoff, LAND, RTL, mission}
    assert {MANUAL, PRECLAND} <= {m.custom_mode for m in listed.values()}  # not selectable
    g.command(512, 435, total + 1, expect=mav.MAV_RESULT_DENIED)
    g.command(512, 436, expect=0)
    assert g.wait("CURRENT_MODE", 5.0).custom_mode == HOLD
    g.gcs.mav.param_request_list_send(1, 1)
    names = {}
    deadline = time.monotonic() + 20.0
    total = None
    while time.monotonic() < deadline and (total is None or len(names) < total):
        pv = g.wait("PARAM_VALUE", 5.0)
        names[pv.param_id] = param_value(pv)
        total = pv.param_count
    assert len(names) == total
    assert names["SYS_AUTOSTART"] != 0  # AirframeComponent::setupComplete
    assert names["COM_RC_IN_MODE"] == 4 and names["SYS_HITL"] == 0
    for kind in (0, 1, 2):  # MissionManager, GeoFenceManager, RallyPointManager
        g.gcs.mav.mission_request_list_send(1, 1, kind)
        assert g.wait("MISSION_COUNT", 5.0, lambda m, k=kind: m.mission_type == k).count == 0
        g.gcs.mav.mission_ack_send(1, 1, 0, kind)
    ack, hb = g.set_mode(HOLD)  # "Hold" from the menu
    assert ack.result == 0 and hb is not None
    for custom, text in ((RTL, "AUTO.RTL refused: disarmed"),
                         (LAND, "AUTO.LAND refused: disarmed")):
        ack, _ = g.set_mode(custom)
        assert ack.result == mav.MAV_RESULT_DENIED
        g.text(text)
    # the Takeoff button (PX4FirmwarePlugin::guidedModeTakeoff): NAV_TAKEOFF, NaN yaw/lat/lon;
    # disarmed it is refused with the reason (flown from the ground: test_mavlink_ground.py)
    nan = math.nan
    g.command(22, -1, 0, 0, nan, nan, nan, 500.0, expect=mav.MAV_RESULT_DENIED)
    g.text("takeoff refused: disarmed")
    assert g.thread.is_alive() and g.bridge.stats.ignored == 0


@pytest.mark.clients
def test_mavros_connect_and_offboard_sequence_replayed():
    """MAVROS (mavros/src/plugins/): sys_status autopilot_version_cb sends REQUEST_AUTOPILOT_
    CAPABILITIES (param1 1, broadcast first); param param_request_list; waypoint, geofence
    and rallypoint mission_request_list; then the offboard example: setpoints streamed,
    set_mode_cb's SET_MODE (custom flag | armed flag from the last HEARTBEAT), arming."""
    g = Ground(system=1, component=mav.MAV_COMP_ID_ONBOARD_COMPUTER)
    try:
        g.gcs.mav.heartbeat_send(mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID,
                                 0, 0, 0)
        g.gcs.mav.command_long_send(0, 0, 520, 0, 1, 0, 0, 0, 0, 0, 0)  # broadcast
        ack = g.wait("COMMAND_ACK", 5.0, lambda m: m.command == 520)
        assert ack.result == 0
        g.wait("AUTOPILOT_VERSION", 5.0)
        g.gcs.mav.param_request_list_send(1, 1)
        g.wait("PARAM_VALUE", 5.0)
        for kind in (0, 1, 2):
            g.gcs.mav.mission_request_list_send(1, 1, kind)
            assert g.wait("MISSION_COUNT", 5.0,
                          lambda m, k=kind: m.mission_type == k).count == 0
            g.gcs.mav.mission_ack_send(1, 1, 0, kind)
        g.gcs.mav.timesync_send(0, 1000)
        assert g.wait("TIMESYNC", 5.0, lambda m: m.ts1 == 1000).tc1 >= 0
        stream_until = time.monotonic() + 1.0  # the example streams 100 setpoints first
        while time.monotonic() < stream_until:
            g.setpoint()
            g.collect(0.005)  # keep reading: a full socket buffer would drop the answers
        ack, hb = g.set_mode(OFFBOARD, during=g.setpoint)  # disarmed: no armed flag
        assert ack.result == 0 and hb is not None
        g.command(400, 1, expect=0)
        hb = g.wait("HEARTBEAT", 5.0, lambda m: m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED,
                    during=g.setpoint)
        assert hb.custom_mode == OFFBOARD
        # set_mode again while armed: MAVROS copies SAFETY_ARMED into base_mode
        ack, hb = g.set_mode(HOLD, base_mode=CUSTOM | mav.MAV_MODE_FLAG_SAFETY_ARMED)
        assert ack.result == 0 and hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
    finally:
        g.close()


@pytest.mark.clients
def test_mavproxy_changes_mode_with_long_do_set_mode(tmp_path):
    out, _ = harness.mavproxy_session(
        tmp_path, ["--duration", "60"], "ftp,param,cmdlong",
        [("long DO_SET_MODE 1 3 0", 2.0), ("long DO_SET_MODE 1 1 0", 2.0)],
        setup=["ftp set debug 1"])  # print the FTP outcome
    assert "Detected vehicle 1:1" in out, out
    # the param module's FTP download of @PARAM/param.pck is NAKed at once: no retry, no
    # timeout, and the parameters come by PARAM_REQUEST_LIST instead
    assert "ftp open failed" in out, out
    assert "FTP: retry" not in out and "timed out" not in out, out
    received = re.search(r"Received (\d+) parameters", out)
    assert received and int(received.group(1)) > 0, out
    assert "Mode POSCTL" in out, out  # PX4 POSCTL, named by pymavlink's PX4 mode map
    assert "MANUAL refused: needs sticks" in out, out
    assert "DO_SET_MODE" in out and "DENIED" in out, out


@pytest.mark.clients
def test_mavsdk_downloads_empty_plans_and_changes_mode():
    from mavsdk.plugins.action import Action, ActionError
    from mavsdk.plugins.mission_raw import MissionRaw
    from mavsdk.plugins.telemetry import FlightMode, Telemetry

    with harness.mavsdk_session() as (bridge, system, plugins):
        mission, action, telemetry = MissionRaw(system), Action(system), Telemetry(system)
        plugins += [mission, action, telemetry]
        assert list(mission.download_mission()) == []
        assert list(mission.download_geofence()) == []
        assert list(mission.download_rallypoints()) == []
        action.hold()  # DO_SET_MODE AUTO.LOITER: accepted
        deadline = time.monotonic() + 10.0
        while telemetry.flight_mode() != FlightMode.HOLD and time.monotonic() < deadline:
            time.sleep(0.05)
        assert telemetry.flight_mode() == FlightMode.HOLD
        with pytest.raises(ActionError):  # MAVSDK sends DO_SET_MODE AUTO.RTL: disarmed
            action.return_to_launch()
        assert any("AUTO.RTL refused: disarmed" in t for t in bridge.events), bridge.events
