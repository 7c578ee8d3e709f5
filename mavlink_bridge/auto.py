"""Flight from the ground and back as PX4 flies it: takeoff, land, return, missions, go-to,
the geofence and auto-disarm, all through the mission executor
(:mod:`orchestrator.mission.executor`) that scenario missions use.

The auto modes (AUTO.TAKEOFF, AUTO.LAND, AUTO.RTL, AUTO.MISSION, and AUTO.LOITER when a
go-to moves it) each fly a plan: a one-item plan of their own, or the uploaded mission.
Each chunk, :func:`step` hands the executor the vehicle's state, sets the reference it
returns, tells the ground stations what happened (MISSION_CURRENT, MISSION_ITEM_REACHED,
STATUSTEXT) and moves on as PX4 does: a finished takeoff or mission holds (AUTO.LOITER); a
landing ends on the ground, disarmed after COM_DISARM_LAND.  docs/mavlink.md ("From the
ground") says what each command and parameter does.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mavlink_bridge.context import Context
from mavlink_bridge.setpoints import Reference
from mavlink_bridge.telemetry import mav
from orchestrator.mission import items as mi
from orchestrator.mission.executor import Executor, Settings, Vehicle
from orchestrator.mission.fence import Fence
from orchestrator.mission.items import MissionItem

#: the bridge modes a plan flies (HOLD too, once a go-to gave it one)
AUTO_MODES = ("TAKEOFF", "LAND", "RTL", "MISSION", "HOLD")
FORCE_DISARM = 21196  # MAV_CMD_COMPONENT_ARM_DISARM param2: disarm even in flight
GF_ACTIONS = {0: "none", 1: "warning", 2: "hold", 3: "return", 5: "land"}


def settings(ctx: Context) -> Settings:
    """The executor's settings from the parameters in force (and a DO_CHANGE_SPEED)."""
    g = ctx.params.get
    return Settings(cruise=ctx.cruise if ctx.cruise is not None else g("MPC_XY_CRUISE"),
                    speed_max=g("MPC_XY_VEL_MAX"), climb=g("MPC_Z_VEL_MAX_UP"),
                    descent=g("MPC_Z_VEL_MAX_DN"), land=g("MPC_LAND_SPEED"),
                    acc_hor=g("MPC_ACC_HOR"),
                    acc_ver=min(g("MPC_ACC_UP_MAX"), g("MPC_ACC_DOWN_MAX")),
                    acceptance=g("NAV_ACC_RAD"), rtl_alt=g("RTL_RETURN_ALT"),
                    ground_z=ctx.ground_z)


def _executor(ctx: Context, plan: list[MissionItem], start: int = 0) -> Executor:
    rally = [mi.target(p, ctx.origin, ctx.home_alt, ctx.home) for p in ctx.plans[mi.RALLY]]
    return Executor(plan, settings(ctx), ctx.ref.pos.copy(), ctx.ref.euler.copy(),
                    home=ctx.home.copy(), home_alt=ctx.home_alt, geo=ctx.origin,
                    rally=rally, start=start)


def fly(ctx: Context, mode: str, plan: list[MissionItem], start: int = 0) -> None:
    """Fly ``plan`` in ``mode`` from the reference flown now."""
    ctx.frozen = False
    ctx.pos_sp = ctx.att_sp = None
    ctx.auto = _executor(ctx, plan, start)
    ctx.set_mode(mode)


def here(ctx: Context) -> np.ndarray:
    """The vehicle's position (NED, m)."""
    return np.array(ctx.state["plant"]["pos"], float)


def takeoff_item(ctx: Context, alt_amsl: float, yaw_deg: float) -> MissionItem:
    """NAV_TAKEOFF above the vehicle to alt_amsl (NaN: MIS_TAKEOFF_ALT above home)."""
    if math.isnan(alt_amsl):
        alt_amsl = ctx.home_alt + ctx.params.get("MIS_TAKEOFF_ALT")
    return MissionItem(0, mi.FRAME_GLOBAL_INT, mi.NAV_TAKEOFF, 0.0, 0.0, 0.0, yaw_deg,
                       0, 0, alt_amsl)


def point_item(ctx: Context, command: int, lat: float, lon: float, alt_amsl: float,
               yaw_deg: float) -> MissionItem:
    """An item at lat, lon (deg), alt (m AMSL): NaN (or lat and lon both 0) keeps the
    vehicle's own north and east, a NaN altitude its own altitude."""
    pos = here(ctx)
    if math.isnan(alt_amsl):
        alt_amsl = ctx.origin.to_geodetic(*(float(v) for v in pos))[2]
    if math.isnan(lat) or math.isnan(lon) or (lat == 0.0 and lon == 0.0):
        return MissionItem(0, mi.FRAME_GLOBAL_INT, command, 0.0, 0.0, 0.0, yaw_deg, 0, 0,
                           alt_amsl)
    return MissionItem(0, mi.FRAME_GLOBAL_INT, command, 0.0, 0.0, 0.0, yaw_deg,
                       round(lat * 1e7), round(lon * 1e7), alt_amsl)


def start_mission(ctx: Context, start: int | None = None) -> str | None:
    """AUTO.MISSION from item ``start`` (None: the current item); why not, or None."""
    plan = ctx.plans[mi.MISSION]
    if not plan:
        return "no mission uploaded"
    seq = ctx.mission_current if start is None else start
    if start is None and ctx.mission_complete:
        seq = 0
    if not 0 <= seq < len(plan):
        return f"no mission item {seq} (the mission has {len(plan)})"
    if not ctx.armed:
        return "disarmed: arm first"
    ctx.mission_complete = False
    fly(ctx, "MISSION", plan, seq)
    return None


