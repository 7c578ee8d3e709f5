"""Safety a flight needs (issue 15, item 4), against a running bridge over real UDP:
SETUP_SIGNING policy, parameter ranges (the FMU's own), the design-model stability guard,
typed (INT32, byte-wise) parameters with pymavlink and MAVSDK, setpoint range checks,
setpoint loss (hold, PX4's timeout) and the infeasible-attitude report.  Every refusal is
checked by its STATUSTEXT; every test checks that the vehicle keeps flying."""

import math
import os
import socket
import struct
import threading
import time

import numpy as np
import pytest
from helpers import mavlink_harness as harness
from helpers.mavlink_harness import free_port

os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav

from controller import hinf
from controller.gains_defaults import controller_parameters
from mavlink_bridge import stability
from mavlink_bridge.bridge import Bridge, BridgeConfig

pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

REAL32, INT32 = 9, 6
VEL_ONLY = 0b0000_1101_1100_0111  # vx, vy, vz, yaw used


YAW_USED = 0b0000_1001_1111_1000  # x, y, z, yaw used


class Flight(harness.Flight):
    """A bridge (BridgeConfig of our own) in a thread and a pymavlink ground station."""


stream = harness.stream


flight = harness.flight_fixture(Flight)


def text_seen(f, fragment, timeout=3.0):
    if not any(fragment in t for t in f.texts):
        f.wait("STATUSTEXT", timeout, lambda m: fragment in m.text)


def fly_offboard(f, pos=(0.3, 0.0, -3.0)):
    f.command(400, 1, expect=0)
    f.position(*pos)
    f.offboard(expect=0)
    stream(f, 0.5, lambda: f.position(*pos))
    assert f.bridge.mode == "OFFBOARD"


def still_flying(f, pos=(0.3, 0.0, -3.0), tol=0.05):
    stream(f, 0.5, lambda: f.position(*pos))
    lp = f.wait("LOCAL_POSITION_NED")
    assert abs(lp.x - pos[0]) < tol and abs(lp.z - pos[2]) < tol, lp
    assert f.bridge.mode == "OFFBOARD" and f.thread.is_alive()


def param_value(f, name):
    f.gcs.mav.param_request_read_send(1, 1, name.encode(), -1)
    return f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == name)


def param_set(f, name, value, kind=REAL32):
    raw = struct.unpack("<f", struct.pack("<i", value))[0] if kind == INT32 else value
    f.gcs.mav.param_set_send(1, 1, name.encode(), raw, kind)
    return f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == name)


def as_int(pv):
    assert pv.param_type == INT32
    return struct.unpack("<i", struct.pack("<f", pv.param_value))[0]


# -- signing ------------------------------------------------------------------------------

def test_setup_signing_refused_while_armed_and_from_anyone_unauthenticated():
    """No key in force and no one-time key: SETUP_SIGNING is refused whoever sends it (the
    issue's spoof: any local process could name itself the setup link)."""
    f = Flight()
    stranger = mavutil.mavlink_connection(f"udpout:127.0.0.1:{f.bridge_port()}",
                                          source_system=254, source_component=1,
                                          dialect="common")
    try:
        fly_offboard(f)
        f.gcs.mav.setup_signing_send(1, 1, [9] * 32, 0)  # unsigned, while armed
        text_seen(f, "SETUP_SIGNING refused: armed")
        still_flying(f)  # setpoints still accepted, offboard kept
        f.command(400, 0, expect=0)  # disarm still works
        for sender in (f.gcs, stranger):
            sender.mav.setup_signing_send(1, 1, [9] * 32, 0)
            text_seen(f, "SETUP_SIGNING refused: no --signing-setup-key")
        assert not f.bridge.signing.enabled
    finally:
        stranger.close()
        f.close()


