"""Mission items as MAVLink carries them, and which of them are flown here.

An item keeps MISSION_ITEM_INT's fields exactly as they came (``x``, ``y`` integers: degrees
times 1e7 in a global frame, metres times 1e4 in a local one), so a plan downloaded is the plan
uploaded, bit for bit.  Where an item goes is worked out when it is flown (:func:`target`),
with the origin of the local frame known then.

The full pose of a leg: MAVLink has no field for roll and pitch at a waypoint, so a command of
its user range, :data:`FULLPOSE_ATTITUDE` (MAV_CMD_USER_1, 31010: param1 roll, param2 pitch in
degrees), sets the tilt of every leg after it until the next one (0, 0: level).  A ground
station sends it as any other mission item (QGroundControl: a plan file's SimpleItem with
``"command": 31010``; MAVSDK's mission_raw; pymavlink: MISSION_ITEM_INT).  The heading stays
the waypoint's own yaw (param4).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

# MAV_MISSION_TYPE
MISSION, FENCE, RALLY = 0, 1, 2
MISSION_TYPES = (MISSION, FENCE, RALLY)

# MAV_FRAME
FRAME_GLOBAL = 0  # lat, lon, alt AMSL
FRAME_LOCAL_NED = 1
FRAME_MISSION = 2  # not a position (DO_ items)
FRAME_GLOBAL_RELATIVE_ALT = 3  # alt above home
FRAME_LOCAL_ENU = 4
FRAME_GLOBAL_INT = 5
FRAME_GLOBAL_RELATIVE_ALT_INT = 6
FRAME_GLOBAL_TERRAIN_ALT = 10
FRAME_GLOBAL_TERRAIN_ALT_INT = 11
GLOBAL_FRAMES = (FRAME_GLOBAL, FRAME_GLOBAL_INT)
RELATIVE_FRAMES = (FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT)
POSITION_FRAMES = (*GLOBAL_FRAMES, *RELATIVE_FRAMES, FRAME_LOCAL_NED)

# MAV_CMD
NAV_WAYPOINT = 16
NAV_LOITER_TIME = 19
NAV_RETURN_TO_LAUNCH = 20
NAV_LAND = 21
NAV_TAKEOFF = 22
DO_CHANGE_SPEED = 178
FULLPOSE_ATTITUDE = 31010  # MAV_CMD_USER_1: roll, pitch (deg) of the legs that follow
FENCE_POLYGON_VERTEX_INCLUSION = 5001
FENCE_POLYGON_VERTEX_EXCLUSION = 5002
FENCE_CIRCLE_INCLUSION = 5003
FENCE_CIRCLE_EXCLUSION = 5004
RALLY_POINT = 5100

#: command -> name, per mission type: what is flown (or, for fence and rally, used)
SUPPORTED: dict[int, dict[int, str]] = {
    MISSION: {NAV_WAYPOINT: "NAV_WAYPOINT", NAV_LOITER_TIME: "NAV_LOITER_TIME",
              NAV_RETURN_TO_LAUNCH: "NAV_RETURN_TO_LAUNCH", NAV_LAND: "NAV_LAND",
              NAV_TAKEOFF: "NAV_TAKEOFF", DO_CHANGE_SPEED: "DO_CHANGE_SPEED",
              FULLPOSE_ATTITUDE: "FULLPOSE_ATTITUDE"},
    FENCE: {FENCE_POLYGON_VERTEX_INCLUSION: "NAV_FENCE_POLYGON_VERTEX_INCLUSION",
            FENCE_CIRCLE_INCLUSION: "NAV_FENCE_CIRCLE_INCLUSION"},
    RALLY: {RALLY_POINT: "NAV_RALLY_POINT"},
}
#: commands whose x, y, z are a position
POSITIONED = frozenset({NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LAND, NAV_TAKEOFF,
                        FENCE_POLYGON_VERTEX_INCLUSION, FENCE_CIRCLE_INCLUSION, RALLY_POINT})
#: why some well-known commands are refused (the rest: "not supported")
REFUSED_BECAUSE: dict[int, str] = {
    FENCE_POLYGON_VERTEX_EXCLUSION: "exclusion zones not supported (inclusion only)",
    FENCE_CIRCLE_EXCLUSION: "exclusion zones not supported (inclusion only)",
    17: "unlimited loiter not supported: use NAV_LOITER_TIME",  # NAV_LOITER_UNLIM
    18: "loiter turns not supported: use NAV_LOITER_TIME",  # NAV_LOITER_TURNS
    34: "orbits not supported",  # DO_ORBIT
    82: "splines not supported: NAV_WAYPOINT flies straight legs",  # NAV_SPLINE_WAYPOINT
    84: "VTOL takeoff: not a VTOL",
    85: "VTOL land: not a VTOL",
    177: "DO_JUMP not supported",
    179: "DO_SET_HOME in a mission not supported (send it as a command)",
    201: "gimbal commands: no gimbal",  # DO_SET_ROI
    203: "no camera",  # DO_DIGICAM_CONTROL
    205: "no gimbal",  # DO_MOUNT_CONTROL
    206: "no camera",  # DO_SET_CAM_TRIGG_DIST
    2000: "no camera", 2001: "no camera", 2500: "no camera", 2501: "no camera",
    1000: "no gimbal", 1001: "no gimbal",
}
TILT_MAX_DEG = 80.0  # largest |roll|, |pitch| a FULLPOSE_ATTITUDE item may ask for


@dataclass(frozen=True)
class MissionItem:
    """One item as MISSION_ITEM_INT carries it (``x``, ``y`` as its integers)."""

    seq: int
    frame: int
    command: int
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    current: int = 0
    autocontinue: int = 1
    mission_type: int = MISSION

    @property
    def name(self) -> str:
        """The command's MAVLink name (or its number)."""
        return SUPPORTED.get(self.mission_type, {}).get(self.command, f"command {self.command}")

    @property
    def params(self) -> tuple[float, float, float, float]:
        """param1..param4."""
        return (self.param1, self.param2, self.param3, self.param4)

    def with_seq(self, seq: int) -> MissionItem:
        """The same item at another place in its plan."""
        return MissionItem(seq, self.frame, self.command, *self.params, self.x, self.y,
                           self.z, self.current, self.autocontinue, self.mission_type)

    @classmethod
    def local(cls, seq: int, command: int, pos: Sequence[float] | np.ndarray | None = None,
              params: Sequence[float] = (0.0, 0.0, 0.0, 0.0),
              mission_type: int = MISSION) -> MissionItem:
        """An item at a local NED position (m; None: a command without a position)."""
        p = [float(v) for v in params] + [0.0] * (4 - len(params))
        if pos is None:
            return cls(seq, FRAME_MISSION, command, p[0], p[1], p[2], p[3],
                       mission_type=mission_type)
        return cls(seq, FRAME_LOCAL_NED, command, p[0], p[1], p[2], p[3],
                   round(float(pos[0]) * 1e4), round(float(pos[1]) * 1e4), float(pos[2]),
                   mission_type=mission_type)


