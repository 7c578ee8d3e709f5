"""The parameter protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ and PARAM_SET on the
controller's tunable parameters and the bridge's own FPB_ ones
(:class:`~mavlink_bridge.params.ParameterTable`)."""

from __future__ import annotations

from typing import Any

from mavlink_bridge import params as mparams
from mavlink_bridge.context import Context, Source
from mavlink_bridge.links import Endpoint
from mavlink_bridge.telemetry import mav


def param_id(raw: Any) -> str:
    """A message's param_id field as text (up to the first NUL)."""
    if isinstance(raw, bytes | bytearray):
        raw = raw.decode("ascii", errors="replace")
    return str(raw).split("\x00", 1)[0]


def param_value(ctx: Context, index: int) -> Any:
    """PARAM_VALUE of the parameter at index, with the value in force."""
    p = ctx.params.items[index]
    value, kind = mparams.encode(p.value, p.integer)  # INT32 byte-wise, as PX4
    return mav.MAVLink_param_value_message(p.name.encode("ascii"), value, kind,
                                           len(ctx.params), index)


def on_param_list(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """Every parameter, in index order."""
    for i in range(len(ctx.params)):
        ep.send(param_value(ctx, i))


def on_param_read(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """One parameter, by index or (index -1) by name."""
    index = int(msg.param_index)
    if index < 0:
        found = ctx.params.index(param_id(msg.param_id))
        if found is None:
            unknown_param(ctx, ep, msg, src, param_id(msg.param_id), index)
            return
        index = found
    if 0 <= index < len(ctx.params):
        ep.send(param_value(ctx, index))
    else:
        unknown_param(ctx, ep, msg, src, "", index)


def unknown_param(ctx: Context, ep: Endpoint, msg: Any, src: Source, name: str,
                  index: int) -> None:
    """As PX4: a STATUSTEXT naming it (and no PARAM_VALUE); plus PARAM_ERROR, which
    newer MAVLink defines for this."""
    ctx.statustext(mav.MAV_SEVERITY_INFO, f"unknown param: {name or index}"[:50], limited=True)
    raw = param_id(msg.param_id).encode("ascii", "replace")[:16]
    ep.send(mav.MAVLink_param_error_message(src[0], src[1], raw, index,
                                            mav.MAV_PARAM_ERROR_DOES_NOT_EXIST))


def on_param_set(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """Set a parameter (checked by the table); every endpoint hears the value in force.  A
    refusal is told three ways: STATUSTEXT with the reason, PARAM_ERROR to the sender (which
    MAVSDK and QGroundControl turn into an error result at once) and the PARAM_VALUE in force.
    The bridge's own FPB_ parameters (setpoint limits and timeouts) change only on a signed
    link (or with ``fullpose fly --limit``)."""
    name = param_id(msg.param_id)
    index = ctx.params.index(name)
    kind = int(msg.param_type)
    value = mparams.decode(float(msg.param_value), kind)
    refused: mparams.Refused | None
    if index is None:
        refused = mparams.Refused(f"unknown parameter {name[:30]}",
                                  mparams.MAV_PARAM_ERROR_DOES_NOT_EXIST)
    elif value is None:
        refused = mparams.Refused(f"{name} refused: param_type {kind} unsupported",
                                  mparams.MAV_PARAM_ERROR_TYPE_UNSUPPORTED)
    elif name.startswith("FPB_") and not ctx.signed:
        refused = mparams.Refused(f"{name} refused: limits change on a signed link only",
                                  mparams.MAV_PARAM_ERROR_PERMISSION_DENIED)
    else:
        refused = ctx.params.set(name, value, kind)
    if refused is not None:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, str(refused), limited=True)
        raw = param_id(msg.param_id).encode("ascii", "replace")[:16]
        ep.send(mav.MAVLink_param_error_message(src[0], src[1], raw, -1 if index is None
                                                else index, refused.code))
    elif name.startswith("FPB_"):
        ctx.sync_limits()
    if index is None:
        return
    m = param_value(ctx, index)  # the value in force, accepted or not
    for e in ctx.endpoints:
        e.send(m)


HANDLERS = {
    "PARAM_REQUEST_LIST": on_param_list,
    "PARAM_REQUEST_READ": on_param_read,
    "PARAM_SET": on_param_set,
}
"""The parameter messages."""