def test_setup_signing_with_the_one_time_key_then_only_on_the_signed_link():
    setup, new, other = bytes(range(32)), bytes([9] * 32), bytes([7] * 32)
    f = Flight(signing_setup_key=setup)
    stranger = mavutil.mavlink_connection(f"udpout:127.0.0.1:{f.bridge_port()}",
                                          source_system=254, source_component=1,
                                          dialect="common")
    try:
        stranger.mav.setup_signing_send(1, 1, list(other), 0)  # unsigned
        text_seen(f, "SETUP_SIGNING refused: unsigned (not the --signing-setup-key)")
        stranger.setup_signing(other, sign_outgoing=True)  # signed with a key of its own
        stranger.mav.setup_signing_send(1, 1, list(other), 0)
        text_seen(f, "SETUP_SIGNING refused: bad signature (not the --signing-setup-key)")
        assert not f.bridge.signing.enabled
        f.gcs.setup_signing(setup, sign_outgoing=True)  # the user's ground station
        f.gcs.mav.setup_signing_send(1, 1, list(new), 0)
        deadline = time.monotonic() + 3.0
        while f.bridge.signing.key != new and time.monotonic() < deadline:
            time.sleep(0.05)
        assert f.bridge.signing.key == new
        assert "signing enabled with a new key" in f.bridge.events
        f.gcs.setup_signing(new, sign_outgoing=True)  # as the ground station does after it
        # the one-time key is spent, and the stranger's forged message changes nothing
        stranger.mav.setup_signing_send(1, 1, list(other), 0)
        spent = mavutil.mavlink_connection(f"udpout:127.0.0.1:{f.bridge_port()}",
                                           source_system=253, source_component=1,
                                           dialect="common")
        spent.setup_signing(setup, sign_outgoing=True)
        spent.mav.setup_signing_send(1, 1, list(other), 0)  # the spent one-time key
        spent.close()
        f.drain()
        time.sleep(0.3)
        f.drain()
        assert f.bridge.signing.key == new
        assert f.bridge.stats.refused_unsigned >= 2
        f.gcs.mav.setup_signing_send(1, 1, list(other), 0)  # a change of keys, signed
        deadline = time.monotonic() + 3.0
        while f.bridge.signing.key != other and time.monotonic() < deadline:
            f.drain()
            time.sleep(0.05)
        assert f.bridge.signing.key == other
        assert f.thread.is_alive()
    finally:
        stranger.close()
        f.close()


def test_setup_signing_refused_when_the_key_came_from_the_command_line():
    f = Flight(signing_key=bytes(range(32)))
    try:
        f.gcs.setup_signing(bytes(range(32)), sign_outgoing=True)
        f.gcs.mav.setup_signing_send(1, 1, [9] * 32, 0)  # signed, disarmed
        text_seen(f, "SETUP_SIGNING refused: key set by --signing-key")
        assert f.bridge.signing.key == bytes(range(32))
    finally:
        f.close()


def test_safety_limits_change_only_on_a_signed_link():
    """A stranger's PARAM_SET widening the setpoint limits (the issue: FPB_SP_XY_MAX = 10000,
    FPB_SP_TIMEOUT = 60 accepted) is refused with PARAM_ERROR PERMISSION_DENIED; the same
    from the signed ground station is taken."""
    key = bytes(range(32))
    for signed in (False, True):
        f = Flight(**({"signing_key": key} if signed else {}))
        try:
            if signed:
                f.gcs.setup_signing(key, sign_outgoing=True)
            for name, value in (("FPB_SP_XY_MAX", 10000.0), ("FPB_SP_TIMEOUT", 60.0)):
                before = f.bridge.params.get(name)
                f.gcs.mav.param_set_send(1, 1, name.encode(), value, REAL32)
                if signed:
                    f.wait("PARAM_VALUE", 3.0, lambda m, n=name, v=value: m.param_id == n
                           and m.param_value == pytest.approx(v))
                    assert f.bridge.params.get(name) == pytest.approx(value)
                else:
                    err = f.wait("PARAM_ERROR", 3.0, lambda m, n=name: m.param_id == n)
                    assert err.error == mavutil.mavlink.MAV_PARAM_ERROR_PERMISSION_DENIED
                    pv = f.wait("PARAM_VALUE", 3.0, lambda m, n=name: m.param_id == n)
                    assert pv.param_value == pytest.approx(before)
                    assert f.bridge.params.get(name) == before
            if not signed:
                assert f.bridge.limits.xy == pytest.approx(100.0)
                text_seen(f, "limits change on a signed link only")
        finally:
            f.close()