def float_xy(item: MissionItem) -> tuple[float, float]:
    """x, y as MISSION_ITEM (the float message) carries them: degrees or metres."""
    scale = 1e-4 if item.frame == FRAME_LOCAL_NED else 1e-7
    if item.frame in POSITION_FRAMES:
        return item.x * scale, item.y * scale
    return float(item.x), float(item.y)


def int_xy(frame: int, x: float, y: float) -> tuple[int, int]:
    """MISSION_ITEM's float x, y as MISSION_ITEM_INT's integers (the inverse of
    :func:`float_xy`; non-position frames keep their value, truncated)."""
    if frame == FRAME_LOCAL_NED:
        return round(x * 1e4), round(y * 1e4)
    if frame in POSITION_FRAMES:
        return round(x * 1e7), round(y * 1e7)
    return int(x), int(y)


def check(item: MissionItem) -> str | None:
    """Why the item cannot be flown (None: it can).  The reason fits a STATUSTEXT after
    "item N: "."""
    kind = item.mission_type
    if kind not in MISSION_TYPES:
        return f"mission type {kind} unknown"
    if item.command not in SUPPORTED[kind]:
        return REFUSED_BECAUSE.get(item.command, f"command {item.command} not supported"
                                   + ("" if kind == MISSION else
                                      f" in a {('', 'fence', 'rally')[kind]} plan"))
    values = {"param1": item.param1, "param2": item.param2, "param3": item.param3,
              "param4": item.param4, "z": item.z}
    if item.command in POSITIONED:
        if item.frame not in POSITION_FRAMES:
            if item.frame in (FRAME_GLOBAL_TERRAIN_ALT, FRAME_GLOBAL_TERRAIN_ALT_INT):
                return "terrain altitude unsupported: no terrain model"
            return f"frame {item.frame} unsupported"
        if not math.isfinite(item.z):
            return "z not finite"
        if item.frame != FRAME_LOCAL_NED and (abs(item.x) > 900_000_000
                                              or abs(item.y) > 1_800_000_000):
            return "latitude/longitude out of range"
    c = item.command
    used = {NAV_WAYPOINT: ("param1", "param2"), NAV_LOITER_TIME: ("param1",),
            NAV_TAKEOFF: (), NAV_LAND: (), DO_CHANGE_SPEED: ("param1", "param2"),
            FULLPOSE_ATTITUDE: ("param1", "param2"),
            FENCE_POLYGON_VERTEX_INCLUSION: ("param1",), FENCE_CIRCLE_INCLUSION: ("param1",)
            }.get(c, ())
    for name in used:
        if not math.isfinite(values[name]):
            return f"{name} not finite"
    if c in (NAV_WAYPOINT, NAV_LOITER_TIME) and item.param1 < 0:
        return "hold time negative"
    if c == NAV_WAYPOINT and item.param2 < 0:
        return "acceptance radius negative"
    if c == DO_CHANGE_SPEED and item.param1 not in (0.0, 1.0, 2.0, 3.0):
        return f"speed type {item.param1:g} unknown (0..3)"
    if c == DO_CHANGE_SPEED and not (item.param2 == -1.0 or item.param2 > 0):
        return "speed must be positive (-1: no change)"
    if c == FULLPOSE_ATTITUDE and max(abs(item.param1), abs(item.param2)) > TILT_MAX_DEG:
        return f"roll/pitch beyond {TILT_MAX_DEG:g} deg"
    if c == FENCE_POLYGON_VERTEX_INCLUSION and (item.param1 < 3 or item.param1 != int(
            item.param1)):
        return "a polygon needs a vertex count of 3 or more (param1)"
    if c == FENCE_CIRCLE_INCLUSION and not item.param1 > 0:
        return "circle radius must be positive (param1)"
    return None


