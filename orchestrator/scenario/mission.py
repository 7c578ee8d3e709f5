"""A scenario's ``[mission]``: mission items (the ones a ground station uploads) instead of
reference signals, flown by the same executor as the MAVLink bridge's AUTO.MISSION
(:mod:`orchestrator.mission.executor`).

Layout (local NED, metres; angles in degrees)::

    [mission]
    start = [0.0, 0.0, -1.5]      # where the vehicle starts (NED; with start = "ground":
                                  #   resting on the ground below it); home is there too
    yaw_deg = 0.0                 # its heading at the start (optional, 0)
    cruise_speed = 1.0            # m/s horizontal (optional; MPC_XY_CRUISE)
    climb_speed = 1.0             # m/s up (optional)
    descent_speed = 0.7           # m/s down (optional)
    land_speed = 0.5              # m/s down when landing (optional)
    acceptance_radius = 0.1       # m, for waypoints giving none (optional)
    rtl_altitude = 3.0            # m above home a return climbs to (optional)

    [[mission.item]]              # in the order flown; ``command`` is the MAVLink name
    command = "NAV_TAKEOFF"       #   position = [x, y, z], yaw_deg (optional)
    position = [0.0, 0.0, -1.5]
    [[mission.item]]
    command = "FULLPOSE_ATTITUDE" #   roll_deg, pitch_deg of the legs that follow
    roll_deg = 15.0
    [[mission.item]]
    command = "NAV_WAYPOINT"      #   position, hold (s), acceptance_radius (m), yaw_deg
    position = [1.5, 0.0, -1.5]
    [[mission.item]]
    command = "DO_CHANGE_SPEED"   #   speed (m/s), speed_type "ground" | "climb" | "descent"
    speed = 0.5
    [[mission.item]]
    command = "NAV_LOITER_TIME"   #   position, time (s)
    [[mission.item]]
    command = "NAV_RETURN_TO_LAUNCH"
    [[mission.item]]
    command = "NAV_LAND"          #   position = [x, y] (where to land; a z is ignored), yaw_deg

Each item becomes the :class:`~orchestrator.mission.items.MissionItem` a ground station
would upload (local NED frame), checked by the same rules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from orchestrator.mission import items as mi
from orchestrator.mission.executor import Settings
from orchestrator.mission.items import MissionItem
from orchestrator.scenario.reader import FieldReader, ScenarioError

_COMMANDS = {name: cmd for cmd, name in mi.SUPPORTED[mi.MISSION].items()}
#: command -> (fields it takes, whether a position is required)
_FIELDS: dict[int, tuple[tuple[str, ...], bool]] = {
    mi.NAV_TAKEOFF: (("position", "yaw_deg"), True),
    mi.NAV_WAYPOINT: (("position", "hold", "acceptance_radius", "yaw_deg"), True),
    mi.NAV_LOITER_TIME: (("position", "time"), True),
    mi.NAV_LAND: (("position", "yaw_deg"), True),
    mi.NAV_RETURN_TO_LAUNCH: ((), False),
    mi.DO_CHANGE_SPEED: (("speed", "speed_type"), False),
    mi.FULLPOSE_ATTITUDE: (("roll_deg", "pitch_deg"), False),
}
_SPEED_TYPES = {"ground": 1.0, "climb": 2.0, "descent": 3.0}
_SETTINGS = {"cruise_speed": "cruise", "climb_speed": "climb", "descent_speed": "descent",
             "land_speed": "land", "acceptance_radius": "acceptance", "rtl_altitude": "rtl_alt"}


@dataclass(frozen=True)
class ScenarioMission:
    """A scenario's mission: its items, the settings they are flown with, and the start."""

    items: tuple[MissionItem, ...]
    settings: Settings
    start: tuple[float, float, float]  # NED, m
    yaw: float  # rad

    def summary(self) -> dict[str, Any]:
        """JSON-friendly facts (run metadata)."""
        return {"items": [{"seq": it.seq, "command": it.name, "params": list(it.params),
                           "position": _position(it)} for it in self.items],
                "settings": vars(self.settings).copy(), "start": list(self.start)}