def test_limit_option_sets_the_bridge_parameters():
    f = Flight(bridge_parameters={"FPB_SP_XY_MAX": 250.0})
    try:
        assert f.bridge.limits.xy == pytest.approx(250.0)
    finally:
        f.close()
    for bad, why in (({"FPB_SP_XY_MAX": 1e9}, "outside"), ({"FP_KPOS_D1": 1.0}, "not a bridge")):
        with pytest.raises(ValueError, match=why):
            Flight(bridge_parameters=bad)


# -- parameters -----------------------------------------------------------------------------

def test_parameter_outside_the_fmu_range_is_refused_with_the_value_in_force(flight):
    f = flight
    fly_offboard(f)
    shipped = controller_parameters()["K_pos_A[1]"]
    pv = param_set(f, "FP_KPOS_A1", 1.5)  # the FMU declares (-1, 1)
    assert pv.param_value == pytest.approx(shipped, rel=1e-6)
    text_seen(f, "FP_KPOS_A1 1.5 refused: outside (-1, 1)")
    # in the FMU's range (0, inf) but absurd: three decades from the design value at most
    w0 = param_value(f, "FP_W_U1").param_value
    pv = param_set(f, "FP_W_U1", 1e-30)
    assert pv.param_value == pytest.approx(w0, rel=1e-6)
    text_seen(f, "FP_W_U1 1e-30 refused: outside")
    pv = param_set(f, "FP_W_U1", w0 * 2)  # a plausible change is taken
    assert pv.param_value == pytest.approx(w0 * 2, rel=1e-6)
    still_flying(f)


def test_destabilizing_gain_refused_with_the_predicted_margin(flight):
    f = flight
    fly_offboard(f)
    shipped = controller_parameters()["K_pos_D[1]"]
    pv = param_set(f, "FP_KPOS_D1", 1e30)
    assert pv.param_value == pytest.approx(shipped, rel=1e-6)
    text_seen(f, "FP_KPOS_D1 1e+30 refused: margin -")
    rate = controller_parameters()["K_rate_D[1]"]
    pv = param_set(f, "FP_KRATE_D1", 3 * rate)
    assert pv.param_value == pytest.approx(rate, rel=1e-6)
    text_seen(f, "FP_KRATE_D1")
    assert any("FP_KRATE_D1" in t and "margin -" in t for t in f.texts)
    pv = param_set(f, "FP_KPOS_D1", 1.1 * shipped)  # a stable change is taken
    assert pv.param_value == pytest.approx(1.1 * shipped, rel=1e-6)
    still_flying(f)


def _oracle_radius(values, outer, inner, axis, spec):
    """Nominal closed-loop poles from the characteristic polynomial of the synthesis'
    frequency-domain code (hinf.FastEval, polynomial algebra: not the state-space
    interconnection the guard uses), by numpy's roots."""
    m = hinf.FastEval(spec, [1.0]).models[0]
    assert m["k"] == 1.0

    def poly(loop):
        b = hinf.Block.from_fmu(*(values[f"K_{loop}_{p}[{axis}]"] for p in "ABCD"))
        if b.g == 0.0:
            return np.array([b.d]), np.array([1.0])
        return np.array([b.d, b.g - b.d * b.a]), np.array([1.0, -b.a])

    (n1, d1), (n2, d2) = poly(outer), poly(inner)
    nh = hinf.FastEval(spec, [1.0]).nh
    char = np.polyadd(np.polymul(np.polymul(d1, d2), m["cE"]),
                      np.polymul(np.polymul(n2, nh),
                                 np.polyadd(np.polymul(m["nv"], d1), np.polymul(n1, m["np"]))))
    char2 = np.polyadd(np.polymul(d2, m["cE2"]), np.polymul(np.polymul(n2, nh), m["nv2"]))
    return max(float(np.max(np.abs(np.roots(np.trim_zeros(c, "f"))))) for c in (char, char2))


@pytest.mark.parametrize("name,factor", [("K_pos_D[1]", 1.0), ("K_pos_D[1]", 30.0),
                                         ("K_vel_D[2]", 10.0), ("K_vel_C[3]", -5.0),
                                         ("K_att_D[1]", 4.0), ("K_rate_D[3]", 2.0),
                                         ("K_rate_D[3]", 0.5)])