def check_plan(items: Sequence[MissionItem]) -> str | None:
    """Why a whole plan cannot be used (None: it can): each item, and the fence's polygons
    complete (every vertex of a polygon says the same count, as many as follow)."""
    for i, item in enumerate(items):
        why = check(item)
        if why is not None:
            return f"item {i}: {why}"
    i = 0
    while i < len(items):
        item = items[i]
        if item.command == FENCE_POLYGON_VERTEX_INCLUSION:
            n = int(item.param1)
            group = items[i:i + n]
            if len(group) < n or any(g.command != item.command or int(g.param1) != n
                                     for g in group):
                return f"item {i}: polygon of {n} vertices incomplete"
            i += n
        else:
            i += 1
    return None


class Geodetic(Protocol):
    """The geodetic origin of the local frame (the bridge's ``Origin``)."""

    def to_ned(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """Local NED (m) of a WGS84 point (alt m AMSL)."""
        ...

    def to_geodetic(self, n: float, e: float, d: float) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt m AMSL) of a local NED point."""
        ...


def target(item: MissionItem, geo: Geodetic | None, home_alt: float,
           here: Sequence[float] | np.ndarray) -> np.ndarray:
    """The local NED point an item goes to.  Global frames through the origin ``geo``;
    relative-altitude frames count the altitude above home (``home_alt``, m AMSL).  A
    latitude and longitude both 0 (as QGroundControl and MAVSDK send a takeoff or land
    "here") take the vehicle's own north and east (``here``)."""
    if item.frame == FRAME_LOCAL_NED:
        return np.array([item.x * 1e-4, item.y * 1e-4, item.z])
    if item.frame not in POSITION_FRAMES:
        return np.array(here, float)
    if geo is None:
        raise ValueError(f"item {item.seq}: a global position needs the geodetic origin")
    alt = item.z + (home_alt if item.frame in RELATIVE_FRAMES else 0.0)
    if item.x == 0 and item.y == 0:
        lat, lon, _ = geo.to_geodetic(float(here[0]), float(here[1]), float(here[2]))
        return np.array([float(here[0]), float(here[1]), geo.to_ned(lat, lon, alt)[2]])
    return np.array(geo.to_ned(item.x * 1e-7, item.y * 1e-7, alt))
