"""Telemetry messages built from the co-simulation's state, and their default rates.

Rates are per endpoint and count simulated time (the vehicle's clock, like PX4 in
lockstep SITL); SET_MESSAGE_INTERVAL changes them for the endpoint it came from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mav

from mavlink_bridge.geodesy import Origin
from mavlink_bridge.geometry import euler_to_quat, rotation
from mavlink_bridge.identity import FLIGHT_SW_VERSION

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
    # the global-position group at the rates PX4 streams to a GCS (MAVLINK_MODE_NORMAL in
    # PX4-Autopilot src/modules/mavlink/mavlink_main.cpp, Mavlink::configure_streams_to_default)
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 5.0,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    mav.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: 0.1,
    mav.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    mav.MAVLINK_MSG_ID_ALTITUDE: 1.0,
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,  # PX4 streams it at 1 Hz to a GCS as well
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
    origin: Origin = field(default_factory=Origin)
    battery: Battery = field(default_factory=lambda: Battery())
    unix_us: int = 0  # wall clock (SYSTEM_TIME), 0: unknown
    home: np.ndarray = field(default_factory=lambda: np.zeros(3))  # local NED of home
    landed_state: int = mav.MAV_LANDED_STATE_IN_AIR
    mission_seq: int = 0  # the mission item flown or next (MISSION_CURRENT)
    mission_total: int = 0  # items in the mission
    mission_active: bool = False  # flying it (AUTO.MISSION)
    mission_complete: bool = False  # flown to its end


@dataclass
class Battery:
    """A simple battery: 4S LiPo, 5000 mAh; current proportional to the commanded thrust
    (60 A at full thrust), open-circuit cell voltage linear in the charge (4.2 V full,
    3.5 V empty).  Reported only: the plant's thrust does not depend on it."""

    cells: int = 4
    capacity_mah: float = 5000.0
    current_full_a: float = 60.0
    consumed_mah: float = 0.0
    current_a: float = 0.0

    def update(self, thrust_fraction: float, dt: float) -> None:
        """Draw the current of the commanded thrust fraction (0..1) for dt seconds."""
        self.current_a = self.current_full_a * min(1.0, max(0.0, thrust_fraction))
        self.consumed_mah += self.current_a * dt / 3.6

    @property
    def remaining(self) -> float:
        """Charge left, 0..1."""
        return max(0.0, 1.0 - self.consumed_mah / self.capacity_mah)

    @property
    def cell_v(self) -> float:
        """Open-circuit cell voltage (V) at the charge left."""
        return 3.5 + 0.7 * self.remaining


BASE_MODE_CUSTOM = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
ATT_TARGET_MASK = 0  # attitude, rates and thrust all given


def build(msg_id: int, s: Snapshot) -> Any:
    """The message ``msg_id`` for snapshot ``s`` (None: not produced here)."""
    f = _BUILDERS.get(msg_id)
    return None if f is None else f(s)


def heartbeat(s: Snapshot) -> Any:
    """HEARTBEAT: vehicle type, autopilot, PX4 mode and armed state."""
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
    """ATTITUDE: Euler angles and body rates."""
    e, w = s.plant["euler"], s.plant["rate"]
    return mav.MAVLink_attitude_message(_ms(s), *_f(e), *_f(w))


def attitude_quaternion(s: Snapshot) -> Any:
    """ATTITUDE_QUATERNION: the attitude quaternion [w, x, y, z] and body rates."""
    w = s.plant["rate"]
    return mav.MAVLink_attitude_quaternion_message(_ms(s), *_f(s.plant["quat"]), *_f(w),
                                                   [0.0, 0.0, 0.0, 0.0])


def local_position(s: Snapshot) -> Any:
    """LOCAL_POSITION_NED: position and velocity in the local NED frame."""
    return mav.MAVLink_local_position_ned_message(_ms(s), *_f(s.plant["pos"]),
                                                  *_f(s.plant["vel"]))


def odometry(s: Snapshot) -> Any:
    """ODOMETRY: position (local NED), attitude quaternion, velocity and rates (body FRD)."""
    r = rotation(*s.plant["euler"])
    v_body = r.T @ s.plant["vel"]
    nan21 = [math.nan] * 21
    return mav.MAVLink_odometry_message(
        _us(s), mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_BODY_FRD, *_f(s.plant["pos"]),
        _f(s.plant["quat"]), *_f(v_body), *_f(s.plant["rate"]), nan21, nan21, 0,
        mav.MAV_ESTIMATOR_TYPE_NAIVE, 100)