def test_stability_guard_agrees_with_the_characteristic_polynomial(name, factor):
    values = {k: float(v) for k, v in controller_parameters().items() if k.startswith("K_")}
    values[name] *= factor
    loop, axis = name[2:].split("_")[0], name[-2]
    outer, inner, spec = stability._LOOP[loop]
    t0 = time.perf_counter()
    mg = stability.margin(values, name)
    elapsed = time.perf_counter() - t0
    assert mg is not None
    rho = _oracle_radius(values, outer, inner, axis, spec)
    # polynomial roots near the double pole at 1 are good to ~1e-5
    assert 1.0 - mg == pytest.approx(rho, abs=1e-4)
    if abs(rho - 1.0) > 1e-4:
        assert (stability.guard(values, name) is None) == (rho < 1.0)
    assert elapsed < 0.5  # generous: it runs on a PARAM_SET (measured ~1-2 ms, see docs)


def test_integer_parameter_is_int32_byte_wise_and_set_by_its_type(flight):
    f = flight
    pv = param_value(f, "FP_QP_MAX_ITER")
    start = as_int(pv)
    assert start == int(f.bridge.session.ctrl_inst.get("qp_max_iter"))
    pv = param_set(f, "FP_QP_MAX_ITER", 57, INT32)
    assert as_int(pv) == 57
    assert int(f.bridge.session.ctrl_inst.get("qp_max_iter")) == 57
    pv = param_set(f, "FP_QP_MAX_ITER", 5000, INT32)  # the FMU declares 1..1000
    assert as_int(pv) == 57
    text_seen(f, "FP_QP_MAX_ITER 5000 refused: outside 1..1000")
    pv = param_set(f, "FP_KPOS_D1", 3, INT32)  # a float parameter sent as INT32
    assert pv.param_type == REAL32
    text_seen(f, "refused: a REAL32 parameter")
    f.gcs.mav.param_request_list_send(1, 1)
    pv = f.wait("PARAM_VALUE", 3.0, lambda m: m.param_id == "FPB_SP_TIMEOUT")
    assert pv.param_type == REAL32 and pv.param_value == pytest.approx(1.0)  # COM_OF_LOSS_T


@pytest.mark.clients
def test_mavsdk_int_and_float_parameter_round_trips():
    from mavsdk.plugins.param import Param, ParamError

    with harness.mavsdk_session() as (bridge, system, plugins):
        param = Param(system)
        plugins += [param]
        start = param.get_param_int("FP_QP_MAX_ITER")
        assert start == int(bridge.session.ctrl_inst.get("qp_max_iter"))
        param.set_param_int("FP_QP_MAX_ITER", 42)
        assert param.get_param_int("FP_QP_MAX_ITER") == 42
        assert int(bridge.session.ctrl_inst.get("qp_max_iter")) == 42
        d1 = param.get_param_float("FP_KPOS_D1")
        assert d1 == pytest.approx(controller_parameters()["K_pos_D[1]"], rel=1e-6)
        param.set_param_float("FP_KPOS_D1", 1.05 * d1)
        assert param.get_param_float("FP_KPOS_D1") == pytest.approx(1.05 * d1, rel=1e-6)
        with pytest.raises(ParamError):
            param.get_param_float("FP_QP_MAX_ITER")  # typed: an int is not a float
        t0 = time.monotonic()
        with pytest.raises(ParamError):
            param.set_param_float("FP_KPOS_A1", 1.5)  # refused: answered, not timed out
        refused_after = time.monotonic() - t0
        assert param.get_param_float("FP_KPOS_A1") == pytest.approx(
            controller_parameters()["K_pos_A[1]"], rel=1e-6)
        print(f"\nMAVSDK refused set answered after {refused_after:.2f} s")
        chunks = bridge.stats.chunks
        time.sleep(0.2)
        assert bridge.stats.chunks > chunks  # still flying


# -- setpoints --------------------------------------------------------------------------------

