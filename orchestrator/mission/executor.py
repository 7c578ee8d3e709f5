"""The mission executor: a plan of mission items flown as the controller's full-pose reference.

Each item becomes a leg.  A leg moves a point (the carrot) along straight segments with a
trapezoidal speed profile (speeding up and slowing down at the accelerations in force, at
most the speeds in force; horizontal and vertical parts each within their own limit) and
hands the controller the carrot's position, velocity and acceleration; the controller's own
reference shaping smooths the remaining steps of acceleration within its jerk limits.  A
leg is reached when the carrot has arrived and the vehicle is within the acceptance radius
of the end; it is done after its hold time.  Roll and pitch come from the last
FULLPOSE_ATTITUDE item (level before any), the heading from the item's yaw (param4,
degrees; NaN keeps the heading flown).  Takeoff and landing are flown level.

Landing descends at the landing speed until the controller's land detector says landed
(``Vehicle.landed``); the carrot stops ``LAND_DEPTH`` below the ground when the ground's
height is known, so the reference is below the gear and the controller idles the rotors.

The executor knows no MAVLink transport and no FMU: the MAVLink bridge and the scenario
runner both call :meth:`Executor.update` with the vehicle's state and feed the reference
it returns, so a ground station's mission and a scenario's mission fly the same way.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from orchestrator.mission import items as mi
from orchestrator.mission.items import Geodetic, MissionItem

LAND_DEPTH = 0.3  # m: how far below the ground the landing reference stops


@dataclass
class Settings:
    """Speeds, radii and altitudes a plan is flown with (the bridge sets them from PX4's
    parameters of the same meaning: docs/mavlink.md)."""

    cruise: float = 1.0  # m/s horizontal (MPC_XY_CRUISE; DO_CHANGE_SPEED types 0, 1)
    speed_max: float = 5.0  # m/s: the fastest DO_CHANGE_SPEED flown (MPC_XY_VEL_MAX)
    climb: float = 1.0  # m/s up (MPC_Z_VEL_MAX_UP; DO_CHANGE_SPEED type 2)
    descent: float = 0.7  # m/s down (MPC_Z_VEL_MAX_DN; DO_CHANGE_SPEED type 3)
    land: float = 0.5  # m/s down when landing (MPC_LAND_SPEED)
    acc_hor: float = 2.0  # m/s^2 horizontal speed-up and slow-down (MPC_ACC_HOR)
    acc_ver: float = 1.5  # m/s^2 vertical (MPC_ACC_UP_MAX, MPC_ACC_DOWN_MAX)
    acceptance: float = 0.1  # m: acceptance radius of an item giving 0 (NAV_ACC_RAD)
    rtl_alt: float = 3.0  # m above home a return climbs to first (RTL_RETURN_ALT)
    ground_z: float | None = None  # NED z of the ground (None: unknown)

    def checked(self) -> Settings:
        """Itself, or ValueError naming the first value that cannot be flown."""
        for name in ("cruise", "speed_max", "climb", "descent", "land", "acceptance",
                     "acc_hor", "acc_ver"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"mission setting {name} must be positive, got {v!r}")
        if not (math.isfinite(self.rtl_alt) and self.rtl_alt >= 0):
            raise ValueError(f"mission setting rtl_alt must be >= 0, got {self.rtl_alt!r}")
        return self


@dataclass(frozen=True)
class Vehicle:
    """What the executor needs of the vehicle: NED position (m), Euler angles (rad), and
    whether the controller's land detector says landed."""

    pos: np.ndarray
    euler: np.ndarray
    landed: bool = False


@dataclass(frozen=True)
class Event:
    """Something the ground station (or the run's log) is told: ``kind`` is "current" (item
    ``seq`` is flown now), "reached" (item ``seq`` reached), "landed", "finished" or
    "notice" (``text`` says what)."""

    time: float
    kind: str
    seq: int
    text: str = ""


@dataclass(frozen=True)
class LegRecord:
    """One item as flown: its place, command name, start, reach and end time (s; NaN:
    not yet)."""

    seq: int
    name: str
    start: float
    reached: float = math.nan
    end: float = math.nan