def position_target(s: Snapshot) -> Any:
    """POSITION_TARGET_LOCAL_NED: the position and yaw setpoint in use."""
    r = s.reference
    mask = 2048  # yaw rate ignored; yaw = commanded feasible yaw
    return mav.MAVLink_position_target_local_ned_message(
        _ms(s), mav.MAV_FRAME_LOCAL_NED, mask, *_f(r["pos_ref"]), *_f(r["vel_ref"]),
        *_f(r["acc_ref"]), float(s.ctrl["mu_c"][2]), 0.0)


def attitude_target(s: Snapshot) -> Any:
    """ATTITUDE_TARGET: the attitude the controller commands (mu_c)."""
    mu = s.ctrl["mu_c"]  # the commanded *feasible* attitude
    f = float(np.linalg.norm(s.ctrl["f_b_c"]))
    thrust = min(1.0, f / s.thrust_max) if s.thrust_max > 0 else 0.0
    return mav.MAVLink_attitude_target_message(_ms(s), ATT_TARGET_MASK,
                                               euler_to_quat(*_f(mu)),
                                               *_f(s.ctrl["rate_c"]), thrust)


#: what the simulated vehicle has, as PX4 SITL reports it (all present, enabled, healthy)
SENSORS = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL |
           mav.MAV_SYS_STATUS_SENSOR_3D_MAG | mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE |
           mav.MAV_SYS_STATUS_SENSOR_GPS | mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL |
           mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION |
           mav.MAV_SYS_STATUS_SENSOR_YAW_POSITION |
           mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL |
           mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL |
           mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | mav.MAV_SYS_STATUS_AHRS |
           mav.MAV_SYS_STATUS_SENSOR_BATTERY | mav.MAV_SYS_STATUS_PREARM_CHECK)
#: no geofence is simulated: not present, not enabled, and healthy (= not breached), which is
#: what MAVProxy's fence module reads; a clear health bit is its "fence breach"
HEALTH_ONLY = mav.MAV_SYS_STATUS_GEOFENCE


def sys_status(s: Snapshot) -> Any:
    """SYS_STATUS: sensors present and healthy, the loop's load, battery voltage and current."""
    load = int(min(1000, max(0, round(s.load * 1000))))
    b = s.battery
    return mav.MAVLink_sys_status_message(
        SENSORS, SENSORS, SENSORS | HEALTH_ONLY, load, round(b.cells * b.cell_v * 1000),
        round(b.current_a * 100), round(b.remaining * 100), 0, 0, 0, 0, 0, 0)


def battery_status(s: Snapshot) -> Any:
    """BATTERY_STATUS: cell voltages, current, consumed charge and charge left."""
    b = s.battery
    cells = [round(b.cell_v * 1000)] * b.cells + [65535] * (10 - b.cells)
    return mav.MAVLink_battery_status_message(
        0, mav.MAV_BATTERY_FUNCTION_ALL, mav.MAV_BATTERY_TYPE_LIPO, 32767, cells,
        round(b.current_a * 100), round(b.consumed_mah), -1, round(b.remaining * 100))


def _global(s: Snapshot) -> tuple[int, int, int, int]:
    """(lat 1e7 deg, lon 1e7 deg, alt mm AMSL, relative alt mm above home)."""
    n, e, d = _f(s.plant["pos"])
    lat, lon, alt = s.origin.to_geodetic(n, e, d)
    home_alt = s.origin.to_geodetic(*_f(s.home))[2]
    return (round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
            round((alt - home_alt) * 1000))


def _hdg_cdeg(s: Snapshot) -> int:
    return round(math.degrees(float(s.plant["euler"][2])) * 100) % 36000


def global_position_int(s: Snapshot) -> Any:
    """GLOBAL_POSITION_INT: WGS84 position, altitudes and NED velocity."""
    lat, lon, alt, rel = _global(s)
    v = [round(100 * x) for x in _f(s.plant["vel"])]
    return mav.MAVLink_global_position_int_message(_ms(s), lat, lon, alt, rel, *v,
                                                   _hdg_cdeg(s))


def gps_raw_int(s: Snapshot) -> Any:
    # as PX4 SITL's simulated GPS (PX4-Autopilot src/modules/simulation/sensor_gps_sim/
    # SensorGpsSim.cpp, SensorGpsSim::Run): 3-D fix, 10 satellites (SIM_GPS_USED), HDOP 0.7,
    # VDOP 1.1 (eph/epv carry the DOPs x 100), accuracies 0.9 m / 1.78 m / 0.4 m/s
    """GPS_RAW_INT: a 3-D fix at the WGS84 position."""
    lat, lon, alt, _ = _global(s)
    v = s.plant["vel"]
    vel = round(100 * math.hypot(float(v[0]), float(v[1])))
    cog = round(math.degrees(math.atan2(float(v[1]), float(v[0]))) * 100) % 36000 \
        if vel > 0 else 65535
    return mav.MAVLink_gps_raw_int_message(_us(s), mav.GPS_FIX_TYPE_3D_FIX, lat, lon, alt,
                                           70, 110, vel, cog, 10, alt, 900, 1780, 400, 0, 0)