@pytest.mark.parametrize("field,value,reason", [
    ("yaw", 1e30, "|yaw| above 2 pi rad"),
    ("yaw", 7.0, "|yaw| above 2 pi rad"),
    ("x", 1e6, "|x|, |y| above 100 m"),
    ("z", -500.0, "|z| above 100 m"),
    ("vx", 50.0, "velocity above 10 m/s"),
    ("afz", 1e9, "acceleration above 20 m/s^2"),
    ("yaw_rate", 100.0, "yaw rate above 6 rad/s"),
])
def test_setpoint_fields_range_checked_previous_kept(flight, field, value, reason):
    f = flight
    fly_offboard(f)
    before = f.bridge.pos_sp
    fields = dict(x=0.3, y=0.0, z=-3.0, vx=0.0, vy=0.0, vz=0.0, afx=0.0, afy=0.0, afz=0.0,
                  yaw=0.0, yaw_rate=0.0)
    fields[field] = value
    mask = 0  # every field used
    f.gcs.mav.set_position_target_local_ned_send(0, 1, 1, 1, mask, *fields.values())
    text_seen(f, f"POSITION_TARGET rejected: {reason}"[:50])  # STATUSTEXT: 50 chars
    assert f.bridge.pos_sp is before  # the previous setpoint is kept
    still_flying(f)


def test_yaw_within_one_turn_accepted(flight):
    f = flight
    fly_offboard(f)
    stream(f, 0.2, lambda: f.position(0.3, 0.0, -3.0, yaw=2 * math.pi - 0.1,
                                      mask=YAW_USED))  # the [0, 2 pi) convention
    assert f.bridge.pos_sp.yaw == pytest.approx(-0.1, abs=1e-5)


# -- setpoint loss ----------------------------------------------------------------------------

def test_setpoint_loss_holds_instead_of_flying_the_last_velocity(flight):
    f = flight
    assert f.bridge.timeout == pytest.approx(1.0)  # PX4 COM_OF_LOSS_T default
    f.command(400, 1, expect=0)

    def vel():
        f.gcs.mav.set_position_target_local_ned_send(0, 1, 1, 1, VEL_ONLY, 0, 0, 0,
                                                      1.0, 0, 0, 0, 0, 0, 0.0, 0)
    vel()
    f.offboard(expect=0)
    stream(f, 0.5, vel)  # 2 s simulated at 1 m/s
    t_stop = f.bridge.session.time
    x_stop = float(f.bridge.session.state()["plant"]["pos"][0])
    # stop streaming; PX4's timeout (1 s simulated) later: HOLD mode
    hb = f.wait("HEARTBEAT", 3.0, lambda m: (m.custom_mode >> 16) & 0xFF == 4)
    assert (hb.custom_mode >> 24) & 0xFF == 3  # AUTO.LOITER
    text_seen(f, "offboard lost")
    time.sleep(0.5)
    x_end = float(f.bridge.session.state()["plant"]["pos"][0])
    assert f.bridge.session.time - t_stop > 2.0
    # the old behaviour flew on at 1 m/s for the whole timeout (>= 1 m); now it brakes
    # after FPB_SP_STALE (0.25 s): the overshoot is the stale window plus a stop from 1 m/s
    # within the controller's reference shaping (jerk ref_jerk_max = 5 m/s^3 at most: a
    # triangular deceleration, v sqrt(v / j) = 0.45 m)
    # (plus 2 cm: the hold point is the stop of the shaped reference, which the vehicle
    # trails by its tracking error)
    v, stale, jerk = 1.0, 0.25, 5.0
    assert x_end - x_stop < v * stale + v * math.sqrt(v / jerk) + 0.02, (x_stop, x_end)
    f.wait("LOCAL_POSITION_NED", 5.0, lambda m: abs(m.vx) < 0.05)  # settles at the hold
    assert f.thread.is_alive()


# -- infeasible attitude ----------------------------------------------------------------------

