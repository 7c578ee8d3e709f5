"""What the ground stations ask of the vehicle's voice: message intervals and one-off
messages (the MAV_CMDs of the message protocol), TIMESYNC, PING and the file-transfer
protocol's component metadata.  The streams themselves are built in
:mod:`mavlink_bridge.telemetry` and sent by the router."""

from __future__ import annotations

import math
from typing import Any

from mavlink_bridge import modes, protocols, px4, telemetry
from mavlink_bridge.context import Context, Source
from mavlink_bridge.links import Endpoint
from mavlink_bridge.telemetry import mav

#: the message commands and the params (1-based) each uses (NaN/inf there is DENIED)
COMMAND_PARAMS: dict[int, tuple[int, ...]] = {
    mav.MAV_CMD_REQUEST_MESSAGE: (1,),
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: (1,),
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: (1, 2),
    mav.MAV_CMD_GET_MESSAGE_INTERVAL: (1,),
    mav.MAV_CMD_GET_HOME_POSITION: (),
}
# Commands answered, after their ACK, by one message: REQUEST_MESSAGE names it in param1;
# these two are the older, dedicated requests (MAVSDK and QGroundControl still send them).
_REQUESTS = {mav.MAV_CMD_REQUEST_MESSAGE: 0,
             mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
             mav.MAV_CMD_GET_HOME_POSITION: mav.MAVLINK_MSG_ID_HOME_POSITION}


def command(ctx: Context, ep: Endpoint, cmd: int, p: list[float]) -> int:
    """The MAV_RESULT of a message command (one of COMMAND_PARAMS); SET_MESSAGE_INTERVAL
    takes effect on this endpoint."""
    if cmd == mav.MAV_CMD_REQUEST_MESSAGE:
        known = (int(p[0]) in telemetry.DEFAULT_RATES or int(p[0]) in telemetry.ON_REQUEST
                 or int(p[0]) in modes.REQUESTABLE)
        if int(p[0]) == modes.MSG_AVAILABLE_MODES and math.isfinite(p[1]):
            known = 0 <= p[1] <= modes.AVAILABLE_COUNT  # param2: mode index, 0 = all
        return mav.MAV_RESULT_ACCEPTED if known else mav.MAV_RESULT_DENIED
    if cmd in (mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, mav.MAV_CMD_GET_HOME_POSITION):
        return mav.MAV_RESULT_ACCEPTED
    if cmd in (mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAV_CMD_GET_MESSAGE_INTERVAL):
        msg_id = int(p[0])
        if msg_id not in telemetry.DEFAULT_RATES:
            return mav.MAV_RESULT_DENIED
        if cmd == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            us = p[1]
            if not math.isfinite(us):
                return mav.MAV_RESULT_DENIED
            interval = (1.0 / telemetry.DEFAULT_RATES[msg_id] if us == 0 else
                        -1.0 if us < 0 else max(us * 1e-6, 0.001))
            ep.intervals[msg_id] = interval
            ep.next_due[msg_id] = ctx.session.time
        return mav.MAV_RESULT_ACCEPTED
    return mav.MAV_RESULT_UNSUPPORTED


def answer(ctx: Context, ep: Endpoint, cmd: int, p: list[float]) -> None:
    """After an accepted message command's ACK: the message(s) it asked for."""
    if cmd == mav.MAV_CMD_REQUEST_MESSAGE and int(p[0]) in modes.REQUESTABLE:
        index = int(p[1]) if math.isfinite(p[1]) else 0
        ctx.reply(ep, modes.requested(int(p[0]), index, px4.custom_mode(ctx.mode)))
    elif cmd in _REQUESTS:
        msg_id = int(p[0]) if cmd == mav.MAV_CMD_REQUEST_MESSAGE else _REQUESTS[cmd]
        ctx.reply(ep, telemetry.build_all(msg_id, ctx.fresh_snapshot()))
    elif cmd == mav.MAV_CMD_GET_MESSAGE_INTERVAL:
        msg_id = int(p[0])
        interval = ep.intervals.get(msg_id, 0.0)
        us = int(interval * 1e6) if interval > 0 else -1
        ep.send(mav.MAVLink_message_interval_message(msg_id, us))


def on_timesync(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """A TIMESYNC request answered with the simulated time."""
    if int(msg.tc1) == 0:
        now_ns = int(ctx.session.time * 1e9)
        ep.send(mav.MAVLink_timesync_message(now_ns, int(msg.ts1)))


def on_ping(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """A PING answered."""
    ctx.reply(ep, protocols.ping_reply(msg, src))


def on_ftp(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """A file-transfer request (component metadata) answered."""
    ctx.reply(ep, protocols.ftp_reply(msg, src))


HANDLERS = {
    "TIMESYNC": on_timesync,
    "PING": on_ping,
    "FILE_TRANSFER_PROTOCOL": on_ftp,
}
"""The link-service messages."""
