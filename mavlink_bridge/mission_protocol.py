"""The mission protocol's pieces (https://mavlink.io/en/services/mission.html, MAVLink 2 only):
mission items to and from MISSION_ITEM_INT and the legacy float MISSION_ITEM, the MISSION_ACK
result a refusal earns, and the state of the transfers in progress.  The handlers
(:mod:`mavlink_bridge.handlers.missions`) drive the transfers; the items themselves and their
checks are :mod:`orchestrator.mission.items`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mav

from mavlink_bridge.links import Endpoint
from orchestrator.mission import items
from orchestrator.mission.items import MissionItem

# Upload timing, in wall seconds (the ground station's clock, not the simulated one).  The spec
# recommends 250 ms per item and 5 retries; a busy host (two cores, the bridge and a ground
# station sharing them) answers later than that now and then, so we wait twice as long and give
# up only after 5.5 s of silence, about PX4's MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT (5 s).
ITEM_TIMEOUT = 0.5  # wall s without the item requested before it is requested again
ITEM_RETRIES = 10  # re-requests of one item before the upload is given up
#: the largest plan of each type an upload may announce (MISSION_COUNT); beyond: NO_SPACE
MAX_ITEMS = {items.MISSION: 500, items.FENCE: 64, items.RALLY: 32}
PLAN_NAMES = {items.MISSION: "mission", items.FENCE: "fence", items.RALLY: "rally"}
DOWNLOADS_KEPT = 16  # download snapshots kept (one per ground station and plan type)
INT32 = 2 ** 31

Source = tuple[int, int]
"""(system id, component id) of a message's sender."""
Partner = tuple[int, int, int]
"""Who a transfer is with: (endpoint link id, system id, component id)."""

# Why an item is refused (orchestrator.mission.items.check) -> the field it names, as the
# MAV_MISSION_RESULT a ground station shows next to that field.  A reason not listed here
# earns MAV_MISSION_INVALID: still refused, and the STATUSTEXT carries the reason.
_REASON_RESULTS: tuple[tuple[str, int], ...] = (
    ("param1", mav.MAV_MISSION_INVALID_PARAM1),
    ("param2", mav.MAV_MISSION_INVALID_PARAM2),
    ("param3", mav.MAV_MISSION_INVALID_PARAM3),
    ("param4", mav.MAV_MISSION_INVALID_PARAM4),
    ("x ", mav.MAV_MISSION_INVALID_PARAM5_X),
    ("y ", mav.MAV_MISSION_INVALID_PARAM6_Y),
    ("z ", mav.MAV_MISSION_INVALID_PARAM7),
    ("hold time", mav.MAV_MISSION_INVALID_PARAM1),
    ("acceptance radius", mav.MAV_MISSION_INVALID_PARAM2),
    ("speed type", mav.MAV_MISSION_INVALID_PARAM1),
    ("speed must", mav.MAV_MISSION_INVALID_PARAM2),
    ("a polygon needs", mav.MAV_MISSION_INVALID_PARAM1),
    ("polygon of", mav.MAV_MISSION_INVALID_PARAM1),
    ("circle radius", mav.MAV_MISSION_INVALID_PARAM1),
)
_ITEM_REASON = re.compile(r"item (\d+): (.*)", re.DOTALL)


class BadItem(ValueError):
    """A received item that cannot even be held as a :class:`MissionItem`; ``result`` is the
    MAV_MISSION_RESULT it earns."""

    def __init__(self, reason: str, result: int) -> None:
        super().__init__(reason)
        self.result = result


@dataclass
class Upload:
    """An upload in progress: the items received so far from its partner, in order."""

    partner: Partner
    kind: int  # MAV_MISSION_TYPE
    count: int  # items announced by MISSION_COUNT
    ep: Endpoint  # where the partner is reached
    received: list[MissionItem] = field(default_factory=list)
    # the partner answered with the float MISSION_ITEM: ask with MISSION_REQUEST (as PX4 does)
    legacy: bool = False
    sent_at: float = 0.0  # wall time (time.monotonic) of the latest request
    retries: int = 0  # re-requests of the item expected next

    @property
    def source(self) -> Source:
        """The partner's (system, component)."""
        return (self.partner[1], self.partner[2])

    @property
    def next_seq(self) -> int:
        """The sequence number expected next."""
        return len(self.received)


@dataclass(frozen=True)
class Finished:
    """The last upload that ran to its end: its last item coming again means the ground
    station missed our MISSION_ACK, which is then sent again (as PX4 does)."""

    partner: Partner
    kind: int
    count: int
    result: int  # the MAV_MISSION_RESULT sent


@dataclass
class MissionTransfers:
    """The mission protocol's state on a bridge: at most one upload at a time (for all plan
    types, as PX4), the last upload finished, and what each ground station is downloading."""

    upload: Upload | None = None
    finished: Finished | None = None
    # (partner, plan type) -> the plan as it was at MISSION_REQUEST_LIST: a download stays one
    # plan even if an upload replaces it meanwhile (Context.install_plan makes a new list)
    downloads: dict[tuple[Partner, int], list[MissionItem]] = field(default_factory=dict)

    def remember_download(self, key: tuple[Partner, int], plan: list[MissionItem]) -> None:
        """Serve the download ``key`` from ``plan``; the oldest beyond DOWNLOADS_KEPT are
        forgotten (a ground station that never sends its final MISSION_ACK)."""
        self.downloads.pop(key, None)
        self.downloads[key] = plan
        while len(self.downloads) > DOWNLOADS_KEPT:
            del self.downloads[next(iter(self.downloads))]