def test_infeasible_attitude_reported_once_naming_the_attitude_held(flight):
    f = flight
    fly_offboard(f)
    steep = (math.radians(60), 0.0, 0.0)  # beyond the feasible tilt of the hexacopter
    stream(f, 1.5, lambda: (f.position(0.3, 0.0, -3.0), f.attitude(*steep)))  # 6 s sim
    text_seen(f, "attitude infeasible: holding r")
    reports = [t for t in f.bridge.events if t.startswith("attitude infeasible")]
    assert len(reports) == 1, reports  # no flapping
    mu = np.degrees(f.bridge.session.state()["ctrl"]["mu_c"])
    held = float(reports[0].split("holding r")[1].split(" ")[0])
    assert abs(held - mu[0]) < 2.0
    assert held < 55.0  # the attitude flown, not the one asked for
    stream(f, 1.0, lambda: (f.position(0.3, 0.0, -3.0), f.attitude(0.0, 0.0, 0.0)))
    text_seen(f, "attitude reference feasible again")
    still_flying(f)


def test_setpoint_loss_mid_transit_stops_once_and_holds(flight):
    """A position target 10 m away, the stream stopped mid-transit at 2 m/s: the vehicle
    brakes within the shaping's limits and holds where it stops (docs/mavlink.md): it neither
    flies on to the old target nor comes back (the issue: 1.35 m beyond and back)."""
    f = flight
    f.command(400, 1, expect=0)
    f.position(10.0, 0.0, -3.0)
    f.offboard(expect=0)
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:  # stream until mid-transit at cruise speed
        stream(f, 0.05, lambda: f.position(10.0, 0.0, -3.0))
        state = f.bridge.session.state()
        x_stop, v = float(state["plant"]["pos"][0]), float(state["plant"]["vel"][0])
        if v > 1.5:
            break
    assert v > 1.5 and x_stop < 6.0, (x_stop, v)  # mid-transit
    xs = []
    deadline = time.monotonic() + 3.0  # 12 s simulated: past FPB_SP_TIMEOUT, into HOLD
    while time.monotonic() < deadline:
        f.drain()
        xs.append(float(f.bridge.session.state()["plant"]["pos"][0]))
        time.sleep(0.02)
    assert f.bridge.mode == "HOLD"
    final, held = xs[-1], float(f.bridge.ref.pos[0])
    info = (x_stop, v, final, held, max(xs), f.bridge.events[-3:])
    # braked: a stop from 2 m/s within the shaping's limits is under 1.5 m, plus the stale
    # window (0.25 s); the old behaviour flew on toward the target (6.6 m and back)
    assert final - x_stop < 2.5, info
    assert abs(held - final) < 0.05, info  # holds where it stopped ...
    assert max(xs) - final < 0.1, info  # ... without coming back beyond tracking


def test_a_setpoint_before_the_first_chunk_is_shaped():
    """A ground station whose arm, setpoint and OFFBOARD reach the bridge before its first
    chunk (queued on its socket before it runs): the 10 m jump is flown within the shaping's
    limits from the start pose, not as a raw step (the controller's first sample takes its
    reference as given; the bridge runs that sample at the start pose first)."""
    port = free_port()
    bridge = Bridge(BridgeConfig(urls=[f"udpout:127.0.0.1:{port}"], speed=4.0, duration=8.0))
    sender = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{bridge.endpoints[0].sock.getsockname()[1]}", source_system=255,
        source_component=190)
    seen: list[tuple[np.ndarray, np.ndarray, float]] = []
    bridge.on_chunk = lambda b: seen.append((b.session.state()["ctrl"]["pos_ref_s"].copy(),
                                             b.session.state()["ctrl"]["vel_ref_s"].copy(),
                                             float(b.session.state()["ctrl"]["ref_vel_limit"][0])))
    try:
        sender.mav.heartbeat_send(6, 8, 0, 0, 0)
        sender.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)  # arm
        sender.mav.set_position_target_local_ned_send(0, 1, 1, 1, harness.POS_ONLY, 10.0, 0.0,
                                                      -3.0, 0, 0, 0, 0, 0, 0, 0.0, 0)
        sender.mav.command_long_send(1, 1, 176, 0, 1, 6, 0, 0, 0, 0, 0)  # OFFBOARD
        time.sleep(0.2)  # every datagram waits in the bridge's socket
        runner = threading.Thread(target=bridge.run, daemon=True)
        runner.start()
        deadline = time.monotonic() + 10.0
        while bridge.mode != "OFFBOARD" and time.monotonic() < deadline:
            time.sleep(0.01)
        assert bridge.mode == "OFFBOARD"
        while bridge.session.time < 2.0 and time.monotonic() < deadline:
            sender.mav.set_position_target_local_ned_send(0, 1, 1, 1, harness.POS_ONLY, 10.0,
                                                          0.0, -3.0, 0, 0, 0, 0, 0, 0, 0.0, 0)
            time.sleep(0.02)
        bridge.stop()
        runner.join(timeout=10)
    finally:
        bridge.close()
        sender.close()
    pos = np.array([p for p, _, _ in seen])
    speed = np.array([np.hypot(v[0], v[1]) for _, v, _ in seen])
    assert abs(pos[0, 0]) < 0.05, pos[:3]  # the first chunk starts at the start pose
    assert speed.max() <= seen[-1][2] + 1e-6  # within the shaping's speed limit
    assert pos[-1, 0] > 1.0  # and on its way to the target


