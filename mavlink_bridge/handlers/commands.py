"""Commands and modes: COMMAND_LONG / COMMAND_INT (arming, DO_SET_MODE, the message
commands of :mod:`~mavlink_bridge.handlers.telemetry`), SET_MODE, and the messages the
bridge does not fly (told once per sender)."""

from __future__ import annotations

import math
import time
from typing import Any

from mavlink_bridge import modes
from mavlink_bridge.context import Context, Source
from mavlink_bridge.handlers import telemetry
from mavlink_bridge.links import Endpoint
from mavlink_bridge.telemetry import mav

UNSUPPORTED_TEXT_PERIOD = 10.0  # wall s between "not supported" texts to one sender
#: the params (1-based) each implemented command uses; NaN/inf there is DENIED.  Others
#: are ignored, as common.xml marks them reserved or lets NaN mean "no change".
COMMAND_PARAMS: dict[int, tuple[int, ...]] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: (1,),
    mav.MAV_CMD_DO_SET_MODE: (1, 2, 3),
    **telemetry.COMMAND_PARAMS,
}


def on_command(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """COMMAND_LONG or COMMAND_INT: checked, carried out, acknowledged, then answered."""
    cmd = int(msg.command)
    p = [float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4)]
    if msg.get_type() == "COMMAND_LONG":
        p += [float(msg.param5), float(msg.param6), float(msg.param7)]
    else:  # COMMAND_INT: x, y are integers, z a float
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
        if p[0] not in (0.0, 1.0):
            return mav.MAV_RESULT_DENIED
        arm = p[0] == 1.0
        if arm != ctx.armed:
            ctx.armed = arm
            if ctx.mode == "OFFBOARD" and arm:
                ctx.enter_offboard()
            elif not arm:
                ctx.hold()
                ctx.mode = "HOLD"
            ctx.heartbeat_now()
        return mav.MAV_RESULT_ACCEPTED
    if cmd == mav.MAV_CMD_DO_SET_MODE:
        return request_mode(ctx, int(p[0]), int(p[1]), int(p[2]))
    return telemetry.command(ctx, ep, cmd, p)


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
    "SET_ACTUATOR_CONTROL_TARGET": on_unsupported,
}
"""The command and mode messages, and those told unsupported."""