def _origin_fields(s: Snapshot) -> tuple[int, int, int]:
    o = s.origin
    return round(o.lat * 1e7), round(o.lon * 1e7), round(o.alt * 1000)


def home_position(s: Snapshot) -> Any:
    """HOME_POSITION: home (where the vehicle booted, or as DO_SET_HOME moved it), in WGS84
    and in the local frame."""
    lat, lon, alt = s.origin.to_geodetic(*_f(s.home))
    x, y, z = _f(s.home)
    return mav.MAVLink_home_position_message(round(lat * 1e7), round(lon * 1e7),
                                             round(alt * 1000), x, y, z,
                                             [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, _us(s))


def gps_global_origin(s: Snapshot) -> Any:
    """GPS_GLOBAL_ORIGIN: the WGS84 point of the local NED origin."""
    lat, lon, alt = _origin_fields(s)
    return mav.MAVLink_gps_global_origin_message(lat, lon, alt, _us(s))


def vfr_hud(s: Snapshot) -> Any:
    """VFR_HUD: ground speed, heading, throttle, altitude and climb rate."""
    v = s.plant["vel"]
    ground = math.hypot(float(v[0]), float(v[1]))
    f = float(np.linalg.norm(s.ctrl["f_b_c"]))
    throttle = round(100 * min(1.0, f / s.thrust_max)) if s.thrust_max > 0 else 0
    _, _, alt, _ = _global(s)
    return mav.MAVLink_vfr_hud_message(ground, ground, _hdg_cdeg(s) // 100, throttle,
                                       alt / 1000, -float(v[2]))


def altitude(s: Snapshot) -> Any:
    """ALTITUDE: the altitudes PX4 reports (AMSL, local, relative to home)."""
    _, _, alt, rel = _global(s)
    amsl = alt / 1000
    local = -float(s.plant["pos"][2])
    return mav.MAVLink_altitude_message(_us(s), amsl, amsl, local, rel / 1000, math.nan,
                                        math.nan)


def system_time(s: Snapshot) -> Any:
    """SYSTEM_TIME: Unix time and time since boot (simulated)."""
    return mav.MAVLink_system_time_message(s.unix_us, _ms(s))


def extended_sys_state(s: Snapshot) -> Any:
    """EXTENDED_SYS_STATE: not a VTOL; on the ground, taking off, in the air or landing."""
    return mav.MAVLink_extended_sys_state_message(mav.MAV_VTOL_STATE_UNDEFINED,
                                                  s.landed_state)


def mission_current(s: Snapshot) -> Any:
    """MISSION_CURRENT: the item flown or next, of how many, and whether a mission is
    flown (MISSION_STATE)."""
    state = (mav.MISSION_STATE_NO_MISSION if s.mission_total == 0 else
             mav.MISSION_STATE_COMPLETE if s.mission_complete else
             mav.MISSION_STATE_ACTIVE if s.mission_active else mav.MISSION_STATE_NOT_STARTED)
    return mav.MAVLink_mission_current_message(s.mission_seq, s.mission_total, state, 0)


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
    """AUTOPILOT_VERSION: capabilities and the PX4 version the bridge presents."""
    caps = (mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT |
            mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE |  # INT32 params, as PX4
            mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT |
            mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET |
            mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED |
            # the plans are served by the mission protocol (mavlink_bridge.mission_protocol)
            mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mav.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE |
            mav.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY)
    return mav.MAVLink_autopilot_version_message(caps, FLIGHT_SW_VERSION, 0, 0, 0,
                                                 [0] * 8, [0] * 8,
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
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: global_position_int,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: gps_raw_int,
    mav.MAVLINK_MSG_ID_HOME_POSITION: home_position,
    mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: gps_global_origin,
    mav.MAVLINK_MSG_ID_VFR_HUD: vfr_hud,
    mav.MAVLINK_MSG_ID_ALTITUDE: altitude,
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: system_time,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: battery_status,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: mission_current,
}


def build_all(msg_id: int, s: Snapshot) -> list[Any]:
    """All messages for ``msg_id`` (SERVO_OUTPUT_RAW goes out on two ports)."""
    if msg_id == mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW:
        return [servo_output_raw(s), servo_output_raw_beta(s)]
    m = build(msg_id, s)
    return [] if m is None else [m]
