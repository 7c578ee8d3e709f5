"""Flight modes as PX4 encodes them, and which of them the simulated vehicle flies.

A mode request arrives as SET_MODE (message 11: base_mode, custom_mode) or as
MAV_CMD_DO_SET_MODE (176: param1 base_mode, param2 main mode, param3 sub mode).  PX4's
MavlinkReceiver turns the message into the command (main = bits 16..23 of custom_mode,
sub = bits 24..31), so both roads end in :func:`resolve`, and the bridge answers both
the same way: COMMAND_ACK for command 176 to the sender and, on a change, an immediate
HEARTBEAT; a refusal carries a STATUSTEXT naming the reason (docs/mavlink.md, "Modes").
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from mavlink_bridge import px4

CUSTOM_MODE_ENABLED = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
SUB_POSCTL_ORBIT = 1  # PX4_CUSTOM_SUB_MODE_POSCTL_ORBIT (POSCTL_POSCTL = 0)

_STICKS = "needs sticks, not simulated"

#: PX4 (main, sub) -> (mode name as MAVROS spells it, bridge mode flown or None, reason)
_TABLE: dict[tuple[int, int], tuple[str, str | None, str]] = {
    (px4.MAIN_MANUAL, 0): ("MANUAL", None, _STICKS),
    (px4.MAIN_ALTCTL, 0): ("ALTCTL", None, _STICKS),
    (px4.MAIN_POSCTL, 0): ("POSCTL", "POSCTL", ""),
    (px4.MAIN_ACRO, 0): ("ACRO", None, _STICKS),
    (px4.MAIN_OFFBOARD, 0): ("OFFBOARD", "OFFBOARD", ""),
    (px4.MAIN_STABILIZED, 0): ("STABILIZED", None, _STICKS),
    (px4.MAIN_RATTITUDE, 0): ("RATTITUDE", None, _STICKS),
    (px4.MAIN_AUTO, px4.SUB_AUTO_READY): ("AUTO.READY", None, "not a mode PX4 flies"),
    (px4.MAIN_AUTO, px4.SUB_AUTO_TAKEOFF): ("AUTO.TAKEOFF", "TAKEOFF", ""),
    (px4.MAIN_AUTO, px4.SUB_AUTO_LOITER): ("AUTO.LOITER", "HOLD", ""),
    (px4.MAIN_AUTO, px4.SUB_AUTO_MISSION): ("AUTO.MISSION", "MISSION", ""),
    (px4.MAIN_AUTO, px4.SUB_AUTO_RTL): ("AUTO.RTL", "RTL", ""),
    (px4.MAIN_AUTO, px4.SUB_AUTO_LAND): ("AUTO.LAND", "LAND", ""),
    (px4.MAIN_AUTO, px4.SUB_AUTO_RTGS): ("AUTO.RTGS", None, "not simulated"),
    (px4.MAIN_AUTO, px4.SUB_AUTO_FOLLOW_TARGET): ("AUTO.FOLLOW_TARGET", None,
                                                  "not simulated"),
    (px4.MAIN_AUTO, px4.SUB_AUTO_PRECLAND): ("AUTO.PRECLAND", None,
                                             "no landing target: use AUTO.LAND"),
}


#: commands not flown here and why (UNSUPPORTED, the reason told by STATUSTEXT)
COMMAND_REASONS: dict[int, str] = {
    34: "orbit not supported: fly the circle as mission legs",  # MAV_CMD_DO_ORBIT
    84: "VTOL takeoff: not a VTOL",  # MAV_CMD_NAV_VTOL_TAKEOFF
    85: "VTOL land: not a VTOL",  # MAV_CMD_NAV_VTOL_LAND
}


@dataclass(frozen=True)
class Resolved:
    """What a mode request means here: a bridge mode to fly, or why not (the reason
    fits a STATUSTEXT after "NAME refused: ")."""

    name: str  # PX4's name (MAVROS spelling), or main/sub numbers when unknown
    mode: str | None  # the bridge mode, None: refused
    reason: str = ""


def from_custom_mode(custom_mode: int) -> tuple[int, int]:
    """PX4's (main, sub) from a 32-bit custom_mode (px4_custom_mode.h)."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


def resolve(base_mode: int, main: int, sub: int) -> Resolved:
    """The bridge mode a request with PX4's encoding asks for."""
    if not base_mode & CUSTOM_MODE_ENABLED:
        return Resolved(f"base_mode {base_mode}", None,
                        "no CUSTOM_MODE flag")
    if main == px4.MAIN_POSCTL and sub == SUB_POSCTL_ORBIT:
        return Resolved("POSCTL.ORBIT", None, "not simulated")
    if main != px4.MAIN_AUTO:
        sub = 0  # only AUTO (and POSCTL's orbit) use the sub mode
    entry = _TABLE.get((main, sub))
    if entry is None:
        return Resolved(f"mode {main}/{sub}", None, "unknown PX4 mode")
    name, mode, reason = entry
    return Resolved(name, mode, reason)


def names() -> dict[str, tuple[int, int]]:
    """PX4 mode name -> (main, sub), every mode PX4 defines (for tests and docs)."""
    return {name: key for key, (name, _, _) in _TABLE.items()}


# AVAILABLE_MODES (435) / CURRENT_MODE (436): MAVLink's standard-modes messages, in the
# development dialect of the installed pymavlink (not yet in its common.xml).  Every PX4
# mode is listed, the ones not flown here as NOT_USER_SELECTABLE: QGroundControl then
# leaves them out of its mode menu but can still send them (its RTL and Land buttons),
# and the refusal tells the user why.
_dev: Any = importlib.import_module("pymavlink.dialects.v20.development")
MSG_AVAILABLE_MODES = 435
MSG_CURRENT_MODE = 436
REQUESTABLE = (MSG_AVAILABLE_MODES, MSG_CURRENT_MODE)
NOT_USER_SELECTABLE = 2  # MAV_MODE_PROPERTY_NOT_USER_SELECTABLE
#: PX4 (main, sub) -> the MAV_STANDARD_MODE of the same meaning (0: NON_STANDARD)
_STANDARD = {(px4.MAIN_POSCTL, 0): 1, (px4.MAIN_ALTCTL, 0): 4,
             (px4.MAIN_AUTO, px4.SUB_AUTO_RTL): 5, (px4.MAIN_AUTO, px4.SUB_AUTO_MISSION): 6,
             (px4.MAIN_AUTO, px4.SUB_AUTO_LAND): 7, (px4.MAIN_AUTO, px4.SUB_AUTO_TAKEOFF): 8}
_MODE_LIST = tuple(_TABLE.items())
AVAILABLE_COUNT = len(_MODE_LIST)


def _custom(main: int, sub: int) -> int:
    return (main << 16) | (sub << 24)


def requested(msg_id: int, index: int, custom_mode: int) -> list[Any]:
    """The answer to REQUEST_MESSAGE for AVAILABLE_MODES (param2: mode index, 0 = all)
    or CURRENT_MODE; ``custom_mode``: the mode flown now."""
    if msg_id == MSG_CURRENT_MODE:
        standard = _STANDARD.get(from_custom_mode(custom_mode), 0)
        return [_dev.MAVLink_current_mode_message(standard, custom_mode, custom_mode)]
    out = []
    for i, (key, (name, mode, _)) in enumerate(_MODE_LIST, start=1):
        if index in (0, i):
            out.append(_dev.MAVLink_available_modes_message(
                AVAILABLE_COUNT, i, _STANDARD.get(key, 0), _custom(*key),
                0 if mode is not None else NOT_USER_SELECTABLE, name.encode("ascii")))
    return out
