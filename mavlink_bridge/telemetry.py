"""Telemetry messages built from the co-simulation's state, and their default rates.

Rates are per endpoint and count simulated time (the vehicle's clock, like PX4 in
lockstep SITL); SET_MESSAGE_INTERVAL changes them for the endpoint it came from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mav

from mavlink_bridge.geometry import euler_to_quat, rotation

#: message id -> default rate (Hz, simulated time)
DEFAULT_RATES: dict[int, float] = {
    mav.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    mav.MAVLINK_MSG_ID_SYS_STATUS: 2.0,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 2.0,
    mav.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    mav.MAVLINK_MSG_ID_ODOMETRY: 30.0,
    mav.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 10.0,
    mav.MAVLINK_MSG_ID_ATTITUDE_TARGET: 10.0,
    mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: 10.0,
    mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 10.0,
}
#: messages REQUEST_MESSAGE can produce besides the streamed ones
ON_REQUEST = (mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION,)


@dataclass
class Snapshot:
    """What the telemetry needs, sampled once per chunk."""

    time: float  # simulated s
    plant: dict[str, np.ndarray]
    ctrl: dict[str, np.ndarray]
    reference: dict[str, np.ndarray]
    mode_custom: int
    armed: bool
    n_rotors: int
    omega_max: float
    tilt_limits: np.ndarray  # (n, 2) max |alpha|, |beta|
    thrust_max: float  # N, all rotors at omega_max
    load: float  # share of wall time spent computing (0..1)


BASE_MODE_CUSTOM = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
ATT_TARGET_MASK = 0  # attitude, rates and thrust all given


def build(msg_id: int, s: Snapshot) -> Any:
    """The message ``msg_id`` for snapshot ``s`` (None: not produced here)."""
    f = _BUILDERS.get(msg_id)
    return None if f is None else f(s)


def heartbeat(s: Snapshot) -> Any:
    base = BASE_MODE_CUSTOM | mav.MAV_MODE_FLAG_STABILIZE_ENABLED | \
        mav.MAV_MODE_FLAG_GUIDED_ENABLED
    if s.armed:
        base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
    state = mav.MAV_STATE_ACTIVE if s.armed else mav.MAV_STATE_STANDBY
    kind = {4: mav.MAV_TYPE_QUADROTOR, 6: mav.MAV_TYPE_HEXAROTOR,
            8: mav.MAV_TYPE_OCTOROTOR}.get(s.n_rotors, mav.MAV_TYPE_GENERIC)
    return mav.MAVLink_heartbeat_message(kind, mav.MAV_AUTOPILOT_PX4, base, s.mode_custom,
                                         state, 3)


def _ms(s: Snapshot) -> int:
    return round(s.time * 1000) & 0xFFFFFFFF


def _us(s: Snapshot) -> int:
    return round(s.time * 1e6)


def _f(v: Any) -> list[float]:
    return [float(x) for x in v]


def attitude(s: Snapshot) -> Any:
    e, w = s.plant["euler"], s.plant["rate"]
    return mav.MAVLink_attitude_message(_ms(s), *_f(e), *_f(w))


def attitude_quaternion(s: Snapshot) -> Any:
    w = s.plant["rate"]
    return mav.MAVLink_attitude_quaternion_message(_ms(s), *_f(s.plant["quat"]), *_f(w),
                                                   [0.0, 0.0, 0.0, 0.0])


def local_position(s: Snapshot) -> Any:
    return mav.MAVLink_local_position_ned_message(_ms(s), *_f(s.plant["pos"]),
                                                  *_f(s.plant["vel"]))


def odometry(s: Snapshot) -> Any:
    r = rotation(*s.plant["euler"])
    v_body = r.T @ s.plant["vel"]
    nan21 = [math.nan] * 21
    return mav.MAVLink_odometry_message(
        _us(s), mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_BODY_FRD, *_f(s.plant["pos"]),
        _f(s.plant["quat"]), *_f(v_body), *_f(s.plant["rate"]), nan21, nan21, 0,
        mav.MAV_ESTIMATOR_TYPE_NAIVE, 100)


def position_target(s: Snapshot) -> Any:
    r = s.reference
    mask = 2048  # yaw rate ignored; yaw = commanded feasible yaw
    return mav.MAVLink_position_target_local_ned_message(
        _ms(s), mav.MAV_FRAME_LOCAL_NED, mask, *_f(r["pos_ref"]), *_f(r["vel_ref"]),
        *_f(r["acc_ref"]), float(s.ctrl["mu_c"][2]), 0.0)


def attitude_target(s: Snapshot) -> Any:
    mu = s.ctrl["mu_c"]  # the commanded *feasible* attitude
    f = float(np.linalg.norm(s.ctrl["f_b_c"]))
    thrust = min(1.0, f / s.thrust_max) if s.thrust_max > 0 else 0.0
    return mav.MAVLink_attitude_target_message(_ms(s), ATT_TARGET_MASK,
                                               euler_to_quat(*_f(mu)),
                                               *_f(s.ctrl["rate_c"]), thrust)


def sys_status(s: Snapshot) -> Any:
    sensors = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL |
               mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL |
               mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION |
               mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL |
               mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL |
               mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
    load = int(min(1000, max(0, round(s.load * 1000))))
    return mav.MAVLink_sys_status_message(sensors, sensors, sensors, load, 65535, -1, -1,
                                          0, 0, 0, 0, 0, 0)


def extended_sys_state(s: Snapshot) -> Any:
    # the simulated vehicle has no ground: it is always in the air
    return mav.MAVLink_extended_sys_state_message(mav.MAV_VTOL_STATE_UNDEFINED,
                                                  mav.MAV_LANDED_STATE_IN_AIR)


def actuator_output_status(s: Snapshot) -> Any:
    """actuator[0:n] rotor speeds (rad/s), [n:2n] tilt alpha, [2n:3n] tilt beta (rad)."""
    n = s.n_rotors
    values = _f(s.plant["omega"][:n]) + _f(s.plant["alpha"][:n]) + _f(s.plant["beta"][:n])
    return mav.MAVLink_actuator_output_status_message(_us(s), len(values),
                                                      values + [0.0] * (32 - len(values)))


def _pwm(x: float) -> int:
    return int(min(2000, max(1000, round(1500 + 500 * x))))


def servo_output_raw(s: Snapshot) -> Any:
    """Port 0: servo1..n the rotor speeds (1000 us = 0, 2000 us = omega_max),
    servo9..8+n the tilt angle alpha (1500 us = 0, 1000/2000 us = -/+ limit)."""
    n = min(s.n_rotors, 8)
    raw = [0] * 16
    for i in range(n):
        raw[i] = _pwm(2 * float(s.plant["omega"][i]) / s.omega_max - 1)
        lim = s.tilt_limits[i, 0]
        raw[8 + i] = _pwm(float(s.plant["alpha"][i]) / lim) if lim > 0 else 1500
    return mav.MAVLink_servo_output_raw_message(_us(s) & 0xFFFFFFFF, 0, *raw)


def servo_output_raw_beta(s: Snapshot) -> Any:
    """Port 1: servo1..n the tilt angle beta."""
    n = min(s.n_rotors, 8)
    raw = [0] * 16
    for i in range(n):
        lim = s.tilt_limits[i, 1]
        raw[i] = _pwm(float(s.plant["beta"][i]) / lim) if lim > 0 else 1500
    return mav.MAVLink_servo_output_raw_message(_us(s) & 0xFFFFFFFF, 1, *raw)


def autopilot_version(s: Snapshot) -> Any:
    caps = (mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT |
            mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE |  # INT32 params, as PX4
            mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT |
            mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET |
            mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED)
    version = (0 << 24) | (1 << 16) | (0 << 8) | 0  # fullpose 0.1.0
    return mav.MAVLink_autopilot_version_message(caps, version, 0, 0, 0, [0] * 8, [0] * 8,
                                                 [0] * 8, 0, 0, 1, [0] * 18)


_BUILDERS = {
    mav.MAVLINK_MSG_ID_HEARTBEAT: heartbeat,
    mav.MAVLINK_MSG_ID_SYS_STATUS: sys_status,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: extended_sys_state,
    mav.MAVLINK_MSG_ID_ATTITUDE: attitude,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: attitude_quaternion,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: local_position,
    mav.MAVLINK_MSG_ID_ODOMETRY: odometry,
    mav.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: position_target,
    mav.MAVLINK_MSG_ID_ATTITUDE_TARGET: attitude_target,
    mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: actuator_output_status,
    mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION: autopilot_version,
}


def build_all(msg_id: int, s: Snapshot) -> list[Any]:
    """All messages for ``msg_id`` (SERVO_OUTPUT_RAW goes out on two ports)."""
    if msg_id == mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW:
        return [servo_output_raw(s), servo_output_raw_beta(s)]
    m = build(msg_id, s)
    return [] if m is None else [m]
