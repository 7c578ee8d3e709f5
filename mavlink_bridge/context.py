"""What every part of the bridge shares: its configuration, the co-simulation, the endpoints,
the vehicle as the ground stations see it (mode, arming, reference, setpoints, limits,
parameters) and the ways to tell them (STATUSTEXT, HEARTBEAT, replies).

The router (:mod:`mavlink_bridge.bridge`) steps the loop and hands each message to a handler
(:mod:`mavlink_bridge.handlers`); both work on a :class:`Context`, so a handler never imports
the router.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mavlink_bridge import px4, stability, telemetry
from mavlink_bridge.budget import RequestBudget
from mavlink_bridge.geodesy import Origin
from mavlink_bridge.links import Address, Endpoint, Signing
from mavlink_bridge.params import FLIGHT_PARAMETERS, ParameterTable, Range, fmu_range
from mavlink_bridge.setpoints import (
    AttitudeSetpoint,
    Limits,
    PositionSetpoint,
    Reference,
    VehicleState,
)
from mavlink_bridge.telemetry import Snapshot, mav
from orchestrator.mission import items
from orchestrator.mission.executor import Executor
from orchestrator.mission.fence import Fence
from orchestrator.mission.items import MissionItem
from orchestrator.sim.live import LiveSession
from plant import Airframe

DEFAULT_URLS = ("udpout:127.0.0.1:14550", "udpout:127.0.0.1:14540")
SYSTEM_ID = 1
COMPONENT_ID = 1
STATUSTEXT_PER_S = 5  # rejection/refusal messages per wall second, the rest are counted
STATUSTEXT_CHUNK = 50  # characters per STATUSTEXT; longer texts go in chunks (MAVLink 2)
EVENTS_KEPT = 1000  # STATUSTEXTs kept in Context.events (the older half dropped beyond)

Source = tuple[int, int]
"""(system id, component id) of a message's sender."""


@dataclass
class PacingStats:
    """How the loop kept up with the wall clock."""

    speed: float
    sim_time: float = 0.0
    wall_time: float = 0.0
    chunks: int = 0
    max_lag: float = 0.0  # s of wall time the published state was ever late
    late_chunks: int = 0  # chunks finished more than one chunk period late
    datagrams: int = 0
    messages: int = 0
    malformed: int = 0
    ignored: int = 0
    refused_unsigned: int = 0
    throttled: int = 0  # requests beyond a sender's budget (mavlink_bridge.budget)
    sent: int = 0
    max_rx_rate: float = 0.0  # datagrams per wall second, best 1 s window

    @property
    def achieved_speed(self) -> float:
        """Simulated seconds per wall second over the run."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else 0.0

    def lines(self) -> list[str]:
        """The run's pacing summary, a line each, for a terminal."""
        target = "max" if math.isinf(self.speed) else f"{self.speed:g}x"
        return [
            f"simulated           {self.sim_time:.3f} s in {self.wall_time:.3f} s wall "
            f"(speed {target}, achieved {self.achieved_speed:.2f}x)",
            f"max lag             {1e3 * self.max_lag:.2f} ms behind wall time "
            f"({self.late_chunks} of {self.chunks} chunks late by more than a chunk)",
            f"received            {self.datagrams} datagrams, {self.messages} messages "
            f"({self.malformed} malformed, {self.ignored} ignored, "
            f"{self.refused_unsigned} refused by signing, {self.throttled} throttled); "
            f"peak {self.max_rx_rate:.0f}/s",
            f"sent                {self.sent} messages",
        ]


