"""Offboard setpoints: SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT and SET_ATTITUDE_TARGET,
decoded and checked against the limits (:mod:`mavlink_bridge.setpoints`), then flown when the
vehicle is armed in OFFBOARD."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from mavlink_bridge.context import Context, Source
from mavlink_bridge.links import Endpoint
from mavlink_bridge.setpoints import Rejected, decode_attitude, decode_global, decode_position
from mavlink_bridge.telemetry import mav

T = TypeVar("T")


def on_position(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """A position/velocity/acceleration target, local or global: kept as the latest setpoint."""
    if msg.get_type() == "SET_POSITION_TARGET_GLOBAL_INT":
        sp = _decoded(ctx, "POSITION_TARGET",
                      lambda: decode_global(msg, ctx.vehicle(), ctx.limits, ctx.origin))
    else:
        sp = _decoded(ctx, "POSITION_TARGET",
                      lambda: decode_position(msg, ctx.vehicle(), ctx.limits))
    if sp is not None:
        ctx.pos_sp = sp
        if ctx.control_active:
            ctx.ref.apply_position(sp)


def on_attitude(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """An attitude/body-rate target: kept as the latest setpoint."""
    sp = _decoded(ctx, "ATTITUDE_TARGET", lambda: decode_attitude(msg, ctx.limits))
    if sp is not None:
        ctx.att_sp = sp
        if ctx.control_active:
            ctx.ref.apply_attitude(sp)


def _decoded(ctx: Context, what: str, decode: Callable[[], T]) -> T | None:
    """The setpoint ``decode`` returns, the clock of setpoint loss restarted and a frozen pose
    thawed; or None, the rejection told (rate-limited)."""
    try:
        sp = decode()
    except Rejected as e:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, f"{what} rejected: {e}", limited=True)
        return None
    ctx.last_setpoint = ctx.session.time
    ctx.frozen = False
    return sp


HANDLERS = {
    "SET_POSITION_TARGET_LOCAL_NED": on_position,
    "SET_POSITION_TARGET_GLOBAL_INT": on_position,
    "SET_ATTITUDE_TARGET": on_attitude,
}
"""The setpoint messages."""
