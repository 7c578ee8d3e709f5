"""Offboard setpoints: decoded, checked and latched as two channels.

The position channel (SET_POSITION_TARGET_LOCAL_NED) and the attitude channel
(SET_ATTITUDE_TARGET) are latched independently; together they form the full-pose
reference of the controller (``Reference``).  Decoding resolves the frame at the
time of reception, so a latched setpoint is always in absolute NED terms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mavlink_bridge.geodesy import Origin
from mavlink_bridge.geometry import body_rates_to_euler_rates, quat_to_euler, rotation, wrap_pi

# POSITION_TARGET_TYPEMASK
X_IGNORE, Y_IGNORE, Z_IGNORE = 1, 2, 4
VX_IGNORE, VY_IGNORE, VZ_IGNORE = 8, 16, 32
AX_IGNORE, AY_IGNORE, AZ_IGNORE = 64, 128, 256
FORCE_SET, YAW_IGNORE, YAW_RATE_IGNORE = 512, 1024, 2048
# ATTITUDE_TARGET_TYPEMASK
ROLL_RATE_IGNORE, PITCH_RATE_IGNORE, YAW_RATE_IGNORE_ATT = 1, 2, 4
THRUST_BODY_SET, THROTTLE_IGNORE, ATTITUDE_IGNORE = 32, 64, 128

MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_OFFSET_NED, MAV_FRAME_BODY_NED = 1, 7, 8
MAV_FRAME_BODY_OFFSET_NED = 9
MAV_FRAME_GLOBAL_INT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 5, 6
MAV_FRAME_GLOBAL_TERRAIN_ALT_INT = 11

#: largest accepted |yaw| of a position setpoint (rad): one turn covers both conventions
#: clients use, [-pi, pi] and [0, 2 pi); anything larger can only be a unit error (degrees
#: sent as radians) or garbage, and wrapping it would fly an arbitrary heading
YAW_MAX = 2 * math.pi


class Rejected(ValueError):
    """A setpoint refused, with the reason told to the ground station."""


@dataclass
class PositionSetpoint:
    """Absolute NED values; NaN where the type_mask ignores a field."""

    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    yaw: float
    yaw_rate: float


@dataclass
class AttitudeSetpoint:
    """A decoded SET_ATTITUDE_TARGET: Euler angles, Euler-angle rates and thrust, each None where
    the message's mask ignores it."""
    euler: np.ndarray | None  # roll, pitch, yaw (rad); None: attitude ignored
    euler_rate: np.ndarray | None  # Euler-angle rates from the body rates; None: ignored
    thrust: float | None  # collective thrust 0..1 (decoded, not flown: see docs)
    thrust_body: np.ndarray | None  # normalized body thrust vector (decoded, not flown)


@dataclass
class Limits:
    """Safety limits of setpoints (FPB_SP_* parameters): the largest |x|, |y| and |z| of a
    position (m), speed (m/s), acceleration (m/s^2), rate (rad/s), roll/pitch (rad)."""
    xy: float = 100.0
    z: float = 100.0
    vel: float = 10.0
    acc: float = 20.0
    rate: float = 6.0
    tilt: float = 1.4


@dataclass
class VehicleState:
    """The vehicle's position (NED, m) and Euler angles (rad) that relative setpoints refer to."""
    pos: np.ndarray
    euler: np.ndarray


def _fields(msg: object, names: tuple[str, ...], mask: int, bits: tuple[int, int, int]
            ) -> np.ndarray:
    return np.array([math.nan if mask & b else float(getattr(msg, n))
                     for n, b in zip(names, bits, strict=True)])