@dataclass
class BridgeConfig:
    """What a bridge flies and how: the airframe, start pose, FMU parameter overrides and coupling;
    its MAVLink endpoints, speed (simulated seconds per wall second; math.inf: as fast as
    possible), signing, duration, chunk size, safety limits and geodetic origin."""
    airframe: str | Airframe = "paper_hexacopter"
    pos0: Sequence[float] = (0.0, 0.0, -3.0)
    euler0: Sequence[float] = (0.0, 0.0, 0.0)
    plant_parameters: Mapping[str, Any] | None = None
    controller_parameters: Mapping[str, Any] | None = None
    coupling: str = "gauss-seidel"
    urls: Sequence[str] = DEFAULT_URLS
    speed: float = 1.0  # math.inf: as fast as possible
    signing_key: bytes | None = None
    # a one-time key: a SETUP_SIGNING signed with it (while disarmed, without ``signing_key``)
    # installs the key it carries; None: SETUP_SIGNING only on a link already signed
    signing_setup_key: bytes | None = None
    # the bridge's own FPB_ parameters (safety limits, timeouts) set at start: over MAVLink
    # they change only on a signed link
    bridge_parameters: Mapping[str, float] | None = None
    duration: float | None = None  # simulated s; None: until stop()
    chunk: int = 5
    limits: Limits = field(default_factory=Limits)
    origin: Origin = field(default_factory=Origin)  # WGS84 point of local NED (0, 0, 0)
    system_id: int = SYSTEM_ID  # MAVLink system id (PX4 SITL instance i: i + 1)
    # "ground": boot landed and disarmed, resting on the landing gear below pos0 (as PX4
    # SITL); "air": hovering at pos0 from the start, the rotors spinning whatever the arming
    start: str = "ground"
    mission: Sequence[MissionItem] = ()  # a mission held from the start (a scenario's)
    # the controller image (fullpose build-embedded) on the emulated Cortex-M7 in place of
    # the controller FMU (processor in the loop); None: the FMU
    pil: Path | None = None


def stopping_point(pos: np.ndarray, vel: np.ndarray, acc: np.ndarray, acc_limit: np.ndarray,
                   jerk_limit: np.ndarray) -> np.ndarray:
    """Where a reference at pos moving at vel with acceleration acc comes to rest when it
    brakes at most at acc_limit [horizontal, vertical] with jerk at most jerk_limit: per
    direction (the horizontal motion, the vertical one) the distance of a jerk-limited stop
    (:func:`stop_distance`).  A zero limit (none known) stops where the reference is."""
    out = np.array(pos, float)
    v, a = np.asarray(vel, float), np.asarray(acc, float)
    for idx, k in (([0, 1], 0), ([2], 1)):
        s = float(np.linalg.norm(v[idx]))
        if s <= 0.0:
            continue
        along = v[idx] / s
        d = stop_distance(s, float(a[idx] @ along), float(acc_limit[k]), float(jerk_limit[k]))
        out[idx] += along * d
    return out


def stop_distance(speed: float, acc: float, acc_max: float, jerk_max: float,
                  dt: float = 1e-3) -> float:
    """Distance to rest from speed (> 0) with acceleration acc along the motion: the jerk
    is -jerk_max until the deceleration reaches acc_max, then +jerk_max from the moment the
    speed left equals what the release to zero acceleration takes (a^2 / 2 jerk_max), so
    the stop ends at zero speed and zero acceleration.  Integrated at dt (exact to O(dt))."""
    if not acc_max > 0.0 or not jerk_max > 0.0:
        return 0.0
    x, v, a = 0.0, speed, acc
    for _ in range(int(600.0 / dt)):  # 10 min of braking at most
        if v <= 0.0 and a >= 0.0:
            break
        release = a < 0.0 and v <= a * a / (2.0 * jerk_max)
        jerk = jerk_max if release else -jerk_max
        a_next = min(max(a + jerk * dt, -acc_max), acc_max)
        if release:
            a_next = min(a_next, 0.0)
        v_next = v + 0.5 * (a + a_next) * dt
        x += 0.5 * (v + max(v_next, 0.0)) * dt
        v, a = v_next, a_next
        if v <= 0.0:
            break
    return x


