"""The mission protocol for mission, fence and rally plans (https://mavlink.io/en/services/
mission.html), as PX4 serves it: uploads item by item with re-requests, downloads, clearing,
MISSION_SET_CURRENT.  The plans live on the :class:`~mavlink_bridge.context.Context`
(``plans``, ``install_plan``, ``set_current_item``); the transfers in progress in a
:class:`~mavlink_bridge.mission_protocol.MissionTransfers` kept on it.  Re-requests after a
silence need :func:`tick` called from the bridge loop (docs/mavlink.md, "Mission, fence and
rally")."""

from __future__ import annotations

import time
from typing import Any

from mavlink_bridge import mission_protocol as mp
from mavlink_bridge.context import Context, Source
from mavlink_bridge.links import Endpoint
from mavlink_bridge.mission_protocol import MissionTransfers, Partner, Upload
from mavlink_bridge.telemetry import mav
from orchestrator.mission import items
from orchestrator.mission.items import MissionItem

_STATE = "_mission_transfers"  # the Context attribute holding the MissionTransfers


def transfers(ctx: Context) -> MissionTransfers:
    """The bridge's mission transfers (made on first use)."""
    t = getattr(ctx, _STATE, None)
    if not isinstance(t, MissionTransfers):
        t = MissionTransfers()
        setattr(ctx, _STATE, t)
    return t


def _partner(ep: Endpoint, src: Source) -> Partner:
    return (ep.link_id, src[0], src[1])


def _refuse(ctx: Context, ep: Endpoint, src: Source, kind: int, result: int, text: str) -> None:
    """MISSION_ACK with an error to src, and the reason to every ground station."""
    ctx.statustext(mav.MAV_SEVERITY_WARNING, text, limited=True)
    ctx.reply(ep, [mp.ack(src, result, kind)])


# -- upload -----------------------------------------------------------------------------------


