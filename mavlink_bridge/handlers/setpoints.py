"""Offboard setpoints: SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT and SET_ATTITUDE_TARGET,
decoded and checked against the limits (:mod:`mavlink_bridge.setpoints`), then flown when the
vehicle is armed in OFFBOARD."""

from __future__ import annotations

from typing import Any

from mavlink_bridge.context import Context, Source
from mavlink_bridge.links import Endpoint
from mavlink_bridge.setpoints import Rejected, decode_attitude, decode_global, decode_position
from mavlink_bridge.telemetry import mav


def on_position(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """A position/velocity/acceleration target, local or global: kept as the latest setpoint."""
    try:
        if msg.get_type() == "SET_POSITION_TARGET_GLOBAL_INT":
            sp = decode_global(msg, ctx.vehicle(), ctx.limits, ctx.origin)
        else:
            sp = decode_position(msg, ctx.vehicle(), ctx.limits)
    except Rejected as e:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, f"POSITION_TARGET rejected: {e}", limited=True)
        return
    ctx.pos_sp = sp
    ctx.last_setpoint = ctx.session.time
    ctx.frozen = False
    if ctx.control_active:
        ctx.ref.apply_position(sp)


def on_attitude(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """An attitude/body-rate target: kept as the latest setpoint."""
    try:
        sp = decode_attitude(msg, ctx.limits)
    except Rejected as e:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, f"ATTITUDE_TARGET rejected: {e}", limited=True)
        return
    ctx.att_sp = sp
    ctx.last_setpoint = ctx.session.time
    ctx.frozen = False
    if ctx.control_active:
        ctx.ref.apply_attitude(sp)


HANDLERS = {
    "SET_POSITION_TARGET_LOCAL_NED": on_position,
    "SET_POSITION_TARGET_GLOBAL_INT": on_position,
    "SET_ATTITUDE_TARGET": on_attitude,
}
"""The setpoint messages."""