def test_a_long_statustext_arrives_whole_in_chunks(flight):
    """MAVLink 2 STATUSTEXT chunks (id, chunk_seq): a text longer than 50 characters is sent
    whole, not cut (the issue: "...force setpoints unsuppor")."""
    f = flight
    text = "a refusal that says everything it has to say, " * 3  # 141 characters
    f.bridge.statustext(mav.MAV_SEVERITY_WARNING, text)
    chunks = []
    deadline = time.monotonic() + 3.0
    while (not chunks or len(chunks[-1].text) == 50) and time.monotonic() < deadline:
        m = f.gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=0.1)
        if m is not None and m.id != 0:
            chunks.append(m)
    assert len({c.id for c in chunks}) == 1
    assert [c.chunk_seq for c in chunks] == list(range(len(chunks)))
    assert "".join(c.text for c in chunks) == text.rstrip("\0")
    f.bridge.statustext(mav.MAV_SEVERITY_INFO, "short")
    assert f.wait("STATUSTEXT", 3.0, lambda m: m.text == "short").id == 0


def test_refused_parameter_set_answers_param_error_at_once(flight):
    """A refused PARAM_SET is answered with PARAM_ERROR naming the parameter and the reason's
    code, before the PARAM_VALUE in force: MAVSDK ends its call with that error instead of
    retrying into a timeout."""
    f = flight
    f.gcs.mav.param_set_send(1, 1, b"FP_KPOS_A1", 1.5, REAL32)  # outside (-1, 1)
    order = []
    deadline = time.monotonic() + 3.0
    while len(order) < 2 and time.monotonic() < deadline:
        m = f.gcs.recv_match(type=["PARAM_ERROR", "PARAM_VALUE"], blocking=True, timeout=0.1)
        if m is not None and m.param_id == "FP_KPOS_A1":
            order.append(m)
    assert [m.get_type() for m in order] == ["PARAM_ERROR", "PARAM_VALUE"]
    err = order[0]
    assert err.error == mavutil.mavlink.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE
    assert (err.target_system, err.target_component) == f.src
    f.gcs.mav.param_set_send(1, 1, b"FP_KPOS_D1", 3.0, INT32)  # a float sent as INT32
    err = f.wait("PARAM_ERROR", 3.0, lambda m: m.param_id == "FP_KPOS_D1")
    assert err.error == 7  # MAV_PARAM_ERROR_TYPE_MISMATCH (newer common.xml than pymavlink's)