@dataclass
class _Segment:
    """A straight line from a to b flown with a trapezoidal speed profile: speed up at
    ``acc``, cruise at ``speed``, slow down at ``acc`` to rest at b (a triangle when the line
    is too short to reach the speed)."""

    a: np.ndarray
    b: np.ndarray
    t0: float
    speed: float  # m/s along the line
    acc: float  # m/s^2 along the line

    def __post_init__(self) -> None:
        self.length = float(np.linalg.norm(self.b - self.a))
        self.dir = (self.b - self.a) / self.length if self.length > 0 else np.zeros(3)
        self.peak = min(self.speed, math.sqrt(self.length * self.acc))
        self.ramp = self.peak / self.acc  # s to reach the peak speed
        cruise = (self.length - self.peak * self.ramp) / self.peak if self.peak > 0 else 0.0
        self.duration = 2.0 * self.ramp + max(cruise, 0.0)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at time t."""
        u = t - self.t0
        if self.length <= 0 or u >= self.duration:
            return self.b.copy(), np.zeros(3), np.zeros(3)
        u = max(u, 0.0)
        left = self.duration - u
        if u < self.ramp:
            s, v, a = 0.5 * self.acc * u * u, self.acc * u, self.acc
        elif left < self.ramp:
            s = self.length - 0.5 * self.acc * left * left
            v, a = self.acc * left, -self.acc
        else:
            s, v, a = 0.5 * self.peak * self.ramp + self.peak * (u - self.ramp), self.peak, 0.0
        return self.a + self.dir * s, self.dir * v, self.dir * a

    def done(self, t: float) -> bool:
        """Whether the line has been flown to its end by time t."""
        return t >= self.t0 + self.duration - 1e-12


@dataclass
class _Leg:
    seq: int
    points: list[np.ndarray]  # corners after the start, flown in order
    speeds: list[tuple[float, float]]  # (horizontal, vertical) per corner
    acceptance: float
    hold: float
    land: bool = False  # descend at the landing speed after the corners until landed
    segment: _Segment | None = None
    corner: int = 0
    reached_at: float = math.nan
    descent: tuple[float, float] | None = None  # (start time, start z) of the landing descent


@dataclass
class Executor:
    """Flies ``plan`` (mission items) from item ``start``; ``update`` once per control period
    gives the reference.  ``home``: local NED of home (returns and relative altitudes);
    ``home_alt``: its altitude (m AMSL); ``geo``: the local frame's geodetic origin (for
    items in global frames); ``rally``: rally points (local NED) a return may go to."""

    plan: Sequence[MissionItem]
    settings: Settings
    pos: np.ndarray  # the reference's start: position (NED, m) ...
    euler: np.ndarray  # ... and Euler angles (rad)
    home: np.ndarray = field(default_factory=lambda: np.zeros(3))
    home_alt: float = 0.0
    geo: Geodetic | None = None
    rally: Sequence[np.ndarray] = ()
    start: int = 0
    events: list[Event] = field(default_factory=list)
    legs: list[LegRecord] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.settings.checked()
        self.pos = np.array(self.pos, float)
        self.euler = np.array(self.euler, float)
        self.vel = np.zeros(3)
        self.acc = np.zeros(3)
        self.tilt = np.zeros(2)  # roll, pitch of the legs (FULLPOSE_ATTITUDE)
        self.current = self.start
        self.finished = False
        self._leg: _Leg | None = None
        self._started = False

    @property
    def phase(self) -> str:
        """"takeoff" while a takeoff leg is flown, "landing" while a landing descends, else
        "" (what EXTENDED_SYS_STATE's landed state tells)."""
        leg = self._leg
        if leg is None:
            return ""
        if self.plan[self.current].command == mi.NAV_TAKEOFF:
            return "takeoff"
        return "landing" if leg.land and leg.descent is not None else ""

    # -- the loop ----------------------------------------------------------------

    def update(self, t: float, vehicle: Vehicle) -> dict[str, np.ndarray]:
        """The reference at time t (s) for the vehicle as it is: the controller FMU's
        reference inputs by name."""
        if not self._started:
            self._started = True
            self._begin(t, vehicle)
        leg = self._leg
        if leg is not None:
            self._fly(leg, t, vehicle)
        return {"pos_ref": self.pos.copy(), "euler_ref": self.euler.copy(),
                "vel_ref": self.vel.copy(), "acc_ref": self.acc.copy(),
                "euler_rate_ref": np.zeros(3)}

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference's position, velocity and acceleration at a time t after the last
        ``update`` and before the next, without moving on (between two updates the carrot
        follows its segment, or its landing descent)."""
        leg = self._leg
        if leg is not None and leg.segment is not None:
            return leg.segment.at(t)
        if leg is not None and leg.descent is not None:
            return self._descent_at(leg.descent, t)
        return self.pos.copy(), self.vel.copy(), self.acc.copy()

    def _descent_at(self, descent: tuple[float, float], t: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Down from (t0, z0): speeding up at the vertical acceleration to the landing speed,
        stopping LAND_DEPTH below the ground when it is known."""
        s = self.settings
        t0, z0 = descent
        u = max(t - t0, 0.0)
        ramp = s.land / s.acc_ver
        if u < ramp:
            dz, v, a = 0.5 * s.acc_ver * u * u, s.acc_ver * u, s.acc_ver
        else:
            dz, v, a = 0.5 * s.land * ramp + s.land * (u - ramp), s.land, 0.0
        pos = self.pos.copy()
        pos[2] = z0 + dz
        if s.ground_z is not None and pos[2] >= s.ground_z + LAND_DEPTH:
            pos[2], v, a = max(s.ground_z + LAND_DEPTH, z0), 0.0, 0.0
        return pos, np.array([0.0, 0.0, v]), np.array([0.0, 0.0, a])

    def _begin(self, t: float, vehicle: Vehicle) -> None:
        """Start item ``current``: do-items take effect at once; a leg is set up."""
        while self.current < len(self.plan):
            item = self.plan[self.current]
            self.events.append(Event(t, "current", self.current))
            self.legs.append(LegRecord(self.current, item.name, t))
            leg = self._make_leg(item, t, vehicle)
            if leg is not None:
                self._leg = leg
                self._next_segment(leg, t)
                return
            self._close_record(t, reached=True)
            self.current += 1
        self._leg = None
        self.vel = np.zeros(3)
        if not self.finished:
            self.finished = True
            self.events.append(Event(t, "finished", len(self.plan) - 1))

    def _fly(self, leg: _Leg, t: float, vehicle: Vehicle) -> None:
        seg = leg.segment
        if seg is not None:
            self.pos, self.vel, self.acc = seg.at(t)
            if seg.done(t):
                leg.corner += 1
                self._next_segment(leg, t)
            return
        if leg.land:
            self._descend(leg, t, vehicle)
            return
        if math.isnan(leg.reached_at):
            if float(np.linalg.norm(vehicle.pos - self.pos)) <= leg.acceptance:
                leg.reached_at = t
                self._reached(t)
            else:
                return
        if t - leg.reached_at >= leg.hold - 1e-9:
            self._advance(t, vehicle)

    def _descend(self, leg: _Leg, t: float, vehicle: Vehicle) -> None:
        """Down at the landing speed until the land detector says landed."""
        if vehicle.landed:
            self.vel, self.acc = np.zeros(3), np.zeros(3)
            self._reached(t)
            self.events.append(Event(t, "landed", self.current))
            self._advance(t, vehicle)
            return
        if leg.descent is None:
            leg.descent = (t, float(self.pos[2]))
        self.pos, self.vel, self.acc = self._descent_at(leg.descent, t)

    def _reached(self, t: float) -> None:
        self.events.append(Event(t, "reached", self.current))
        if self.legs and math.isnan(self.legs[-1].reached):
            r = self.legs[-1]
            self.legs[-1] = LegRecord(r.seq, r.name, r.start, t, r.end)

    def _close_record(self, t: float, reached: bool = False) -> None:
        r = self.legs[-1]
        self.legs[-1] = LegRecord(r.seq, r.name, r.start,
                                  t if reached and math.isnan(r.reached) else r.reached, t)

    def _advance(self, t: float, vehicle: Vehicle) -> None:
        self._close_record(t)
        self.current += 1
        self._leg = None
        self._begin(t, vehicle)

    def _next_segment(self, leg: _Leg, t: float) -> None:
        if leg.corner >= len(leg.points):
            leg.segment = None
            self.vel, self.acc = np.zeros(3), np.zeros(3)
            return
        b = leg.points[leg.corner]
        v_h, v_v = leg.speeds[leg.corner]
        d = b - self.pos
        length = float(np.linalg.norm(d))
        # along the line, the speed and acceleration whose horizontal and vertical parts stay
        # within their limits
        h, v = (float(np.hypot(d[0], d[1])) / length, abs(float(d[2])) / length) \
            if length > 0 else (1.0, 0.0)
        s = self.settings
        speed = min(v_h / h if h > 1e-12 else math.inf, v_v / v if v > 1e-12 else math.inf)
        acc = min(s.acc_hor / h if h > 1e-12 else math.inf,
                  s.acc_ver / v if v > 1e-12 else math.inf)
        leg.segment = _Segment(self.pos.copy(), b, t, speed, acc)
        self.pos, self.vel, self.acc = leg.segment.at(t)
        if leg.segment.done(t):
            leg.corner += 1
            self._next_segment(leg, t)

    # -- items -------------------------------------------------------------------

    def _target(self, item: MissionItem, vehicle: Vehicle) -> np.ndarray:
        return mi.target(item, self.geo, self.home_alt, vehicle.pos)

    def _vertical(self, z_to: float) -> float:
        s = self.settings
        return s.climb if z_to < self.pos[2] else s.descent

    def _heading(self, yaw_deg: float) -> None:
        if math.isfinite(yaw_deg):
            self.euler[2] = math.atan2(math.sin(math.radians(yaw_deg)),
                                       math.cos(math.radians(yaw_deg)))

    def _make_leg(self, item: MissionItem, t: float, vehicle: Vehicle) -> _Leg | None:
        """The leg of a positioned item (None: a do-item, carried out here)."""
        s, c = self.settings, item.command
        if c == mi.DO_CHANGE_SPEED:
            self._change_speed(item, t)
            return None
        if c == mi.FULLPOSE_ATTITUDE:
            self.tilt = np.radians([item.param1, item.param2])
            return None
        if c in (mi.NAV_WAYPOINT, mi.NAV_LOITER_TIME):
            b = self._target(item, vehicle)
            if c == mi.NAV_WAYPOINT:  # (NAV_LOITER_TIME's param4 is a fixed-wing exit path)
                self._heading(item.param4)
            self.euler[:2] = self.tilt
            radius = item.param2 if c == mi.NAV_WAYPOINT and item.param2 > 0 else s.acceptance
            return _Leg(self.current, [b], [(s.cruise, self._vertical(b[2]))], radius,
                        max(item.param1, 0.0))
        if c == mi.NAV_TAKEOFF:
            b = self._target(item, vehicle)
            self._heading(item.param4)
            self.euler[:2] = 0.0
            up = np.array([self.pos[0], self.pos[1], b[2]])
            return _Leg(self.current, [up, b], [(s.cruise, s.climb), (s.cruise, s.climb)],
                        s.acceptance, 0.0)
        if c == mi.NAV_LAND:
            b = self._target(item, vehicle)
            self._heading(item.param4)
            self.euler[:2] = 0.0
            over = np.array([b[0], b[1], self.pos[2]])
            return _Leg(self.current, [over], [(s.cruise, s.descent)], s.acceptance, 0.0,
                        land=True)
        if c == mi.NAV_RETURN_TO_LAUNCH:
            self.euler[:2] = 0.0
            dest = self._return_point()
            z = min(self.pos[2], self.home[2] - s.rtl_alt)
            corners = [np.array([self.pos[0], self.pos[1], z]), np.array([dest[0], dest[1], z])]
            return _Leg(self.current, corners, [(s.cruise, s.climb), (s.cruise, s.climb)],
                        s.acceptance, 0.0, land=True)
        raise ValueError(f"item {item.seq}: {item.name} cannot be flown")  # checked at upload

    def _return_point(self) -> np.ndarray:
        """Home, or the nearest rally point when one is nearer."""
        best = np.array(self.home, float)
        for p in self.rally:
            if np.linalg.norm(p[:2] - self.pos[:2]) < np.linalg.norm(best[:2] - self.pos[:2]):
                best = np.array(p, float)
        return best

    def _change_speed(self, item: MissionItem, t: float) -> None:
        s, speed = self.settings, item.param2
        if speed == -1.0:
            return
        kind = int(item.param1)
        if kind in (0, 1) and speed > s.speed_max:
            self.events.append(Event(t, "notice", item.seq,
                                     f"speed {speed:g} m/s above the limit {s.speed_max:g}: "
                                     f"flying {s.speed_max:g} m/s"))
            speed = s.speed_max
        if kind in (0, 1):
            s.cruise = speed
        elif kind == 2:
            s.climb = speed
        else:
            s.descent = speed


def local_plan(specs: Sequence[tuple[int, Sequence[float] | None, Sequence[float]]]
               ) -> list[MissionItem]:
    """Mission items in the local NED frame from (command, position or None, params)."""
    return [MissionItem.local(i, cmd, pos, params) for i, (cmd, pos, params) in
            enumerate(specs)]
