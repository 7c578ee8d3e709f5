"""Commands and modes: COMMAND_LONG / COMMAND_INT (arming, DO_SET_MODE, the message
commands of :mod:`~mavlink_bridge.handlers.telemetry`), SET_MODE, and the messages the
bridge does not fly (told once per sender)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from mavlink_bridge import auto, modes
from mavlink_bridge.context import Context, Source
from mavlink_bridge.handlers import telemetry
from mavlink_bridge.links import Endpoint
from mavlink_bridge.telemetry import mav
from orchestrator.mission import items

UNSUPPORTED_TEXT_PERIOD = 10.0  # wall s between "not supported" texts to one sender
#: the params (1-based) each implemented command uses; NaN/inf there is DENIED.  Others
#: are ignored, as common.xml marks them reserved or lets NaN mean "no change".
COMMAND_PARAMS: dict[int, tuple[int, ...]] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: (1,),
    mav.MAV_CMD_DO_SET_MODE: (1, 2, 3),
    # flight from the ground (mavlink_bridge.auto): NaN is "as you are" in these
    mav.MAV_CMD_NAV_TAKEOFF: (),
    mav.MAV_CMD_NAV_LAND: (),
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: (),
    mav.MAV_CMD_MISSION_START: (),
    mav.MAV_CMD_DO_REPOSITION: (),
    mav.MAV_CMD_DO_CHANGE_SPEED: (1, 2),
    mav.MAV_CMD_DO_SET_HOME: (1,),
    mav.MAV_CMD_DO_SET_MISSION_CURRENT: (1,),
    mav.MAV_CMD_DO_PAUSE_CONTINUE: (1,),
    **telemetry.COMMAND_PARAMS,
}
INT32_MAX = 2**31 - 1  # COMMAND_INT's x, y when unused


def on_command(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """COMMAND_LONG or COMMAND_INT: checked, carried out, acknowledged, then answered."""
    cmd = int(msg.command)
    p = [float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4)]
    if msg.get_type() == "COMMAND_LONG":
        p += [float(msg.param5), float(msg.param6), float(msg.param7)]
    else:  # COMMAND_INT: x, y are integers (degrees x 1e7 in a global frame), z a float
        frame = int(msg.frame)
        if frame in items.POSITION_FRAMES and frame != items.FRAME_LOCAL_NED:
            lat, lon = (math.nan if v == INT32_MAX else v * 1e-7 for v in (msg.x, msg.y))
            z = float(msg.z) + (ctx.home_alt if frame in items.RELATIVE_FRAMES else 0.0)
            p += [lat, lon, z]
        else:
            p += [float(msg.x), float(msg.y), float(msg.z)]
    bad = next((i for i in COMMAND_PARAMS.get(cmd, ()) if not math.isfinite(p[i - 1])), None)
    if cmd not in COMMAND_PARAMS:
        result = mav.MAV_RESULT_UNSUPPORTED
        if cmd in modes.COMMAND_REASONS:
            ctx.statustext(mav.MAV_SEVERITY_WARNING, modes.COMMAND_REASONS[cmd], limited=True)
    elif bad is not None:
        result = mav.MAV_RESULT_DENIED
        ctx.statustext(mav.MAV_SEVERITY_WARNING,
                       f"command {cmd} denied: param{bad} is {p[bad - 1]}", limited=True)
    else:
        result = command(ctx, ep, cmd, p)
    ctx.ack(ep, cmd, result, src)
    if result == mav.MAV_RESULT_ACCEPTED and cmd in telemetry.COMMAND_PARAMS:
        telemetry.answer(ctx, ep, cmd, p)


def command(ctx: Context, ep: Endpoint, cmd: int, p: list[float]) -> int:
    """Carry out an implemented command with finite params: its MAV_RESULT."""
    if cmd == mav.MAV_CMD_COMPONENT_ARM_DISARM:
        return arm_disarm(ctx, p)
    if cmd == mav.MAV_CMD_DO_SET_MODE:
        return request_mode(ctx, int(p[0]), int(p[1]), int(p[2]))
    if cmd in FLIGHT_COMMANDS:
        why = FLIGHT_COMMANDS[cmd](ctx, p)
        if why is None:
            return mav.MAV_RESULT_ACCEPTED
        ctx.statustext(mav.MAV_SEVERITY_WARNING, f"{_NAMES.get(cmd, cmd)} refused: {why}",
                       limited=True)
        return mav.MAV_RESULT_DENIED
    return telemetry.command(ctx, ep, cmd, p)


def arm_disarm(ctx: Context, p: list[float]) -> int:
    """Arm, or disarm: refused in flight (the rotors would stop) unless forced with param2
    21196, as PX4 does; arming in AUTO.MISSION starts the mission."""
    if p[0] not in (0.0, 1.0):
        return mav.MAV_RESULT_DENIED
    arm = p[0] == 1.0
    if arm == ctx.armed:
        return mav.MAV_RESULT_ACCEPTED
    if not arm:
        if ctx.ground_start and not ctx.landed and p[1] != auto.FORCE_DISARM:
            ctx.statustext(mav.MAV_SEVERITY_WARNING,
                           "disarm refused: not landed (force: param2 21196)", limited=True)
            return mav.MAV_RESULT_DENIED
        ctx.disarm()
        return mav.MAV_RESULT_ACCEPTED
    ctx.set_armed(True)
    if ctx.mode == "OFFBOARD":
        ctx.enter_offboard()
    elif ctx.mode == "MISSION":
        why = auto.start_mission(ctx)
        if why is not None:
            ctx.set_mode("HOLD")
    elif ctx.mode in ("LAND", "RTL", "TAKEOFF"):  # nothing to land from: wait in HOLD
        ctx.hold()
        ctx.mode = "HOLD"
    ctx.heartbeat_now()
    return mav.MAV_RESULT_ACCEPTED


def _takeoff(ctx: Context, p: list[float]) -> str | None:
    """NAV_TAKEOFF: param4 yaw (deg), param7 altitude (m AMSL; NaN: MIS_TAKEOFF_ALT above
    home), straight up from where the vehicle is."""
    if not ctx.armed:
        return "disarmed: arm first"
    auto.fly(ctx, "TAKEOFF", [auto.takeoff_item(ctx, p[6], p[3])])
    return None


def _land(ctx: Context, p: list[float]) -> str | None:
    """NAV_LAND: param4 yaw, param5/6 where (NaN: here)."""
    if not ctx.armed:
        return "disarmed: arm first"
    auto.fly(ctx, "LAND", [auto.point_item(ctx, items.NAV_LAND, p[4], p[5], math.nan, p[3])])
    return None


def _rtl(ctx: Context, p: list[float]) -> str | None:
    """NAV_RETURN_TO_LAUNCH."""
    return auto.start_mode(ctx, "RTL")


def _mission_start(ctx: Context, p: list[float]) -> str | None:
    """MISSION_START: param1 the first item (NaN or 0: from the current item)."""
    first = None if not math.isfinite(p[0]) or p[0] <= 0 else int(p[0])
    return auto.start_mission(ctx, first)


def _reposition(ctx: Context, p: list[float]) -> str | None:
    """DO_REPOSITION (QGroundControl's Go-to, and its Pause with every position NaN): fly to
    lat, lon, alt (NaN: where the vehicle is) at param1 m/s (-1, NaN: the cruise speed),
    heading param4 (radians, as common.xml and PX4 say; NaN: kept), then hold there
    (AUTO.LOITER)."""
    if not ctx.armed or ctx.landed:
        return "on the ground: take off first"
    speed = p[0]
    if math.isfinite(speed) and speed > 0:
        if speed > ctx.params.get("MPC_XY_VEL_MAX"):
            return f"speed {speed:g} m/s above MPC_XY_VEL_MAX"
        ctx.cruise = speed
    target = auto.point_item(ctx, items.NAV_WAYPOINT, p[4], p[5], p[6], math.degrees(p[3]))
    if not math.isnan(p[4]) and (abs(p[4]) > 90 or abs(p[5]) > 180):
        return "latitude/longitude out of range"
    auto.fly(ctx, "HOLD", [target])
    return None


def _change_speed(ctx: Context, p: list[float]) -> str | None:
    """DO_CHANGE_SPEED: param1 0/1 horizontal, 2 climb, 3 descent; param2 m/s (-1: no
    change); above MPC_XY_VEL_MAX refused, not clamped."""
    kind, speed = int(p[0]), p[1]
    if kind not in (0, 1, 2, 3):
        return f"speed type {kind} unknown"
    if speed == -1.0:
        return None
    if not speed > 0:
        return "speed must be positive"
    if kind in (0, 1) and speed > ctx.params.get("MPC_XY_VEL_MAX"):
        return f"{speed:g} m/s above MPC_XY_VEL_MAX {ctx.params.get('MPC_XY_VEL_MAX'):g}"
    if kind in (0, 1):
        ctx.cruise = speed
    if ctx.auto is not None:
        s = ctx.auto.settings
        if kind in (0, 1):
            s.cruise = speed
        elif kind == 2:
            s.climb = speed
        else:
            s.descent = speed
    return None


def _set_home(ctx: Context, p: list[float]) -> str | None:
    """DO_SET_HOME: param1 1 = here, else param5/6/7 lat, lon, alt (m AMSL)."""
    if p[0] == 1.0:
        pos = auto.here(ctx)
        if not ctx.landed:
            pos[2] = ctx.home[2]  # home stays on the ground's level
        return set_home(ctx, pos)
    if not all(math.isfinite(v) for v in p[4:7]):
        return "lat, lon and alt needed (or param1 = 1: here)"
    if abs(p[4]) > 90 or abs(p[5]) > 180:
        return "latitude/longitude out of range"
    return set_home(ctx, np.array(ctx.origin.to_ned(p[4], p[5], p[6])))


def set_home(ctx: Context, pos: np.ndarray) -> str | None:
    """Move home (returns, relative altitudes, HOME_POSITION) to the local point pos."""
    lim = ctx.limits
    if abs(pos[0]) > lim.xy or abs(pos[1]) > lim.xy or abs(pos[2]) > lim.z:
        return f"beyond the setpoint limits (FPB_SP_XY_MAX {lim.xy:g} m)"
    ctx.home = np.array(pos, float)
    auto.refresh_fence(ctx)
    ctx.statustext(mav.MAV_SEVERITY_INFO, "home set")
    return None


def _set_current(ctx: Context, p: list[float]) -> str | None:
    """DO_SET_MISSION_CURRENT: go on from item param1."""
    return ctx.set_current_item(int(p[0]))


def _pause_continue(ctx: Context, p: list[float]) -> str | None:
    """DO_PAUSE_CONTINUE: 0 holds where the vehicle is, 1 goes on with the mission."""
    if p[0] == 0.0:
        return _reposition(ctx, [math.nan] * 7)
    return auto.start_mission(ctx)


FLIGHT_COMMANDS = {
    mav.MAV_CMD_NAV_TAKEOFF: _takeoff,
    mav.MAV_CMD_NAV_LAND: _land,
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: _rtl,
    mav.MAV_CMD_MISSION_START: _mission_start,
    mav.MAV_CMD_DO_REPOSITION: _reposition,
    mav.MAV_CMD_DO_CHANGE_SPEED: _change_speed,
    mav.MAV_CMD_DO_SET_HOME: _set_home,
    mav.MAV_CMD_DO_SET_MISSION_CURRENT: _set_current,
    mav.MAV_CMD_DO_PAUSE_CONTINUE: _pause_continue,
}
"""The flight commands (mavlink_bridge.auto): each returns why it is refused, or None."""
_NAMES = {mav.MAV_CMD_NAV_TAKEOFF: "takeoff", mav.MAV_CMD_NAV_LAND: "land",
          mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: "return", mav.MAV_CMD_MISSION_START: "mission",
          mav.MAV_CMD_DO_REPOSITION: "go-to", mav.MAV_CMD_DO_CHANGE_SPEED: "speed change",
          mav.MAV_CMD_DO_SET_HOME: "set home",
          mav.MAV_CMD_DO_SET_MISSION_CURRENT: "set current item",
          mav.MAV_CMD_DO_PAUSE_CONTINUE: "pause/continue"}


def request_mode(ctx: Context, base_mode: int, main: int, sub: int) -> int:
    """The one road for SET_MODE and DO_SET_MODE (PX4 turns the message into the
    command): the MAV_RESULT; a refusal is told by STATUSTEXT, an acceptance by an
    immediate HEARTBEAT."""
    r = modes.resolve(base_mode, main, sub)
    before = ctx.mode
    if r.mode is None:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, f"{r.name} refused: {r.reason}", limited=True)
        return mav.MAV_RESULT_DENIED
    if r.mode == "OFFBOARD":
        if ctx.session.time - ctx.last_setpoint > ctx.timeout:
            ctx.statustext(mav.MAV_SEVERITY_WARNING, "offboard refused: no recent setpoint")
            return mav.MAV_RESULT_TEMPORARILY_REJECTED
        if ctx.mode != "OFFBOARD":
            ctx.enter_offboard()
    elif r.mode == "MISSION" and not ctx.armed:  # PX4: the mission starts when armed
        if not ctx.plans[items.MISSION]:
            ctx.statustext(mav.MAV_SEVERITY_WARNING, f"{r.name} refused: no mission uploaded",
                           limited=True)
            return mav.MAV_RESULT_DENIED
        ctx.hold()
        ctx.set_mode("MISSION")
    elif r.mode in ("TAKEOFF", "LAND", "RTL", "MISSION") and r.mode != ctx.mode:
        why = auto.start_mode(ctx, r.mode)
        if why is not None:
            ctx.statustext(mav.MAV_SEVERITY_WARNING, f"{r.name} refused: {why}", limited=True)
            return mav.MAV_RESULT_DENIED
    elif ctx.mode != r.mode:
        ctx.hold()
        ctx.set_mode(r.mode)
    if ctx.mode == before:
        ctx.heartbeat_now()  # a change sent one already; the requester hears either way
    return mav.MAV_RESULT_ACCEPTED


def on_set_mode(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """SET_MODE, acknowledged as DO_SET_MODE (as PX4's commander does)."""
    main, sub = modes.from_custom_mode(int(msg.custom_mode))
    result = request_mode(ctx, int(msg.base_mode), main, sub)
    ctx.ack(ep, mav.MAV_CMD_DO_SET_MODE, result, src)


def on_set_home_position(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """SET_HOME_POSITION (the message, deprecated but still sent): home to its lat, lon and
    altitude; a refusal is told."""
    lat, lon, alt = auto.message_home(msg)
    why = ("latitude/longitude out of range" if abs(lat) > 90 or abs(lon) > 180 else
           set_home(ctx, np.array(ctx.origin.to_ned(lat, lon, alt))))
    if why is not None:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, f"set home refused: {why}", limited=True)


def on_heartbeat(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """Ground stations announce themselves; nothing to do."""


def on_unsupported(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """Say once per sender and UNSUPPORTED_TEXT_PERIOD that a message is not flown."""
    key = (msg.get_type(), src[0], src[1])
    now = time.monotonic()
    if now - ctx.told_unsupported.get(key, -math.inf) < UNSUPPORTED_TEXT_PERIOD:
        return
    ctx.told_unsupported[key] = now
    ctx.statustext(mav.MAV_SEVERITY_WARNING, f"{key[0][:32]} not supported", limited=True)


HANDLERS = {
    "HEARTBEAT": on_heartbeat,
    "COMMAND_LONG": on_command,
    "COMMAND_INT": on_command,
    "SET_MODE": on_set_mode,
    "SET_HOME_POSITION": on_set_home_position,
    "SET_ACTUATOR_CONTROL_TARGET": on_unsupported,
}
"""The command and mode messages, and those told unsupported."""