def mission_type(msg: Any) -> int:
    """The message's MAV_MISSION_TYPE (a MAVLink 2 extension: 0, the mission, if absent)."""
    return int(getattr(msg, "mission_type", items.MISSION))


def plan_name(kind: int) -> str:
    """What a plan type is called in texts."""
    return PLAN_NAMES.get(kind, f"mission type {kind}")


# -- messages -------------------------------------------------------------------------------


def ack(src: Source, result: int, kind: int) -> Any:
    """MISSION_ACK of a MAV_MISSION_RESULT to src."""
    return mav.MAVLink_mission_ack_message(src[0], src[1], result, kind)


def count(src: Source, n: int, kind: int) -> Any:
    """MISSION_COUNT: the number of items of a plan, to src."""
    return mav.MAVLink_mission_count_message(src[0], src[1], n, kind)


def request(up: Upload) -> Any:
    """The request for the item an upload expects next: MISSION_REQUEST_INT, or the legacy
    MISSION_REQUEST to a partner that answers with MISSION_ITEM."""
    build = mav.MAVLink_mission_request_message if up.legacy else \
        mav.MAVLink_mission_request_int_message
    return build(up.partner[1], up.partner[2], up.next_seq, up.kind)


def item_message(item: MissionItem, src: Source, current: int, legacy: bool) -> Any:
    """An item to src: MISSION_ITEM_INT with its fields as they were uploaded, or (legacy) the
    float MISSION_ITEM with x, y in degrees or metres (:func:`items.float_xy`)."""
    head = (src[0], src[1], item.seq, item.frame, item.command, current, item.autocontinue,
            *item.params)
    if legacy:
        x, y = items.float_xy(item)
        return mav.MAVLink_mission_item_message(*head, x, y, item.z, item.mission_type)
    return mav.MAVLink_mission_item_int_message(*head, item.x, item.y, item.z,
                                                item.mission_type)


def mission_current(seq: int, total: int) -> Any:
    """MISSION_CURRENT: the mission item flown or to fly next, of ``total``."""
    return mav.MAVLink_mission_current_message(seq, total)


# -- items ------------------------------------------------------------------------------------


def item_from(msg: Any) -> MissionItem:
    """A received MISSION_ITEM_INT or MISSION_ITEM as a :class:`MissionItem`; the float
    message's x, y become the integers MISSION_ITEM_INT carries (:func:`items.int_xy`).  Raises
    :class:`BadItem` when the float x, y have no integer form."""
    frame = int(msg.frame)
    if msg.get_type() == "MISSION_ITEM":
        x, y = _int_xy(frame, float(msg.x), float(msg.y))
    else:
        x, y = int(msg.x), int(msg.y)
    return MissionItem(int(msg.seq), frame, int(msg.command), float(msg.param1),
                       float(msg.param2), float(msg.param3), float(msg.param4), x, y,
                       float(msg.z), int(msg.current), int(msg.autocontinue), mission_type(msg))


def _int_xy(frame: int, x: float, y: float) -> tuple[int, int]:
    """The float message's x, y as integers; NaN, inf or beyond int32 cannot be held (a NaN
    in a field the command does not use would be lost anyway: MISSION_ITEM_INT has none)."""
    for name, value, result in (("x", x, mav.MAV_MISSION_INVALID_PARAM5_X),
                                ("y", y, mav.MAV_MISSION_INVALID_PARAM6_Y)):
        if not math.isfinite(value):
            raise BadItem(f"{name} not finite", result)
    ix, iy = items.int_xy(frame, x, y)
    for name, value, result in (("x", ix, mav.MAV_MISSION_INVALID_PARAM5_X),
                                ("y", iy, mav.MAV_MISSION_INVALID_PARAM6_Y)):
        if not -INT32 <= value < INT32:
            raise BadItem(f"{name} out of range", result)
    return ix, iy


def item_result(item: MissionItem, why: str) -> int:
    """The MAV_MISSION_RESULT of an item refused for ``why`` (:func:`items.check`): an
    unsupported command UNSUPPORTED, a frame the command cannot use UNSUPPORTED_FRAME, a bad
    value INVALID_PARAMn of its field, anything else INVALID."""
    if item.command not in items.SUPPORTED.get(item.mission_type, {}):
        return int(mav.MAV_MISSION_UNSUPPORTED)
    if item.command in items.POSITIONED and item.frame not in items.POSITION_FRAMES:
        return int(mav.MAV_MISSION_UNSUPPORTED_FRAME)
    if why.startswith("latitude/longitude"):
        lat_bad = abs(item.x) > 900_000_000  # the bound items.check applies to latitude
        return int(mav.MAV_MISSION_INVALID_PARAM5_X if lat_bad else
                   mav.MAV_MISSION_INVALID_PARAM6_Y)
    if why.startswith("roll/pitch"):  # FULLPOSE_ATTITUDE: param1 roll, param2 pitch
        roll_bad = abs(item.param1) > items.TILT_MAX_DEG
        return int(mav.MAV_MISSION_INVALID_PARAM1 if roll_bad else
                   mav.MAV_MISSION_INVALID_PARAM2)
    for prefix, result in _REASON_RESULTS:
        if why.startswith(prefix):
            return int(result)
    return int(mav.MAV_MISSION_INVALID)


def plan_result(plan: list[MissionItem], why: str) -> int:
    """The MAV_MISSION_RESULT of a whole plan refused for ``why``: an "item N: reason"
    (:func:`items.check_plan`) as that item's refusal, anything else (the plan as a whole)
    MAV_MISSION_ERROR."""
    m = _ITEM_REASON.match(why)
    if m is not None and int(m.group(1)) < len(plan):
        return item_result(plan[int(m.group(1))], m.group(2))
    return int(mav.MAV_MISSION_ERROR)