def start_mode(ctx: Context, mode: str) -> str | None:
    """Enter an auto mode by name (a mode request): why not, or None."""
    if mode == "MISSION":
        return start_mission(ctx)
    if not ctx.armed:
        return "disarmed: arm first"
    if mode == "TAKEOFF":
        fly(ctx, "TAKEOFF", [takeoff_item(ctx, math.nan, math.nan)])
        return None
    if mode == "LAND":
        fly(ctx, "LAND", [point_item(ctx, mi.NAV_LAND, math.nan, math.nan, math.nan,
                                     math.nan)])
        return None
    if mode == "RTL":
        fly(ctx, "RTL", [MissionItem(0, mi.FRAME_MISSION, mi.NAV_RETURN_TO_LAUNCH)])
        return None
    raise ValueError(f"{mode} is not an auto mode")


# -- each chunk ---------------------------------------------------------------------


def step(ctx: Context) -> None:
    """Fly the auto mode's plan one chunk on: its reference, its news, the next mode."""
    ex = ctx.auto
    if ex is None or ctx.mode not in AUTO_MODES:
        return
    s = ctx.session
    t = s.time
    landed = ctx.landed
    r = ex.update(t, Vehicle(here(ctx), np.array(ctx.state["plant"]["euler"]), landed))
    # the chunk holds the reference: the carrot at the chunk's middle (its staircase then
    # straddles the carrot's path instead of lagging it)
    pos, vel, acc = ex.sample(t + 0.5 * s.step_size * s.chunk)
    ctx.ref = Reference(pos, r["euler_ref"], vel, acc, r["euler_rate_ref"])
    _tell(ctx, ex)
    if ex.finished:
        _finished(ctx)


def _tell(ctx: Context, ex: Executor) -> None:
    mission = ctx.mode == "MISSION"
    for e in ex.events:
        if e.kind == "current" and mission:
            ctx.mission_current = e.seq
            ctx.send_all(mav.MAVLink_mission_current_message(
                e.seq, len(ctx.plans[mi.MISSION]), mav.MISSION_STATE_ACTIVE, 0))
        elif e.kind == "reached" and mission:
            ctx.send_all(mav.MAVLink_mission_item_reached_message(e.seq))
        elif e.kind == "notice":
            ctx.statustext(mav.MAV_SEVERITY_WARNING, e.text)
        elif e.kind == "landed":
            ctx.statustext(mav.MAV_SEVERITY_INFO, "landing detected")
    ex.events.clear()


def _finished(ctx: Context) -> None:
    """A plan flown to its end: a mission says so; airborne, hold where it ended (PX4:
    AUTO.LOITER); on the ground, stay (disarmed after COM_DISARM_LAND)."""
    if ctx.mode == "MISSION":
        # as PX4: MISSION_CURRENT stays on the last item with MISSION_STATE_COMPLETE (what
        # MAVSDK's is_mission_finished reads); a new start begins at the first item
        ctx.mission_complete = True
        ctx.send_all(mav.MAVLink_mission_current_message(
            ctx.mission_current, len(ctx.plans[mi.MISSION]), mav.MISSION_STATE_COMPLETE, 0))
        ctx.statustext(mav.MAV_SEVERITY_INFO, "mission finished")
    if ctx.mode in ("MISSION", "TAKEOFF") and not ctx.landed:
        ctx.auto = None
        ctx.set_mode("HOLD")
    elif ctx.mode == "HOLD":
        ctx.auto = None  # a go-to arrived: hold there (the reference stays)


def watch_ground(ctx: Context) -> None:
    """Auto-disarm as PX4's COM_DISARM_LAND and COM_DISARM_PRFLT: landed for that long after a
    flight, or armed that long without taking off (a parameter <= 0 switches it off)."""
    if not ctx.armed or not ctx.ground_start:
        return
    t = ctx.session.time
    if not ctx.landed:
        ctx.flew = True
        ctx.landed_since = math.inf
        return
    ctx.landed_since = min(ctx.landed_since, t)
    delay = ctx.params.get("COM_DISARM_LAND" if ctx.flew else "COM_DISARM_PRFLT")
    if delay > 0 and t - ctx.landed_since >= delay - 1e-9:
        text = "disarmed: landed" if ctx.flew else "disarmed: no takeoff"
        ctx.disarm()
        ctx.statustext(mav.MAV_SEVERITY_INFO, text)


def watch_fence(ctx: Context) -> None:
    """The geofence in flight: on leaving it, the GF_ACTION (told once per breach)."""
    if ctx.fence.empty or not ctx.armed or ctx.landed:
        ctx.breached = False
        return
    inside = ctx.fence.contains(here(ctx))
    if inside or ctx.breached:
        ctx.breached = not inside
        return
    ctx.breached = True
    action = int(ctx.params.get("GF_ACTION"))
    if action == 0:
        return
    ctx.statustext(mav.MAV_SEVERITY_CRITICAL,
                   f"geofence breached: {GF_ACTIONS.get(action, 'hold')}")
    if action == 2:
        ctx.hold()
        ctx.set_mode("HOLD")
    elif action == 3:
        start_mode(ctx, "RTL")
    elif action == 5:
        start_mode(ctx, "LAND")


def refresh_fence(ctx: Context) -> None:
    """The fence's zones from the fence plan held (after an upload or a new home)."""
    ctx.fence = Fence.from_items(ctx.plans[mi.FENCE], ctx.origin, ctx.home_alt)


def message_home(msg: Any) -> tuple[float, float, float]:
    """SET_HOME_POSITION's lat, lon (deg) and altitude (m AMSL)."""
    return int(msg.latitude) * 1e-7, int(msg.longitude) * 1e-7, int(msg.altitude) * 1e-3