def test_udpin_endpoint_talks_only_to_senders_of_a_valid_heartbeat():
    """The issue: a udpin endpoint streamed 1,165 telemetry datagrams in 5 s to a stranger
    sending one junk datagram every 0.5 s.  Now junk makes no peer; a valid HEARTBEAT does
    (with signing on, only a signed one)."""
    for key in (None, bytes(range(32))):
        port = free_port()
        bridge = Bridge(BridgeConfig(urls=[f"udpin:127.0.0.1:{port}"], speed=4.0,
                                     duration=120.0, signing_key=key))
        thread = threading.Thread(target=bridge.run, daemon=True)
        thread.start()
        peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        peer.bind(("127.0.0.1", 0))
        peer.settimeout(0.05)
        gcs = mavutil.mavlink.MAVLink(None, 255, 190)

        def received(seconds, send, peer=peer):
            n, deadline = 0, time.monotonic() + seconds
            while time.monotonic() < deadline:
                send()
                try:
                    while True:
                        peer.recvfrom(65535)
                        n += 1
                except TimeoutError:
                    pass
            return n

        try:
            to = ("127.0.0.1", port)
            assert received(1.0, lambda p=peer, a=to: p.sendto(b"\xfd junk", a)) == 0
            hb = gcs.heartbeat_encode(6, 8, 0, 0, 0).pack(gcs)  # unsigned
            n = received(1.0, lambda p=peer, a=to, d=hb: p.sendto(d, a))
            if key is None:
                assert n > 20, n
            else:
                assert n == 0, n
                signer = mavutil.mavlink.MAVLink(None, 255, 190)
                signer.signing.secret_key = key
                signer.signing.sign_outgoing = True
                signer.signing.timestamp = int((time.time() - 1420070400) * 1e5)
                assert received(1.0, lambda p=peer, a=to, s=signer: p.sendto(
                    s.heartbeat_encode(6, 8, 0, 0, 0).pack(s), a)) > 20
        finally:
            peer.close()
            bridge.stop()
            thread.join(timeout=10)
            bridge.close()


def test_a_parameter_list_flood_from_a_stranger_is_throttled():
    """The issue: ~85 PARAM_REQUEST_LIST per second from a stranger made the bridge send
    33-35k PARAM_VALUE and fall behind real time.  Each sender gets a list every 2 s at
    most (after a burst of 2); the loop keeps its pace."""
    f = Flight(speed=1.0)
    stranger = mavutil.mavlink_connection(f"udpout:127.0.0.1:{f.bridge_port()}",
                                          source_system=254, source_component=1,
                                          dialect="common")
    try:
        n_params = len(f.bridge.params)
        t0 = time.monotonic()
        sent = 0
        while time.monotonic() - t0 < 3.0:
            stranger.mav.param_request_list_send(1, 1)
            sent += 1
            f.drain()
            time.sleep(1 / 85)
        lists = f.bridge.budget.dropped.get("param_list", 0)
        assert sent > 200 and lists >= sent - 4
        assert f.bridge.stats.throttled == lists
        assert f.bridge.endpoints[0].sent < 4 * n_params + 2000  # <= 2 + 3 s / 2 s lists
        assert f.bridge.stats.max_lag < 0.1, f.bridge.stats.max_lag
        assert f.thread.is_alive()
    finally:
        stranger.close()
        f.close()


def test_the_exit_summary_counts_what_was_sent_after_ctrl_c(tmp_path):
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "fly", "--gcs",
         f"udpout:127.0.0.1:{free_port()}"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    try:
        assert "mavlink endpoint" in proc.stdout.readline() + proc.stdout.readline() + \
            proc.stdout.readline()
        time.sleep(1.5)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    sent = [line for line in out.splitlines() if line.startswith("sent")]
    assert sent and int(sent[0].split()[1]) > 10, (out, err)
    assert "Traceback" not in err


def test_cli_limit_and_signing_setup_key_options(tmp_path):
    import subprocess
    import sys

    key = tmp_path / "setup.key"
    key.write_text("a passphrase for the first setup\n")
    base = [sys.executable, "-m", "orchestrator.cli", "fly", "--speed", "max", "--duration",
            "0.05", "--gcs", f"udpout:127.0.0.1:{free_port()}"]
    out = subprocess.run([*base, "--limit", "FPB_SP_XY_MAX=250", "--signing-setup-key",
                          str(key)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    for bad, why in (("FPB_SP_XY_MAX=1e9", "outside"), ("FP_KPOS_D1=1", "not a bridge"),
                     ("FPB_SP_XY_MAX", "expected FPB_NAME=NUMBER")):
        out = subprocess.run([*base, "--limit", bad], capture_output=True, text=True,
                             timeout=120)
        assert out.returncode != 0 and why in out.stderr, out.stderr
        assert "Traceback" not in out.stderr