def on_count(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """MISSION_COUNT: an upload begins (or, with count 0, clears the plan).  One upload at a
    time: another ground station's is DENIED until it ends; the same station starting again
    gives up its earlier one (it timed out on its side)."""
    kind, n = mp.mission_type(msg), int(msg.count)
    if kind not in items.MISSION_TYPES:
        ctx.reply(ep, [mp.ack(src, mav.MAV_MISSION_UNSUPPORTED, kind)])
        return
    t = transfers(ctx)
    partner = _partner(ep, src)
    up = t.upload
    if up is not None and up.partner != partner:
        _refuse(ctx, ep, src, kind, mav.MAV_MISSION_DENIED,
                f"{mp.plan_name(kind)} upload refused: busy with an upload from "
                f"{up.partner[1]}/{up.partner[2]}")
        return
    t.upload = None
    if n > mp.MAX_ITEMS[kind]:
        _refuse(ctx, ep, src, kind, mav.MAV_MISSION_NO_SPACE,
                f"{mp.plan_name(kind)} upload refused: {n} items, at most "
                f"{mp.MAX_ITEMS[kind]}")
        return
    if n == 0:
        _install(ctx, t, ep, partner, kind, [])
        return
    t.upload = Upload(partner, kind, n, ep)
    _request_next(t.upload)


def on_item(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """MISSION_ITEM_INT or the legacy MISSION_ITEM: the next item of the upload, checked at
    once (a refusal ends the upload, the plan held stays); a later item than expected means
    one was lost, so it is requested again; an earlier one is a duplicate, dropped."""
    t = transfers(ctx)
    up, seq = t.upload, int(msg.seq)
    if up is None:
        _stray_item(ctx, ep, t, msg, src)
        return
    if up.partner != _partner(ep, src):
        _refuse(ctx, ep, src, mp.mission_type(msg), mav.MAV_MISSION_DENIED,
                f"mission item {seq} from {src[0]}/{src[1]} refused: busy with an upload "
                f"from {up.partner[1]}/{up.partner[2]}")
        return
    up.legacy = msg.get_type() == "MISSION_ITEM"
    why = _sequence_error(up, msg)
    if why is not None:
        _abort(ctx, t, why[0], why[1])
        return
    if seq != up.next_seq:
        if seq > up.next_seq:
            _request_next(up)
        return
    _take(ctx, t, up, msg)


def _sequence_error(up: Upload, msg: Any) -> tuple[int, str] | None:
    """Why an item from the partner does not belong to its upload at all (an error, which ends
    the upload), as (MAV_MISSION_RESULT, reason); None: it does."""
    kind, seq = mp.mission_type(msg), int(msg.seq)
    if kind != up.kind:
        return (mav.MAV_MISSION_ERROR,
                f"item {seq} is a {mp.plan_name(kind)} item, not a {mp.plan_name(up.kind)} one")
    if seq >= up.count:
        return mav.MAV_MISSION_INVALID_SEQUENCE, f"item {seq} beyond the {up.count} announced"
    return None


def _take(ctx: Context, t: MissionTransfers, up: Upload, msg: Any) -> None:
    """Check the item expected next and keep it; install the plan after the last one."""
    try:
        item = mp.item_from(msg)
    except mp.BadItem as e:
        _abort(ctx, t, e.result, f"item {up.next_seq}: {e}")
        return
    why = items.check(item)
    if why is not None:
        _abort(ctx, t, mp.item_result(item, why), f"item {item.seq}: {why}")
        return
    up.received.append(item)
    up.retries = 0
    if up.next_seq < up.count:
        _request_next(up)
        return
    t.upload = None
    _install(ctx, t, up.ep, up.partner, up.kind, up.received)


def _request_next(up: Upload) -> None:
    up.sent_at = time.monotonic()
    up.ep.send(mp.request(up))


def _install(ctx: Context, t: MissionTransfers, ep: Endpoint, partner: Partner, kind: int,
             plan: list[MissionItem]) -> None:
    """A plan received whole: installed (ACCEPTED) or refused with the reason; the plan held
    before stays then."""
    why = ctx.install_plan(kind, plan)
    src = (partner[1], partner[2])
    result = mav.MAV_MISSION_ACCEPTED if why is None else mp.plan_result(plan, why)
    t.finished = mp.Finished(partner, kind, len(plan), result)
    if why is None:
        ctx.reply(ep, [mp.ack(src, result, kind)])
    else:
        _refuse(ctx, ep, src, kind, result, f"{mp.plan_name(kind)} upload refused: {why}")


def _abort(ctx: Context, t: MissionTransfers, result: int, why: str) -> None:
    """End the upload with an error; the plan held stays."""
    up = t.upload
    if up is None:
        return
    t.upload = None
    t.finished = None
    _refuse(ctx, up.ep, up.source, up.kind, result,
            f"{mp.plan_name(up.kind)} upload refused: {why}")


def _stray_item(ctx: Context, ep: Endpoint, t: MissionTransfers, msg: Any, src: Source) -> None:
    """An item with no upload in progress: the last item of the upload just finished again
    (the ground station missed our MISSION_ACK) gets that ACK again; anything else an ERROR."""
    kind, seq = mp.mission_type(msg), int(msg.seq)
    done = t.finished
    if (done is not None and done.partner == _partner(ep, src) and done.kind == kind
            and seq == done.count - 1):
        ctx.reply(ep, [mp.ack(src, done.result, kind)])
        return
    _refuse(ctx, ep, src, kind, mav.MAV_MISSION_ERROR,
            f"mission item {seq} ignored: no upload in progress")


def tick(ctx: Context, now: float) -> None:
    """Request the item expected again after ITEM_TIMEOUT wall seconds of silence; after
    ITEM_RETRIES such re-requests give the upload up (MISSION_ACK OPERATION_CANCELLED and a
    STATUSTEXT).  ``now`` is ``time.monotonic()``; call it from the bridge loop (every chunk:
    it does nothing while no upload is in progress)."""
    t = getattr(ctx, _STATE, None)
    if not isinstance(t, MissionTransfers) or t.upload is None:
        return
    up = t.upload
    if now - up.sent_at < mp.ITEM_TIMEOUT:
        return
    if up.retries >= mp.ITEM_RETRIES:
        silence = mp.ITEM_TIMEOUT * (mp.ITEM_RETRIES + 1)
        _abort(ctx, t, mav.MAV_MISSION_OPERATION_CANCELLED,
               f"no item {up.next_seq} for {silence:g} s")
        return
    up.retries += 1
    _request_next(up)


# -- download ---------------------------------------------------------------------------------


def on_request_list(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """MISSION_REQUEST_LIST: a download begins with the plan's MISSION_COUNT; the items are
    served from the plan as it is now until the ground station's MISSION_ACK."""
    kind = mp.mission_type(msg)
    if kind not in items.MISSION_TYPES:
        ctx.reply(ep, [mp.ack(src, mav.MAV_MISSION_UNSUPPORTED, kind)])
        return
    plan = ctx.plans[kind]
    transfers(ctx).remember_download((_partner(ep, src), kind), plan)
    ctx.reply(ep, [mp.count(src, len(plan), kind)])


def on_request(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """MISSION_REQUEST_INT (answered by MISSION_ITEM_INT) or the legacy MISSION_REQUEST
    (answered by the float MISSION_ITEM, as PX4 does); ``current`` marks the mission item
    flown or to fly next."""
    kind, seq = mp.mission_type(msg), int(msg.seq)
    if kind not in items.MISSION_TYPES:
        ctx.reply(ep, [mp.ack(src, mav.MAV_MISSION_UNSUPPORTED, kind)])
        return
    held = ctx.plans[kind]
    plan = transfers(ctx).downloads.get((_partner(ep, src), kind), held)
    if not 0 <= seq < len(plan):
        ctx.reply(ep, [mp.ack(src, mav.MAV_MISSION_INVALID_SEQUENCE, kind)])
        return
    current = int(kind == items.MISSION and plan is held and seq == ctx.mission_current)
    legacy = msg.get_type() == "MISSION_REQUEST"
    ctx.reply(ep, [mp.item_message(plan[seq], src, current, legacy)])


def on_ack(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """MISSION_ACK from a ground station: the end of its download; during its upload, an error
    ends the upload (OPERATION_CANCELLED: the station cancels), except UNSUPPORTED, which asks
    for the other item message (MISSION_REQUEST_INT <-> MISSION_REQUEST, as PX4 switches)."""
    kind, result = mp.mission_type(msg), int(msg.type)
    partner = _partner(ep, src)
    t = transfers(ctx)
    t.downloads.pop((partner, kind), None)
    up = t.upload
    if up is None or up.partner != partner or up.kind != kind:
        return
    if result == mav.MAV_MISSION_UNSUPPORTED and up.retries < mp.ITEM_RETRIES:
        up.legacy = not up.legacy
        up.retries += 1
        _request_next(up)
    elif result != mav.MAV_MISSION_ACCEPTED:
        t.upload = None
        ctx.statustext(mav.MAV_SEVERITY_INFO,
                       f"{mp.plan_name(kind)} upload ended by {src[0]}/{src[1]} (result "
                       f"{result})", limited=True)


# -- clear, current item ----------------------------------------------------------------------


def on_clear(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """MISSION_CLEAR_ALL: the plan of that type emptied (MAV_MISSION_TYPE_ALL: all three)."""
    kind = mp.mission_type(msg)
    if kind == mav.MAV_MISSION_TYPE_ALL:
        kinds: tuple[int, ...] = items.MISSION_TYPES
    elif kind in items.MISSION_TYPES:
        kinds = (kind,)
    else:
        ctx.reply(ep, [mp.ack(src, mav.MAV_MISSION_UNSUPPORTED, kind)])
        return
    for k in kinds:
        why = ctx.install_plan(k, [])
        if why is not None:
            _refuse(ctx, ep, src, kind, mav.MAV_MISSION_ERROR,
                    f"{mp.plan_name(k)} clear refused: {why}")
            return
    ctx.reply(ep, [mp.ack(src, mav.MAV_MISSION_ACCEPTED, kind)])


def on_set_current(ctx: Context, ep: Endpoint, msg: Any, src: Source) -> None:
    """MISSION_SET_CURRENT: the mission goes on from item seq, told to every ground station by
    MISSION_CURRENT (the spec's broadcast); a seq outside the mission is refused with a
    STATUSTEXT and a MISSION_ACK INVALID_SEQUENCE to the sender."""
    seq = int(msg.seq)
    why = ctx.set_current_item(seq)
    if why is not None:
        _refuse(ctx, ep, src, items.MISSION, mav.MAV_MISSION_INVALID_SEQUENCE,
                f"mission item {seq} not set current: {why}")
        return
    m = mp.mission_current(ctx.mission_current, len(ctx.plans[items.MISSION]))
    for e in ctx.endpoints:
        e.send(m)


HANDLERS = {
    "MISSION_COUNT": on_count,
    "MISSION_ITEM_INT": on_item,
    "MISSION_ITEM": on_item,
    "MISSION_REQUEST_LIST": on_request_list,
    "MISSION_REQUEST_INT": on_request,
    "MISSION_REQUEST": on_request,
    "MISSION_ACK": on_ack,
    "MISSION_CLEAR_ALL": on_clear,
    "MISSION_SET_CURRENT": on_set_current,
}
"""The mission protocol's messages."""
