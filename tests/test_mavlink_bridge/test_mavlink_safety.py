"""Safety a flight needs (issue 15, item 4), against a running bridge over real UDP:
SETUP_SIGNING policy, parameter ranges (the FMU's own), the design-model stability guard,
typed (INT32, byte-wise) parameters with pymavlink and MAVSDK, setpoint range checks,
setpoint loss (hold, PX4's timeout) and the infeasible-attitude report.  Every refusal is
checked by its STATUSTEXT; every test checks that the vehicle keeps flying."""

import math
import struct
import time

import numpy as np
import pytest
from helpers import mavlink_harness as harness
from helpers.mavlink_harness import free_port

from controller import hinf
from controller.gains_defaults import controller_parameters
from mavlink_bridge import stability

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

def test_setup_signing_refused_while_armed_in_offboard_and_from_unnamed_links():
    f = Flight()
    try:
        fly_offboard(f)
        f.gcs.mav.setup_signing_send(1, 1, [9] * 32, 0)  # unsigned, while armed
        text_seen(f, "SETUP_SIGNING refused: armed")
        assert not f.bridge.signing.enabled
        still_flying(f)  # setpoints still accepted, offboard kept
        f.command(400, 0, expect=0)  # disarm still works
        f.gcs.mav.setup_signing_send(1, 1, [9] * 32, 0)
        text_seen(f, "SETUP_SIGNING refused: not --signing-setup-from")
        assert not f.bridge.signing.enabled
    finally:
        f.close()


def test_setup_signing_accepted_disarmed_from_the_named_link():
    f = Flight(setup_from_gcs=True)
    try:
        f.gcs.mav.setup_signing_send(1, 1, [9] * 32, 0)
        text_seen(f, "signing enabled with a new key")
        assert f.bridge.signing.key == bytes([9] * 32)
        assert f.thread.is_alive()
    finally:
        f.close()


def test_setup_signing_refused_when_the_key_came_from_the_command_line():
    f = Flight(setup_from_gcs=True, signing_key=bytes(range(32)))
    try:
        f.gcs.setup_signing(bytes(range(32)), sign_outgoing=True)
        f.gcs.mav.setup_signing_send(1, 1, [9] * 32, 0)  # signed, disarmed, named link
        text_seen(f, "SETUP_SIGNING refused: key set by --signing-key")
        assert f.bridge.signing.key == bytes(range(32))
    finally:
        f.close()


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
    v, stale, jerk = 1.0, 0.25, 5.0
    assert x_end - x_stop < v * stale + v * math.sqrt(v / jerk), (x_stop, x_end)
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


def test_stale_position_target_is_still_reached(flight):
    """A position target is a place, not a motion: a client streaming at 2 Hz (stale
    between setpoints, within the loss timeout) still gets there."""
    f = flight
    f.command(400, 1, expect=0)
    f.position(1.0, 0.0, -3.0)
    f.offboard(expect=0)
    for _ in range(6):  # 2 Hz simulated = every 0.125 s wall at 4x
        f.position(1.0, 0.0, -3.0)
        stream(f, 0.125, lambda: None)
    assert f.bridge.mode == "OFFBOARD"
    assert f.bridge.ref.pos[0] == pytest.approx(1.0)
    lp = f.wait("LOCAL_POSITION_NED", 3.0, lambda m: abs(m.x - 1.0) < 0.1)
    assert f.thread.is_alive() and lp is not None


def test_cli_signing_setup_from_adds_the_named_endpoint():
    import subprocess
    import sys

    gcs, setup = free_port(), free_port()
    out = subprocess.run(
        [sys.executable, "-m", "orchestrator.cli", "fly", "--speed", "max", "--duration",
         "0.05", "--gcs", f"udpout:127.0.0.1:{gcs}", "--signing-setup-from",
         f"udpin:127.0.0.1:{setup}"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert f"udpout:127.0.0.1:{gcs}" in out.stdout
    assert f"udpin:127.0.0.1:{setup}" in out.stdout