class Context:
    """The bridge's shared state and its voice: opens the co-simulation and the endpoints of a
    :class:`BridgeConfig`; holds the mode, arming, reference and setpoints the handlers change;
    tells the ground stations (:meth:`statustext`, :meth:`heartbeat_now`, :meth:`ack`)."""

    def __init__(self, config: BridgeConfig) -> None:
        if not config.speed > 0:
            raise ValueError("speed must be positive (math.inf: as fast as possible)")
        if not config.urls:
            raise ValueError("at least one endpoint is needed")
        if config.start not in ("ground", "air"):
            raise ValueError(f"start must be 'ground' or 'air', got {config.start!r}")
        if not 1 <= config.system_id <= 255:
            raise ValueError(f"system id {config.system_id} outside 1..255")
        self.config = config
        controller = None
        if config.pil is not None:  # the controller image on the emulated Cortex-M7
            from controller import controller_fmu
            from orchestrator.pil.instance import PilController

            controller = PilController(config.pil, controller_fmu())
        self.session = LiveSession(config.airframe, pos0=config.pos0, euler0=config.euler0,
                                   chunk=config.chunk,
                                   plant_parameters=config.plant_parameters,
                                   controller_parameters_=config.controller_parameters,
                                   coupling=config.coupling, ground=config.start == "ground",
                                   controller=controller)
        self.endpoints: list[Endpoint] = []
        try:
            for i, url in enumerate(config.urls):
                self.endpoints.append(Endpoint(url, link_id=i, system=config.system_id,
                                               component=COMPONENT_ID))
        except Exception:
            self.close()
            raise
        for ep in self.endpoints:
            ep.intervals = {k: 1.0 / v for k, v in telemetry.DEFAULT_RATES.items()}
        self.signing = Signing()
        if config.signing_key is not None:
            self.set_signing(config.signing_key)
        self.airframe = self.session.airframe
        self.params = ParameterTable(self._tunables(), self.session.set_controller_parameter,
                                     guard=stability.guard)
        flight = {bp.name for bp in FLIGHT_PARAMETERS}
        for name, value in (config.bridge_parameters or {}).items():
            if not (name.startswith("FPB_") or name in flight) or self.params.index(name) is None:
                self.close()
                raise ValueError(f"{name}: not a bridge parameter (FPB_... or "
                                 f"{', '.join(sorted(flight))})")
            refused = self.params.set(name, float(value))
            if refused is not None:
                self.close()
                raise ValueError(str(refused))
        self.limits = config.limits
        self.sync_limits()
        self.stats = PacingStats(speed=config.speed)
        self.origin = config.origin
        self.battery = telemetry.Battery()
        self.mode = "HOLD"
        self.armed = False
        self.ground_start = config.start == "ground"
        pos0 = self.session.pos0
        self.ref = Reference.hold(pos0, np.array(config.euler0, float))
        if self.ground_start:
            self.ref.euler[:2] = 0.0
        self.ground_z = float((config.plant_parameters or {}).get("ground_z", 0.0)) \
            if self.airframe.gear is not None else None
        # home (DO_SET_HOME moves it): where the vehicle rests at boot; on an air start the
        # ground below (the origin's level without a ground)
        self.home = pos0.copy()
        if not self.ground_start:
            self.home[2] = self.ground_z if self.ground_z is not None else 0.0
        self.auto: Executor | None = None  # the plan an auto mode flies (mavlink_bridge.auto)
        self.cruise: float | None = None  # a DO_CHANGE_SPEED in force (m/s; None: none)
        self.flew = False  # airborne since armed (auto-disarm: COM_DISARM_LAND / _PRFLT)
        self.landed_since = math.inf  # simulated s the vehicle has been landed since
        self.fence = Fence()
        self.breached = False
        self.pos_sp: PositionSetpoint | None = None
        self.att_sp: AttitudeSetpoint | None = None
        self.last_setpoint: float = -math.inf  # simulated time of the last accepted one
        self.frozen = False  # OFFBOARD with stale setpoints: holding the pose
        self.busy = 0.0  # wall s spent computing chunks
        self.events: list[str] = []  # STATUSTEXTs sent, for logs and tests
        self.told_unsupported: dict[tuple[str, int, int], float] = {}  # -> wall time
        self.setup_key = config.signing_setup_key  # spent once used
        self.budget = RequestBudget()
        # the message being handled: its sender's address and whether its signature is valid
        self.sender: Address = ("", 0)
        self.signed = False
        self._text_id = 0
        self._state = self.session.state()
        self._snapshot: Snapshot | None = None
        self._text_budget: tuple[int, int] = (0, 0)  # (wall second, sent in it)
        self._text_dropped = 0
        # the plans held (mission, fence, rally: orchestrator.mission.items), as uploaded
        self.plans: dict[int, list[MissionItem]] = {k: [] for k in items.MISSION_TYPES}
        self.mission_current = 0  # the mission item flown or to fly next (MISSION_CURRENT)
        self.mission_complete = False  # flown to its end (MISSION_STATE_COMPLETE)
        if config.mission:
            why = self.install_plan(items.MISSION, list(config.mission))
            if why is not None:
                self.close()
                raise ValueError(f"mission refused: {why}")

    @property
    def state(self) -> dict[str, dict[str, np.ndarray]]:
        """The session's latest outputs (``LiveSession.state()``), as of the last chunk."""
        return self._state

    def refresh(self) -> None:
        """Read the session's outputs after a chunk; the next snapshot is made anew."""
        self._state = self.session.state()
        self._snapshot = None

    # -- setup -----------------------------------------------------------------

    def _tunables(self) -> list[tuple[str, float, Range]]:
        """(name, value in force, range the FMU's modelDescription declares)."""
        inst = self.session.ctrl_inst
        out = []
        for name, var in inst.variables.items():
            if var.causality == "parameter" and var.variability == "tunable":
                out.append((name, float(inst.get(name)), fmu_range(var)))
        return out

    def sync_limits(self) -> None:
        """Take the setpoint timeouts and limits from the FPB_ parameters in force."""
        g = self.params.get
        self.timeout = g("FPB_SP_TIMEOUT")
        self.stale = g("FPB_SP_STALE")
        self.limits.xy, self.limits.z = g("FPB_SP_XY_MAX"), g("FPB_SP_Z_MAX")
        self.limits.vel, self.limits.acc = g("FPB_SP_VEL_MAX"), g("FPB_SP_ACC_MAX")
        self.limits.rate, self.limits.tilt = g("FPB_SP_RATE_MAX"), g("FPB_SP_TILT_MAX")

    def set_signing(self, key: bytes | None, initial_timestamp: int = 0) -> None:
        """Sign outgoing and require signed incoming messages with key on every endpoint (None:
        signing off)."""
        self.signing.enable(key, initial_timestamp)
        for ep in self.endpoints:
            ep.set_signing(self.signing)

    # -- vehicle state -------------------------------------------------------------

    @property
    def control_active(self) -> bool:
        """Whether offboard setpoints steer the vehicle (armed and in OFFBOARD)."""
        return self.armed and self.mode == "OFFBOARD"

    def vehicle(self) -> VehicleState:
        """The vehicle's position and attitude now (copies)."""
        p = self._state["plant"]
        return VehicleState(p["pos"].copy(), p["euler"].copy())

    def freeze(self) -> None:
        """Setpoints stale (older than FPB_SP_STALE): stop and hold where the vehicle stops.
        Neither the last velocity nor the last target is flown on: the position held is the
        end of a stop of the controller's shaped reference from its present speed within its
        own acceleration and jerk limits (:func:`stopping_point`), so the vehicle brakes
        once and never comes back; the attitude held is the one reached."""
        self.frozen = True
        v = self.vehicle()
        ctrl = self._state["ctrl"]
        pos = stopping_point(ctrl["pos_ref_s"], ctrl["vel_ref_s"], ctrl["acc_ref_s"],
                             ctrl["ref_acc_limit"], ctrl["ref_jerk_limit"])
        self.ref = Reference.hold(pos, v.euler)

    @property
    def landed(self) -> bool:
        """Whether the controller's land detector says landed."""
        return bool(self._state["ctrl"]["landed"][0] > 0.5)

    @property
    def home_alt(self) -> float:
        """Home's altitude (m AMSL): what relative altitudes count from."""
        return self.origin.to_geodetic(*(float(v) for v in self.home))[2]

    def set_armed(self, armed: bool) -> None:
        """Arm or disarm: the controller's ``armed`` input follows on a ground start (on an
        air start the rotors spin from the start, as when armed in flight)."""
        self.armed = armed
        self.flew = False
        self.landed_since = math.inf
        if self.ground_start:
            self.session.set_armed(armed)

    def disarm(self) -> None:
        """Disarm (the rotors stop on a ground start) and hold: the mode becomes HOLD."""
        self.set_armed(False)
        self.hold()
        self.mode = "HOLD"
        self.heartbeat_now()

    def hold(self) -> None:
        """Hold the pose reached and forget the setpoints; after a setpoint loss the pose
        already held since (:meth:`freeze`) is kept, so the vehicle does not move again.
        A plan being flown is dropped; on the ground the hold is the pose on the gear."""
        self.auto = None
        if not self.frozen:
            v = self.vehicle()
            self.ref = Reference.hold(v.pos, v.euler)
        self.frozen = False
        self.pos_sp = None
        self.att_sp = None

    def set_mode(self, mode: str) -> None:
        """Switch to mode; a change is told at once by a HEARTBEAT."""
        if mode != self.mode:
            self.mode = mode
            self.heartbeat_now()

    def enter_offboard(self) -> None:
        """Enter OFFBOARD from the pose reached, flying the setpoints received so far."""
        self.frozen = False
        v = self.vehicle()
        self.ref = Reference.hold(v.pos, v.euler)
        if self.pos_sp is not None:
            self.ref.apply_position(self.pos_sp)
        if self.att_sp is not None:
            self.ref.apply_attitude(self.att_sp)
        self.set_mode("OFFBOARD")

    def thrust_fraction(self) -> float:
        """The commanded force's share of the airframe's total thrust (the battery's load)."""
        af = self.airframe
        f_max = af.n_rotors * af.k_t * af.omega_max ** 2
        return float(np.linalg.norm(self._state["ctrl"]["f_b_c"])) / f_max if f_max > 0 else 0.0

    # -- output ----------------------------------------------------------------------

    def snapshot(self) -> Snapshot:
        """Everything the telemetry of this chunk is built from (made once per chunk)."""
        if self._snapshot is None:
            af = self.airframe
            n = af.n_rotors
            wall = max(self.stats.wall_time, 1e-9)
            self._snapshot = Snapshot(
                time=self.session.time, plant=self._state["plant"], ctrl=self._state["ctrl"],
                reference=self.ref.as_inputs(), mode_custom=px4.custom_mode(self.mode),
                armed=self.armed, n_rotors=n, omega_max=af.omega_max,
                tilt_limits=np.abs(np.column_stack([af.alpha_limits[:, 1],
                                                    af.beta_limits[:, 1]])),
                thrust_max=n * af.k_t * af.omega_max ** 2, load=self.busy / wall,
                origin=self.origin, battery=self.battery, unix_us=int(time.time() * 1e6),
                home=self.home, landed_state=self.landed_state_now(),
                mission_seq=self.mission_current,
                mission_total=len(self.plans[items.MISSION]),
                mission_active=self.mode == "MISSION",
                mission_complete=self.mission_complete)
        return self._snapshot

    def fresh_snapshot(self) -> Snapshot:
        """A snapshot made now (after a change of mode or arming within the chunk)."""
        self._snapshot = None
        return self.snapshot()

    def landed_state_now(self) -> int:
        """EXTENDED_SYS_STATE's landed state now (ON_GROUND, TAKEOFF, IN_AIR, LANDING)."""
        if self.landed:
            return int(mav.MAV_LANDED_STATE_ON_GROUND)
        phase = self.auto.phase if self.auto is not None else ""
        return int({"takeoff": mav.MAV_LANDED_STATE_TAKEOFF,
                    "landing": mav.MAV_LANDED_STATE_LANDING}.get(
                        phase, mav.MAV_LANDED_STATE_IN_AIR))

    def send_all(self, message: Any) -> None:
        """One message to every endpoint."""
        for ep in self.endpoints:
            ep.send(message)

    def heartbeat_now(self) -> None:
        """A HEARTBEAT to every endpoint now (a change of mode or arming)."""
        hb = telemetry.heartbeat(self.fresh_snapshot())
        for ep in self.endpoints:
            ep.send(hb)

    def statustext(self, severity: int, text: str, limited: bool = False) -> None:
        """Tell every ground station; ``limited`` texts are rate-limited (bad input)."""
        if limited:
            sec = int(time.monotonic())
            window, count = self._text_budget
            if sec != window:
                window, count = sec, 0
                if self._text_dropped:
                    dropped, self._text_dropped = self._text_dropped, 0
                    self._send_text(mav.MAV_SEVERITY_WARNING,
                                    f"{dropped} more rejections not shown")
            if count >= STATUSTEXT_PER_S:
                self._text_dropped += 1
                self._text_budget = (window, count)
                return
            self._text_budget = (window, count + 1)
        self._send_text(severity, text)

    def _send_text(self, severity: int, text: str) -> None:
        """One STATUSTEXT, or for a text longer than a message the chunks MAVLink 2 defines:
        one id (1..65535) for all, chunk_seq from 0, the end marked by a NUL (an empty last
        chunk when the text fills its chunks exactly)."""
        self.events.append(text)
        if len(self.events) > EVENTS_KEPT:
            del self.events[:EVENTS_KEPT // 2]
        data = text.encode("ascii", "replace")
        if len(data) <= STATUSTEXT_CHUNK:
            messages = [mav.MAVLink_statustext_message(severity, data)]
        else:
            self._text_id = self._text_id % 65535 + 1
            pieces = [data[i:i + STATUSTEXT_CHUNK]
                      for i in range(0, len(data), STATUSTEXT_CHUNK)]
            if len(pieces[-1]) == STATUSTEXT_CHUNK:
                pieces.append(b"")
            messages = [mav.MAVLink_statustext_message(severity, piece, self._text_id, seq)
                        for seq, piece in enumerate(pieces)]
        for m in messages:
            for ep in self.endpoints:
                ep.send(m)

    def ack(self, ep: Endpoint, command: int, result: int, src: Source) -> None:
        """COMMAND_ACK of command with result to its sender."""
        ep.send(mav.MAVLink_command_ack_message(command, result, 0, 0, src[0], src[1]))

    @staticmethod
    def reply(ep: Endpoint, messages: list[Any]) -> None:
        """Send messages, in order, to one endpoint."""
        for m in messages:
            ep.send(m)

    # -- plans ---------------------------------------------------------------------

    def install_plan(self, kind: int, plan: list[MissionItem]) -> str | None:
        """A plan uploaded whole (mission, fence or rally): checked, then held in place of the
        one before; returns why it was refused (None: installed).  A new mission starts at its
        first item."""
        why = items.check_plan(plan)
        if why is not None:
            return why
        self.plans[kind] = [it.with_seq(i) for i, it in enumerate(plan)]
        if kind == items.MISSION:
            self.mission_current = 0
            self.mission_complete = False
            if self.mode == "MISSION":  # the plan flown is gone: hold, as told
                self.hold()
                self.set_mode("HOLD")
                self.statustext(mav.MAV_SEVERITY_WARNING, "mission replaced: holding")
        if kind == items.FENCE:
            self.fence = Fence.from_items(self.plans[kind], self.origin, self.home_alt)
            self.breached = False
        return None

    def set_current_item(self, seq: int) -> str | None:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: the mission goes on from item seq;
        returns why not (None: done)."""
        n = len(self.plans[items.MISSION])
        if not 0 <= seq < n:
            return f"no mission item {seq} (the mission has {n})"
        self.mission_current = seq
        self.mission_complete = False
        if self.mode == "MISSION" and self.auto is not None:  # go on from there at once
            self.auto = Executor(self.plans[items.MISSION], self.auto.settings,
                                 self.ref.pos.copy(), self.ref.euler.copy(),
                                 home=self.home.copy(), home_alt=self.home_alt,
                                 geo=self.origin, start=seq)
        return None

    def close(self) -> None:
        """Close the endpoints and the co-simulation."""
        for ep in self.endpoints:
            ep.close()
        self.session.close()