def _position(item: MissionItem) -> list[float] | None:
    if item.frame != mi.FRAME_LOCAL_NED:
        return None
    return [item.x * 1e-4, item.y * 1e-4, item.z]


def parse_mission(table: FieldReader, ground_z: float) -> ScenarioMission:
    """The ``[mission]`` table; ScenarioError naming the field otherwise."""
    start = table.numbers("start")
    if len(start) != 3:
        raise table.fail("start", f"expected [x, y, z] (m, NED), got {list(start)}")
    yaw = math.radians(table.number("yaw_deg", 0.0))
    settings = Settings(ground_z=ground_z)
    for key, attr in _SETTINGS.items():
        default = getattr(settings, attr)
        if key == "rtl_altitude":
            setattr(settings, attr, table.number(key, default, nonnegative=True))
        else:
            setattr(settings, attr, table.number(key, default, positive=True))
    raw = table.raw("item")
    if not isinstance(raw, list) or not raw or not all(isinstance(e, dict) for e in raw):
        raise table.fail("item", "expected an array of tables [[mission.item]] with a "
                         "command each")
    out = [_item(FieldReader(table.source, entry, f"{table.field('item')}[{k + 1}]."), k)
           for k, entry in enumerate(raw)]
    why = mi.check_plan(out)
    if why is not None:
        k = int(why.split(":")[0].split()[1])
        raise ScenarioError(table.source, f"{table.field('item')}[{k + 1}]",
                            why.split(": ", 1)[1])
    table.reject_unknown(lambda _k: " (expected start, yaw_deg, item or a speed setting: "
                         + ", ".join(_SETTINGS) + ")")
    return ScenarioMission(tuple(out), settings, (start[0], start[1], start[2]), yaw)


def _item(r: FieldReader, seq: int) -> MissionItem:
    name = r.string("command")
    cmd = _COMMANDS.get(name)
    if cmd is None:
        raise r.fail("command", f"expected one of {', '.join(_COMMANDS)}, got {name!r}")
    fields, needs_position = _FIELDS[cmd]
    pos: np.ndarray | None = None
    if needs_position:
        p = r.numbers("position")
        if cmd == mi.NAV_LAND and len(p) == 2:
            p = (*p, 0.0)
        if len(p) != 3:
            raise r.fail("position", f"expected [x, y, z] (m, NED), got {list(p)}")
        pos = np.array(p)
    yaw = r.number("yaw_deg", math.nan) if "yaw_deg" in fields else math.nan
    params = [0.0, 0.0, 0.0, 0.0]
    if cmd == mi.NAV_WAYPOINT:
        params = [r.number("hold", 0.0, nonnegative=True),
                  r.number("acceptance_radius", 0.0, nonnegative=True), 0.0, yaw]
    elif cmd == mi.NAV_LOITER_TIME:
        params = [r.number("time", nonnegative=True), 0.0, 0.0, math.nan]
    elif cmd in (mi.NAV_TAKEOFF, mi.NAV_LAND):
        params = [0.0, 0.0, 0.0, yaw]
    elif cmd == mi.DO_CHANGE_SPEED:
        kind = r.string("speed_type", "ground", choices=tuple(_SPEED_TYPES))
        params = [_SPEED_TYPES[kind], r.number("speed", positive=True), -1.0, 0.0]
    elif cmd == mi.FULLPOSE_ATTITUDE:
        params = [r.number("roll_deg", 0.0), r.number("pitch_deg", 0.0), 0.0, 0.0]
    r.reject_unknown(lambda _k: f" ({name} takes command"
                     + "".join(f", {f}" for f in fields) + ")")
    return MissionItem.local(seq, cmd, pos, params)