def decode_position(msg: object, state: VehicleState, limits: Limits) -> PositionSetpoint:
    """A SET_POSITION_TARGET_LOCAL_NED (local, offset or body frames) as a setpoint in the local
    NED frame, checked against the limits; Rejected with the reason otherwise."""
    mask = int(msg.type_mask)  # type: ignore[attr-defined]
    frame = int(msg.coordinate_frame)  # type: ignore[attr-defined]
    if frame not in (MAV_FRAME_LOCAL_NED, MAV_FRAME_LOCAL_OFFSET_NED, MAV_FRAME_BODY_NED,
                     MAV_FRAME_BODY_OFFSET_NED):
        raise Rejected(f"coordinate frame {frame} unsupported")
    if mask & FORCE_SET:
        raise Rejected("force setpoints unsupported")
    used = [(("x", "y", "z"), (X_IGNORE, Y_IGNORE, Z_IGNORE)),
            (("vx", "vy", "vz"), (VX_IGNORE, VY_IGNORE, VZ_IGNORE)),
            (("afx", "afy", "afz"), (AX_IGNORE, AY_IGNORE, AZ_IGNORE))]
    # every field the mask does not ignore must be finite (PX4 also rejects NaN there)
    for names, bits in used:
        for n, b in zip(names, bits, strict=True):
            if not mask & b and not math.isfinite(float(getattr(msg, n))):
                raise Rejected(f"{n} not finite")
    for n, b in (("yaw", YAW_IGNORE), ("yaw_rate", YAW_RATE_IGNORE)):
        if not mask & b and not math.isfinite(float(getattr(msg, n))):
            raise Rejected(f"{n} not finite")
    if not mask & YAW_IGNORE and abs(float(msg.yaw)) > YAW_MAX:  # type: ignore[attr-defined]
        raise Rejected("|yaw| above 2 pi rad")
    pos = _fields(msg, used[0][0], mask, used[0][1])
    vel = _fields(msg, used[1][0], mask, used[1][1])
    acc = _fields(msg, used[2][0], mask, used[2][1])
    if frame == MAV_FRAME_LOCAL_OFFSET_NED:
        pos = state.pos + pos  # NaN stays NaN where ignored
    elif frame in (MAV_FRAME_BODY_NED, MAV_FRAME_BODY_OFFSET_NED):
        # as PX4 for BODY_NED: velocity and acceleration rotated from body to NED (ignored
        # components count as 0), position unused.  BODY_OFFSET_NED (MAVLink: the same as
        # BODY_FRD, origin travelling with the vehicle): the position is an offset in the
        # body frame, rotated the same way and added to the current position
        r = rotation(*state.euler)
        if frame == MAV_FRAME_BODY_OFFSET_NED and not np.all(np.isnan(pos)):
            pos = state.pos + r @ np.nan_to_num(pos)
        else:
            pos = np.full(3, math.nan)
        if not np.all(np.isnan(vel)):
            vel = r @ np.nan_to_num(vel)
        if not np.all(np.isnan(acc)):
            acc = r @ np.nan_to_num(acc)
    yaw = math.nan if mask & YAW_IGNORE else wrap_pi(float(msg.yaw))  # type: ignore[attr-defined]
    yaw_rate = math.nan if mask & YAW_RATE_IGNORE else float(msg.yaw_rate)  # type: ignore
    sp = PositionSetpoint(pos, vel, acc, yaw, yaw_rate)
    _limit(sp, limits)
    if np.all(np.isnan(pos)) and np.all(np.isnan(vel)) and np.all(np.isnan(acc)) \
            and math.isnan(yaw) and math.isnan(yaw_rate):
        raise Rejected("every field ignored")
    return sp


@dataclass
class _LocalView:
    """A SET_POSITION_TARGET_GLOBAL_INT seen as a local-NED one (same type_mask)."""

    type_mask: int
    x: float
    y: float
    z: float
    vx: float
    vy: float
    vz: float
    afx: float
    afy: float
    afz: float
    yaw: float
    yaw_rate: float
    coordinate_frame: int = MAV_FRAME_LOCAL_NED


