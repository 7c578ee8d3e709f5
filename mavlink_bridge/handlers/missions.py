"""The mission, fence and rally protocol: an empty plan to download, uploads refused with a
reason (:mod:`mavlink_bridge.protocols`)."""

from __future__ import annotations

from typing import Any

from mavlink_bridge import protocols
from mavlink_bridge.context import Context, Source
from mavlink_bridge.links import Endpoint
from mavlink_bridge.telemetry import mav


def on_request_list(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """The (empty) plan's count."""
    ctx.reply(ep, protocols.mission_request_list(msg, src))


def on_request(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """A plan item: there is none."""
    ctx.reply(ep, protocols.mission_request_item(msg, src))


def on_count(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """An upload: accepted if empty, else refused with the reason told."""
    replies, why = protocols.mission_count(msg, src)
    if why is not None:
        ctx.statustext(mav.MAV_SEVERITY_WARNING, why, limited=True)
    ctx.reply(ep, replies)


def on_clear(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """Clearing the (empty) plan."""
    ctx.reply(ep, protocols.mission_clear_all(msg, src))


def on_ack(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """The end of a download of an empty plan: nothing to do."""


HANDLERS = {
    "MISSION_REQUEST_LIST": on_request_list,
    "MISSION_REQUEST_INT": on_request,
    "MISSION_REQUEST": on_request,
    "MISSION_COUNT": on_count,
    "MISSION_CLEAR_ALL": on_clear,
    "MISSION_ACK": on_ack,
}
"""The mission protocol's messages."""
