"""PX4 identity: custom-mode encoding (px4_custom_mode.h) and the modes the bridge flies.

PX4 puts its main mode in bits 16..23 and its sub mode in bits 24..31 of
HEARTBEAT.custom_mode (``union px4_custom_mode {struct {uint16 reserved; uint8
main_mode; uint8 sub_mode;}; uint32 data;}``).
"""

from __future__ import annotations

MAIN_MANUAL = 1
MAIN_ALTCTL = 2
MAIN_POSCTL = 3
MAIN_AUTO = 4
MAIN_ACRO = 5
MAIN_OFFBOARD = 6
MAIN_STABILIZED = 7
MAIN_RATTITUDE = 8

SUB_AUTO_READY = 1
SUB_AUTO_TAKEOFF = 2
SUB_AUTO_LOITER = 3
SUB_AUTO_MISSION = 4
SUB_AUTO_RTL = 5
SUB_AUTO_LAND = 6
SUB_AUTO_RTGS = 7
SUB_AUTO_FOLLOW_TARGET = 8
SUB_AUTO_PRECLAND = 9

#: The modes the bridge flies, by name -> (main mode, sub mode).
MODES: dict[str, tuple[int, int]] = {
    "HOLD": (MAIN_AUTO, SUB_AUTO_LOITER),  # AUTO.LOITER: hold the current pose
    "POSCTL": (MAIN_POSCTL, 0),  # no sticks here: holds the pose like HOLD
    "OFFBOARD": (MAIN_OFFBOARD, 0),  # follow SET_POSITION_TARGET/SET_ATTITUDE_TARGET
    "TAKEOFF": (MAIN_AUTO, SUB_AUTO_TAKEOFF),  # climb to MIS_TAKEOFF_ALT (or as commanded)
    "LAND": (MAIN_AUTO, SUB_AUTO_LAND),  # descend where it is until landed
    "RTL": (MAIN_AUTO, SUB_AUTO_RTL),  # climb to RTL_RETURN_ALT, home (or a rally point), land
    "MISSION": (MAIN_AUTO, SUB_AUTO_MISSION),  # fly the uploaded mission
}


def custom_mode(mode: str) -> int:
    """HEARTBEAT's custom_mode of a PX4 mode (main mode in bits 16-23, sub mode in 24-31)."""
    main, sub = MODES[mode]
    return (main << 16) | (sub << 24)