def decode_global(msg: object, state: VehicleState, limits: Limits, origin: Origin
                  ) -> PositionSetpoint:
    """SET_POSITION_TARGET_GLOBAL_INT -> the local setpoint.  GLOBAL_INT: alt in m AMSL;
    GLOBAL_RELATIVE_ALT_INT: alt in m above home (the origin).  A field the type_mask
    ignores takes the vehicle's own value for the conversion and stays ignored."""
    mask = int(msg.type_mask)  # type: ignore[attr-defined]
    frame = int(msg.coordinate_frame)  # type: ignore[attr-defined]
    if frame == MAV_FRAME_GLOBAL_TERRAIN_ALT_INT:
        raise Rejected("terrain altitude unsupported: no terrain model")
    if frame not in (MAV_FRAME_GLOBAL_INT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
        raise Rejected(f"coordinate frame {frame} unsupported")
    here = origin.to_geodetic(*(float(v) for v in state.pos))
    lat_i, lon_i = int(msg.lat_int), int(msg.lon_int)  # type: ignore[attr-defined]
    alt = float(msg.alt)  # type: ignore[attr-defined]
    lat = here[0] if mask & X_IGNORE else lat_i * 1e-7
    lon = here[1] if mask & Y_IGNORE else lon_i * 1e-7
    if not mask & Z_IGNORE:
        if not math.isfinite(alt):
            raise Rejected("alt not finite")
        if frame == MAV_FRAME_GLOBAL_RELATIVE_ALT_INT:
            alt += origin.alt
    else:
        alt = here[2]
    if abs(lat) > 90.0 or abs(lon) > 180.0:
        raise Rejected("latitude/longitude out of range")
    n, e, d = origin.to_ned(lat, lon, alt)
    v = [float(getattr(msg, k)) for k in ("vx", "vy", "vz", "afx", "afy", "afz", "yaw",
                                          "yaw_rate")]
    view = _LocalView(mask, n, e, d, v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7])
    return decode_position(view, state, limits)


def _limit(sp: PositionSetpoint, lim: Limits) -> None:
    def over(v: np.ndarray, bound: float) -> bool:
        return bool(np.any(np.abs(np.nan_to_num(v)) > bound))

    if over(sp.pos[:2], lim.xy):
        raise Rejected(f"|x|, |y| above {lim.xy:g} m")
    if over(sp.pos[2:], lim.z):
        raise Rejected(f"|z| above {lim.z:g} m")
    if over(sp.vel, lim.vel):
        raise Rejected(f"velocity above {lim.vel:g} m/s")
    if over(sp.acc, lim.acc):
        raise Rejected(f"acceleration above {lim.acc:g} m/s^2")
    if not math.isnan(sp.yaw_rate) and abs(sp.yaw_rate) > lim.rate:
        raise Rejected(f"yaw rate above {lim.rate:g} rad/s")


def decode_attitude(msg: object, limits: Limits) -> AttitudeSetpoint:
    """A SET_ATTITUDE_TARGET as an attitude setpoint, checked against the limits; Rejected with the
    reason otherwise."""
    mask = int(msg.type_mask)  # type: ignore[attr-defined]
    euler: np.ndarray | None = None
    if not mask & ATTITUDE_IGNORE:
        q = np.array([float(v) for v in msg.q])  # type: ignore[attr-defined]
        if not np.all(np.isfinite(q)):
            raise Rejected("quaternion not finite")
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > 0.1:
            raise Rejected(f"quaternion norm {norm:.3g} (must be 1)")
        euler = np.array(quat_to_euler(q / norm))
        if max(abs(euler[0]), abs(euler[1])) > limits.tilt:
            raise Rejected(f"roll/pitch beyond {math.degrees(limits.tilt):.0f} deg")
    rate_bits = (ROLL_RATE_IGNORE, PITCH_RATE_IGNORE, YAW_RATE_IGNORE_ATT)
    rates = np.array([math.nan if mask & b else float(getattr(msg, n)) for n, b in zip(
        ("body_roll_rate", "body_pitch_rate", "body_yaw_rate"), rate_bits, strict=True)])
    for r, b in zip(rates, rate_bits, strict=True):
        if not mask & b and not math.isfinite(r):
            raise Rejected("body rate not finite")
    if np.any(np.abs(np.nan_to_num(rates)) > limits.rate):
        raise Rejected(f"body rate above {limits.rate:g} rad/s")
    euler_rate = None
    if not np.all(np.isnan(rates)):
        phi, theta = (euler[0], euler[1]) if euler is not None else (0.0, 0.0)
        euler_rate = np.array(body_rates_to_euler_rates(phi, theta, *np.nan_to_num(rates)))
    thrust = None
    thrust_body = None
    if mask & THRUST_BODY_SET:
        tb = np.array([float(v) for v in getattr(msg, "thrust_body", [0.0, 0.0, 0.0])])
        if not np.all(np.isfinite(tb)) or np.any(np.abs(tb) > 1.0):
            raise Rejected("thrust_body must be finite and within [-1, 1]")
        thrust_body = tb
    elif not mask & THROTTLE_IGNORE:
        t = float(msg.thrust)  # type: ignore[attr-defined]
        if not math.isfinite(t) or not 0.0 <= t <= 1.0:
            raise Rejected("thrust must be finite and within [0, 1]")
        thrust = t
    if euler is None and euler_rate is None and thrust is None and thrust_body is None:
        raise Rejected("every field ignored")
    return AttitudeSetpoint(euler, euler_rate, thrust, thrust_body)


@dataclass
class Reference:
    """The controller's references, built from the hold pose and the latched channels."""

    pos: np.ndarray
    euler: np.ndarray
    vel: np.ndarray = field(default_factory=lambda: np.zeros(3))
    acc: np.ndarray = field(default_factory=lambda: np.zeros(3))
    euler_rate: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def hold(cls, pos: np.ndarray, euler: np.ndarray) -> Reference:
        """A reference that holds pos and euler still."""
        return cls(np.array(pos, float), np.array(euler, float))

    def apply_position(self, sp: PositionSetpoint) -> None:
        """Take the given components of a position setpoint (ignored ones keep their value;
        velocity and acceleration as given, zero where ignored)."""
        have = ~np.isnan(sp.pos)
        self.pos[have] = sp.pos[have]
        self.vel = np.nan_to_num(sp.vel)
        self.acc = np.nan_to_num(sp.acc)
        if not math.isnan(sp.yaw):
            self.euler[2] = sp.yaw
        self.euler_rate[2] = 0.0 if math.isnan(sp.yaw_rate) else sp.yaw_rate

    def apply_attitude(self, sp: AttitudeSetpoint) -> None:
        """Take an attitude setpoint's angles where given, and its Euler-angle rates (zero where
        ignored)."""
        if sp.euler is not None:
            self.euler = sp.euler.copy()
        self.euler_rate = np.zeros(3) if sp.euler_rate is None else sp.euler_rate.copy()

    def integrate(self, pos_sp: PositionSetpoint | None, att_sp: AttitudeSetpoint | None,
                  dt: float) -> None:
        """Axes commanded by velocity (or yaw rate) only: move the reference along."""
        if pos_sp is not None:
            free = np.isnan(pos_sp.pos) & ~np.isnan(pos_sp.vel)
            self.pos[free] += pos_sp.vel[free] * dt
            if math.isnan(pos_sp.yaw) and not math.isnan(pos_sp.yaw_rate):
                self.euler[2] = wrap_pi(self.euler[2] + pos_sp.yaw_rate * dt)
        if att_sp is not None and att_sp.euler is None and att_sp.euler_rate is not None:
            self.euler = self.euler + att_sp.euler_rate * dt
            self.euler[2] = wrap_pi(self.euler[2])

    def as_inputs(self) -> dict[str, np.ndarray]:
        """The reference as the controller FMU's reference inputs by name."""
        return {"pos_ref": self.pos, "euler_ref": self.euler, "vel_ref": self.vel,
                "acc_ref": self.acc, "euler_rate_ref": self.euler_rate}
