"""The bridge: a LiveSession paced to wall-clock time, talking MAVLink 2 over UDP.

One thread does everything.  The closed loop advances in chunks (default 5 steps of
2 ms); while it waits for the wall clock to reach the end of the next chunk it sits in
``select()`` on the endpoints' sockets and handles datagrams as they come, checking the
clock between small batches.  A chunk is computed when it is due (its end time divided
by the speed), so the published state is never ahead of wall time; how late it is once
computed is the lag reported.  When behind, only a bounded batch of datagrams is
handled per chunk, so a flood cannot starve the simulation.  No receive thread: the
pymavlink parsers and the FMUs are not thread-safe, a chunk takes well under a
millisecond, and a single thread keeps the order of events deterministic.
"""

from __future__ import annotations

import math
import select
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from mavlink_bridge import modes, protocols, px4, stability, telemetry
from mavlink_bridge import params as mparams
from mavlink_bridge.geodesy import Origin
from mavlink_bridge.links import Endpoint, Signing
from mavlink_bridge.params import ParameterTable, Range, fmu_range
from mavlink_bridge.setpoints import (
    AttitudeSetpoint,
    Limits,
    PositionSetpoint,
    Reference,
    Rejected,
    VehicleState,
    decode_attitude,
    decode_global,
    decode_position,
)
from mavlink_bridge.telemetry import Snapshot, mav
from orchestrator.sim.live import LiveSession
from plant import Airframe

DEFAULT_URLS = ("udpout:127.0.0.1:14550", "udpout:127.0.0.1:14540")
SYSTEM_ID = 1
COMPONENT_ID = 1
RX_BATCH = 8  # datagrams handled between clock checks
RX_BUDGET_LATE = 32  # datagrams handled per chunk while behind wall time
RX_TIME_LATE = 0.0005  # wall s of input handling per chunk while behind wall time
RX_TIME_SHARE = 0.5  # ... and at most this share of a chunk period while waiting for it
INFEASIBLE_REPORT_S = 0.5  # infeasible this long (simulated s) before it is reported
FEASIBLE_CLEAR_S = 1.0  # feasible this long before the report is cleared
MU_SETTLED = 1.0  # deg: mu_c (the feasible attitude) is held once it stays this close ...
MU_WINDOW = 0.5  # ... over this window (simulated s)
MU_REPORT_LATEST = 3.0  # reported by then in any case (simulated s of infeasibility)
STATUSTEXT_PER_S = 5  # rejection/refusal messages per wall second, the rest are counted
UNSUPPORTED_TEXT_PERIOD = 10.0  # wall s between "not supported" texts to one sender
#: the params (1-based) each implemented command uses; NaN/inf there is DENIED.  Others
#: are ignored, as common.xml marks them reserved or lets NaN mean "no change".
COMMAND_PARAMS: dict[int, tuple[int, ...]] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: (1,),
    mav.MAV_CMD_DO_SET_MODE: (1, 2, 3),
    mav.MAV_CMD_REQUEST_MESSAGE: (1,),
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: (1,),
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: (1, 2),
    mav.MAV_CMD_GET_MESSAGE_INTERVAL: (1,),
    mav.MAV_CMD_GET_HOME_POSITION: (),
}
# Commands answered, after their ACK, by one message: REQUEST_MESSAGE names it in param1;
# these two are the older, dedicated requests (MAVSDK and QGroundControl still send them).
_REQUESTS = {mav.MAV_CMD_REQUEST_MESSAGE: 0,
             mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
             mav.MAV_CMD_GET_HOME_POSITION: mav.MAVLINK_MSG_ID_HOME_POSITION}


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
            f"{self.refused_unsigned} refused by signing); peak {self.max_rx_rate:.0f}/s",
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
    # endpoints (their URLs, as in ``urls``) SETUP_SIGNING is accepted from (while disarmed
    # and without ``signing_key``); empty: SETUP_SIGNING is always refused
    signing_setup_from: Sequence[str] = ()
    duration: float | None = None  # simulated s; None: until stop()
    chunk: int = 5
    limits: Limits = field(default_factory=Limits)
    origin: Origin = field(default_factory=Origin)  # WGS84 point of local NED (0, 0, 0)


class Bridge:
    """The co-simulation paced to wall-clock time behind MAVLink 2 endpoints: one thread steps the
    loop in chunks, handles what the ground stations send and streams telemetry
    (docs/mavlink.md)."""
    def __init__(self, config: BridgeConfig) -> None:
        if not config.speed > 0:
            raise ValueError("speed must be positive (math.inf: as fast as possible)")
        if not config.urls:
            raise ValueError("at least one endpoint is needed")
        self.config = config
        self.session = LiveSession(config.airframe, pos0=config.pos0, euler0=config.euler0,
                                   chunk=config.chunk,
                                   plant_parameters=config.plant_parameters,
                                   controller_parameters_=config.controller_parameters,
                                   coupling=config.coupling)
        self.endpoints: list[Endpoint] = []
        try:
            for i, url in enumerate(config.urls):
                self.endpoints.append(Endpoint(url, link_id=i, system=SYSTEM_ID,
                                               component=COMPONENT_ID))
        except Exception:
            self.close()
            raise
        for ep in self.endpoints:
            ep.intervals = {k: 1.0 / v for k, v in telemetry.DEFAULT_RATES.items()}
        self.signing = Signing()
        if config.signing_key is not None:
            self.set_signing(config.signing_key)
        af = self.session.airframe
        self.airframe = af
        self.params = ParameterTable(self._tunables(), self.session.set_controller_parameter,
                                     guard=stability.guard)
        self.limits = config.limits
        self._sync_limits()
        self.stats = PacingStats(speed=config.speed)
        self.origin = config.origin
        self.battery = telemetry.Battery()
        self.mode = "HOLD"
        self.armed = False
        self.ref = Reference.hold(np.array(config.pos0, float), np.array(config.euler0, float))
        self.pos_sp: PositionSetpoint | None = None
        self.att_sp: AttitudeSetpoint | None = None
        self.last_setpoint: float = -math.inf  # simulated time of the last accepted one
        self._frozen = False  # OFFBOARD with stale setpoints: holding the pose
        self.feasible = True  # as reported (with hysteresis)
        self._feasible_since = 0.0  # simulated time the FMU's flag last changed
        self._feasible_raw = True
        self._mu_c_window: deque[tuple[float, np.ndarray]] = deque()
        self._stop = False
        self._state = self.session.state()
        self._snapshot: Snapshot | None = None
        self._text_budget: tuple[int, int] = (0, 0)  # (wall second, sent in it)
        self._text_dropped = 0
        self._rx_window: tuple[float, int] = (0.0, 0)
        self._busy = 0.0
        self.events: list[str] = []  # STATUSTEXTs sent, for logs and tests
        self._told_unsupported: dict[tuple[str, int, int], float] = {}  # -> wall time
        self.on_chunk: Callable[[Bridge], None] | None = None

    @property
    def state(self) -> dict[str, dict[str, np.ndarray]]:
        """The session's latest outputs (``LiveSession.state()``), as of the last chunk."""
        return self._state

    # -- setup -----------------------------------------------------------------

    def _tunables(self) -> list[tuple[str, float, Range]]:
        """(name, value in force, range the FMU's modelDescription declares)."""
        inst = self.session.ctrl_inst
        out = []
        for name, var in inst.variables.items():
            if var.causality == "parameter" and var.variability == "tunable":
                out.append((name, float(inst.get(name)), fmu_range(var)))
        return out

    def _sync_limits(self) -> None:
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

    # -- the loop ----------------------------------------------------------------

    def stop(self) -> None:
        """Ask the loop to end after its current chunk (thread-safe)."""
        self._stop = True

    def run(self) -> PacingStats:
        """Fly until stop() or the configured duration; returns the pacing statistics."""
        cfg, s = self.config, self.session
        chunk_dt = s.step_size * s.chunk
        t0 = time.perf_counter()
        self._rx_window = (t0, 0)
        self._publish(force_heartbeat=True)
        while not self._stop:
            if cfg.duration is not None and s.time >= cfg.duration - 1e-9:
                break
            due = t0 + (s.time + chunk_dt) / cfg.speed
            if time.perf_counter() < due:
                self._receive_until(due)
                if self._stop:
                    break
            else:
                self._receive_budget(RX_BUDGET_LATE, time.perf_counter() + RX_TIME_LATE)
            busy0 = time.perf_counter()
            self._step()
            now = time.perf_counter()
            self._busy += now - busy0
            if math.isfinite(cfg.speed):
                lag = now - due
                self.stats.max_lag = max(self.stats.max_lag, lag)
                if lag > chunk_dt / cfg.speed:
                    self.stats.late_chunks += 1
            self.stats.chunks += 1
            self.stats.sim_time = s.time
            self.stats.wall_time = now - t0
            if self.on_chunk is not None:
                self.on_chunk(self)
        self.stats.wall_time = time.perf_counter() - t0
        self.stats.sim_time = s.time
        self.stats.sent = sum(ep.sent for ep in self.endpoints)
        return self.stats

    def _step(self) -> None:
        s = self.session
        if self.control_active:
            if s.time - self.last_setpoint <= self.stale:
                self.ref.integrate(self.pos_sp, self.att_sp, s.step_size * s.chunk)
            elif not self._frozen:
                self._freeze()
        s.set_reference(**self.ref.as_inputs())
        s.advance()
        self._state = s.state()
        self.battery.update(self._thrust_fraction(), s.step_size * s.chunk)
        self._snapshot = None
        self._watch()
        self._publish()

    @property
    def control_active(self) -> bool:
        """Whether offboard setpoints steer the vehicle (armed and in OFFBOARD)."""
        return self.armed and self.mode == "OFFBOARD"

    def _watch(self) -> None:
        t = self.session.time
        if self.mode == "OFFBOARD" and t - self.last_setpoint > self.timeout:
            self._hold()
            self._set_mode("HOLD")
            self.statustext(mav.MAV_SEVERITY_WARNING,
                            f"offboard lost: no setpoint for {self.timeout:g} s, holding")
        # infeasible attitude: reported once it lasted INFEASIBLE_REPORT_S, naming the
        # feasible attitude mu_c the controller holds; cleared after FEASIBLE_CLEAR_S
        # (and once mu_c has settled: within MU_SETTLED deg over the last MU_WINDOW s, else
        # at MU_REPORT_LATEST s)
        raw = bool(self._state["ctrl"]["feasible"][0] > 0.5)
        mu_c = np.degrees(self._state["ctrl"]["mu_c"][:2])
        self._mu_c_window.append((t, mu_c))
        while self._mu_c_window and self._mu_c_window[0][0] < t - MU_WINDOW - 1e-9:
            self._mu_c_window.popleft()
        if raw != self._feasible_raw:
            self._feasible_raw, self._feasible_since = raw, t
        lasted = t - self._feasible_since
        if self.feasible and not raw and lasted >= INFEASIBLE_REPORT_S - 1e-9 and (
                lasted >= MU_REPORT_LATEST or self._mu_c_settled(t)):
            self.feasible = False
            mu = np.degrees(self._state["ctrl"]["mu_c"])
            self.statustext(mav.MAV_SEVERITY_WARNING,
                            f"attitude infeasible: holding r{mu[0]:.1f} p{mu[1]:.1f} deg")
        elif not self.feasible and raw and lasted >= FEASIBLE_CLEAR_S - 1e-9:
            self.feasible = True
            self.statustext(mav.MAV_SEVERITY_INFO, "attitude reference feasible again")

    def _mu_c_settled(self, t: float) -> bool:
        w = self._mu_c_window
        if not w or w[0][0] > t - MU_WINDOW + 0.02:
            return False
        mus = np.array([m for _, m in w])
        return bool(np.max(mus.max(axis=0) - mus.min(axis=0)) < MU_SETTLED)

    # -- vehicle state -------------------------------------------------------------

    def vehicle(self) -> VehicleState:
        """The vehicle's position and attitude now (copies)."""
        p = self._state["plant"]
        return VehicleState(p["pos"].copy(), p["euler"].copy())

    def _freeze(self) -> None:
        """Setpoints stale (older than FPB_SP_STALE): hold the pose reached, never fly the
        last velocity, acceleration or rate on.  An absolute position or attitude target is
        a place, not a motion: it is kept (clients streaming slowly still get there)."""
        self._frozen = True
        v = self.vehicle()
        ref = Reference.hold(v.pos, v.euler)
        if self.pos_sp is not None:
            have = ~np.isnan(self.pos_sp.pos)
            ref.pos[have] = self.pos_sp.pos[have]
            if not math.isnan(self.pos_sp.yaw):
                ref.euler[2] = self.pos_sp.yaw
        if self.att_sp is not None and self.att_sp.euler is not None:
            ref.euler = self.att_sp.euler.copy()
        self.ref = ref

    def _hold(self) -> None:
        self._frozen = False
        v = self.vehicle()
        self.ref = Reference.hold(v.pos, v.euler)
        self.pos_sp = None
        self.att_sp = None

    def _set_mode(self, mode: str) -> None:
        if mode != self.mode:
            self.mode = mode
            self._heartbeat_now()

    def _enter_offboard(self) -> None:
        self._frozen = False
        v = self.vehicle()
        self.ref = Reference.hold(v.pos, v.euler)
        if self.pos_sp is not None:
            self.ref.apply_position(self.pos_sp)
        if self.att_sp is not None:
            self.ref.apply_attitude(self.att_sp)
        self._set_mode("OFFBOARD")

    def _thrust_fraction(self) -> float:
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
                thrust_max=n * af.k_t * af.omega_max ** 2, load=self._busy / wall,
                origin=self.origin, battery=self.battery, unix_us=int(time.time() * 1e6))
        return self._snapshot

    def _publish(self, force_heartbeat: bool = False) -> None:
        t = self.session.time
        cache: dict[int, list[Any]] = {}
        for ep in self.endpoints:
            for msg_id, interval in ep.intervals.items():
                if interval <= 0:
                    continue
                due = ep.next_due.get(msg_id, 0.0)
                if t + 1e-9 < due and not (force_heartbeat and
                                          msg_id == mav.MAVLINK_MSG_ID_HEARTBEAT):
                    continue
                ep.next_due[msg_id] = due + interval if due + interval > t else t + interval
                if msg_id not in cache:
                    cache[msg_id] = telemetry.build_all(msg_id, self.snapshot())
                for m in cache[msg_id]:
                    ep.send(m)

    def _heartbeat_now(self) -> None:
        self._snapshot = None
        hb = telemetry.heartbeat(self.snapshot())
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
        self.events.append(text)
        if len(self.events) > 1000:
            del self.events[:500]
        m = mav.MAVLink_statustext_message(severity, text[:50].encode("ascii", "replace"))
        for ep in self.endpoints:
            ep.send(m)

    # -- input -------------------------------------------------------------------------

    def _receive_until(self, due: float) -> None:
        """Handle input until ``due``; input may use at most RX_TIME_SHARE of the chunk
        period (then the rest is left in the socket buffers for later chunks)."""
        socks = {ep.sock.fileno(): ep for ep in self.endpoints}
        start = time.perf_counter()
        period = (self.session.step_size * self.session.chunk) / self.config.speed
        budget_end = start + (RX_TIME_SHARE * period if math.isfinite(period) else 0.0)
        while not self._stop:
            now = time.perf_counter()
            remaining = due - now
            if remaining <= 0:
                return
            if now >= budget_end:
                time.sleep(remaining)  # input budget used up: the socket buffers wait
                return
            try:
                ready, _, _ = select.select(list(socks), [], [], remaining)
            except (OSError, ValueError):
                time.sleep(max(0.0, remaining))
                return
            for fd in ready:
                self._drain(socks[fd], RX_BATCH, min(due, budget_end))

    def _receive_budget(self, budget: int, deadline: float) -> None:
        for ep in self.endpoints:
            self._drain(ep, budget, deadline)

    def _drain(self, ep: Endpoint, budget: int, deadline: float = math.inf) -> None:
        """Up to ``budget`` datagrams, stopping at the first datagram boundary after
        ``deadline`` (perf_counter time)."""
        last = None
        for data, msg in ep.receive(budget, deadline):
            if data is not last:
                last = data
                self._count_datagram()
            if msg is None:
                self.stats.malformed += 1
                continue
            self.stats.messages += 1
            try:
                self._handle(ep, msg)
            except Exception as e:  # a message the decoder accepted but we cannot use
                self.stats.ignored += 1
                self.statustext(mav.MAV_SEVERITY_WARNING,
                                f"{msg.get_type()[:24]} ignored: {type(e).__name__}",
                                limited=True)

    def _count_datagram(self) -> None:
        self.stats.datagrams += 1
        start, n = self._rx_window
        now = time.perf_counter()
        if now - start >= 1.0:
            self.stats.max_rx_rate = max(self.stats.max_rx_rate, n / (now - start))
            self._rx_window = (now, 1)
        else:
            self._rx_window = (start, n + 1)

    def _handle(self, ep: Endpoint, msg: Any) -> None:
        kind = msg.get_type()
        hdr = msg.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        if src == (SYSTEM_ID, COMPONENT_ID):
            self.stats.ignored += 1  # our own messages looped back
            return
        if self.signing.enabled and kind != "HEARTBEAT":
            why = self.signing.verify(msg.get_msgbuf(), hdr.incompat_flags, src)
            if why is not None:
                self.signing.count(why)
                self.stats.refused_unsigned += 1
                self.statustext(mav.MAV_SEVERITY_WARNING, f"{kind[:26]} refused: {why}",
                                limited=True)
                return
        handler = self._HANDLERS.get(kind)
        if handler is None:
            self.stats.ignored += 1
            return
        target = (getattr(msg, "target_system", 0), getattr(msg, "target_component", 0))
        if target[0] not in (0, SYSTEM_ID) or target[1] not in (0, COMPONENT_ID):
            self.stats.ignored += 1
            return
        handler(self, ep, msg, src)

    def _on_heartbeat(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        pass  # ground stations announce themselves; nothing to do

    def _on_position(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        try:
            if msg.get_type() == "SET_POSITION_TARGET_GLOBAL_INT":
                sp = decode_global(msg, self.vehicle(), self.limits, self.origin)
            else:
                sp = decode_position(msg, self.vehicle(), self.limits)
        except Rejected as e:
            self.statustext(mav.MAV_SEVERITY_WARNING, f"POSITION_TARGET rejected: {e}",
                            limited=True)
            return
        self.pos_sp = sp
        self.last_setpoint = self.session.time
        self._frozen = False
        if self.control_active:
            self.ref.apply_position(sp)

    def _on_attitude(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        try:
            sp = decode_attitude(msg, self.limits)
        except Rejected as e:
            self.statustext(mav.MAV_SEVERITY_WARNING, f"ATTITUDE_TARGET rejected: {e}",
                            limited=True)
            return
        self.att_sp = sp
        self.last_setpoint = self.session.time
        self._frozen = False
        if self.control_active:
            self.ref.apply_attitude(sp)

    # commands

    def _ack(self, ep: Endpoint, command: int, result: int, src: tuple[int, int]) -> None:
        ep.send(mav.MAVLink_command_ack_message(command, result, 0, 0, src[0], src[1]))

    def _on_command(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        cmd = int(msg.command)
        p = [float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4)]
        if msg.get_type() == "COMMAND_LONG":
            p += [float(msg.param5), float(msg.param6), float(msg.param7)]
        else:  # COMMAND_INT: x, y are integers, z a float
            p += [float(msg.x), float(msg.y), float(msg.z)]
        bad = next((i for i in COMMAND_PARAMS.get(cmd, ()) if not math.isfinite(p[i - 1])),
                   None)
        if cmd not in COMMAND_PARAMS:
            result = mav.MAV_RESULT_UNSUPPORTED
            if cmd in modes.COMMAND_REASONS:
                self.statustext(mav.MAV_SEVERITY_WARNING, modes.COMMAND_REASONS[cmd],
                                limited=True)
        elif bad is not None:
            result = mav.MAV_RESULT_DENIED
            self.statustext(mav.MAV_SEVERITY_WARNING,
                            f"command {cmd} denied: param{bad} is {p[bad - 1]}", limited=True)
        else:
            result = self._command(ep, cmd, p)
        self._ack(ep, cmd, result, src)
        if (result == mav.MAV_RESULT_ACCEPTED and cmd == mav.MAV_CMD_REQUEST_MESSAGE and
                int(p[0]) in modes.REQUESTABLE):
            index = int(p[1]) if math.isfinite(p[1]) else 0
            self._reply(ep, modes.requested(int(p[0]), index, px4.custom_mode(self.mode)))
        elif result == mav.MAV_RESULT_ACCEPTED and cmd in _REQUESTS:
            msg_id = (int(p[0]) if cmd == mav.MAV_CMD_REQUEST_MESSAGE else _REQUESTS[cmd])
            self._snapshot = None
            for m in telemetry.build_all(msg_id, self.snapshot()):
                ep.send(m)
        elif result == mav.MAV_RESULT_ACCEPTED and cmd == mav.MAV_CMD_GET_MESSAGE_INTERVAL:
            msg_id = int(p[0])
            interval = ep.intervals.get(msg_id, 0.0)
            us = int(interval * 1e6) if interval > 0 else -1
            ep.send(mav.MAVLink_message_interval_message(msg_id, us))

    def _command(self, ep: Endpoint, cmd: int, p: list[float]) -> int:
        if cmd == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] not in (0.0, 1.0):
                return mav.MAV_RESULT_DENIED
            arm = p[0] == 1.0
            if arm != self.armed:
                self.armed = arm
                if self.mode == "OFFBOARD" and arm:
                    self._enter_offboard()
                elif not arm:
                    self._hold()
                    self.mode = "HOLD"
                self._heartbeat_now()
            return mav.MAV_RESULT_ACCEPTED
        if cmd == mav.MAV_CMD_DO_SET_MODE:
            return self.request_mode(int(p[0]), int(p[1]), int(p[2]))
        if cmd == mav.MAV_CMD_REQUEST_MESSAGE:
            known = (int(p[0]) in telemetry.DEFAULT_RATES or int(p[0]) in telemetry.ON_REQUEST
                     or int(p[0]) in modes.REQUESTABLE)
            if int(p[0]) == modes.MSG_AVAILABLE_MODES and math.isfinite(p[1]):
                known = 0 <= p[1] <= modes.AVAILABLE_COUNT  # param2: mode index, 0 = all
            return mav.MAV_RESULT_ACCEPTED if known else mav.MAV_RESULT_DENIED
        if cmd in (mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, mav.MAV_CMD_GET_HOME_POSITION):
            return mav.MAV_RESULT_ACCEPTED
        if cmd in (mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAV_CMD_GET_MESSAGE_INTERVAL):
            msg_id = int(p[0])
            if msg_id not in telemetry.DEFAULT_RATES:
                return mav.MAV_RESULT_DENIED
            if cmd == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
                us = p[1]
                if not math.isfinite(us):
                    return mav.MAV_RESULT_DENIED
                interval = (1.0 / telemetry.DEFAULT_RATES[msg_id] if us == 0 else
                            -1.0 if us < 0 else max(us * 1e-6, 0.001))
                ep.intervals[msg_id] = interval
                ep.next_due[msg_id] = self.session.time
            return mav.MAV_RESULT_ACCEPTED
        return mav.MAV_RESULT_UNSUPPORTED

    def request_mode(self, base_mode: int, main: int, sub: int) -> int:
        """The one road for SET_MODE and DO_SET_MODE (PX4 turns the message into the
        command): the MAV_RESULT; a refusal is told by STATUSTEXT, an acceptance by an
        immediate HEARTBEAT."""
        r = modes.resolve(base_mode, main, sub)
        before = self.mode
        if r.mode is None:
            self.statustext(mav.MAV_SEVERITY_WARNING, f"{r.name} refused: {r.reason}",
                            limited=True)
            return mav.MAV_RESULT_DENIED
        if r.mode == "OFFBOARD":
            if self.session.time - self.last_setpoint > self.timeout:
                self.statustext(mav.MAV_SEVERITY_WARNING,
                                "offboard refused: no recent setpoint")
                return mav.MAV_RESULT_TEMPORARILY_REJECTED
            if self.mode != "OFFBOARD":
                self._enter_offboard()
        elif self.mode != r.mode:
            self._hold()
            self._set_mode(r.mode)
        if self.mode == before:
            self._heartbeat_now()  # a change sent one already; the requester hears either way
        return mav.MAV_RESULT_ACCEPTED

    def _on_set_mode(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        main, sub = modes.from_custom_mode(int(msg.custom_mode))
        result = self.request_mode(int(msg.base_mode), main, sub)
        self._ack(ep, mav.MAV_CMD_DO_SET_MODE, result, src)  # as PX4's commander does

    # small protocols: FTP, PING, mission/fence/rally (mavlink_bridge.protocols)

    def _reply(self, ep: Endpoint, messages: list[Any]) -> None:
        for m in messages:
            ep.send(m)

    def _on_ftp(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        self._reply(ep, protocols.ftp_reply(msg, src))

    def _on_ping(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        self._reply(ep, protocols.ping_reply(msg, src))

    def _on_mission_request_list(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        self._reply(ep, protocols.mission_request_list(msg, src))

    def _on_mission_request(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        self._reply(ep, protocols.mission_request_item(msg, src))

    def _on_mission_count(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        replies, why = protocols.mission_count(msg, src)
        if why is not None:
            self.statustext(mav.MAV_SEVERITY_WARNING, why, limited=True)
        self._reply(ep, replies)

    def _on_mission_clear(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        self._reply(ep, protocols.mission_clear_all(msg, src))

    def _on_mission_ack(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        pass  # the end of a download of an empty plan: nothing to do

    def _on_unsupported(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        """Say once per sender and UNSUPPORTED_TEXT_PERIOD that a message is not flown."""
        key = (msg.get_type(), src[0], src[1])
        now = time.monotonic()
        if now - self._told_unsupported.get(key, -math.inf) < UNSUPPORTED_TEXT_PERIOD:
            return
        self._told_unsupported[key] = now
        self.statustext(mav.MAV_SEVERITY_WARNING, f"{key[0][:32]} not supported", limited=True)

    # parameters

    def _param_value(self, index: int) -> Any:
        p = self.params.items[index]
        value, kind = mparams.encode(p.value, p.integer)  # INT32 byte-wise, as PX4
        return mav.MAVLink_param_value_message(p.name.encode("ascii"), value, kind,
                                               len(self.params), index)

    def _on_param_list(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        for i in range(len(self.params)):
            ep.send(self._param_value(i))

    def _on_param_read(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        index = int(msg.param_index)
        if index < 0:
            found = self.params.index(_param_id(msg.param_id))
            if found is None:
                self._unknown_param(ep, msg, src, _param_id(msg.param_id), index)
                return
            index = found
        if 0 <= index < len(self.params):
            ep.send(self._param_value(index))
        else:
            self._unknown_param(ep, msg, src, "", index)

    def _unknown_param(self, ep: Endpoint, msg: Any, src: tuple[int, int], name: str,
                       index: int) -> None:
        """As PX4: a STATUSTEXT naming it (and no PARAM_VALUE); plus PARAM_ERROR, which
        newer MAVLink defines for this."""
        self.statustext(mav.MAV_SEVERITY_INFO, f"unknown param: {name or index}"[:50],
                        limited=True)
        raw = _param_id(msg.param_id).encode("ascii", "replace")[:16]
        ep.send(mav.MAVLink_param_error_message(src[0], src[1], raw, index,
                                                mav.MAV_PARAM_ERROR_DOES_NOT_EXIST))

    def _on_param_set(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        name = _param_id(msg.param_id)
        index = self.params.index(name)
        if index is None:
            self.statustext(mav.MAV_SEVERITY_WARNING, f"unknown parameter {name[:30]}",
                            limited=True)
            return
        kind = int(msg.param_type)
        value = mparams.decode(float(msg.param_value), kind)
        if value is None:
            reason: str | None = f"{name} refused: param_type {kind} unsupported"
        else:
            reason = self.params.set(name, value, kind)
        if reason is not None:
            self.statustext(mav.MAV_SEVERITY_WARNING, reason, limited=True)
        elif name.startswith("FPB_"):
            self._sync_limits()
        m = self._param_value(index)  # the value in force, accepted or not
        for e in self.endpoints:
            e.send(m)

    # time sync and signing

    def _on_timesync(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        if int(msg.tc1) == 0:
            now_ns = int(self.session.time * 1e9)
            ep.send(mav.MAVLink_timesync_message(now_ns, int(msg.ts1)))

    def _on_setup_signing(self, ep: Endpoint, msg: Any, src: tuple[int, int]) -> None:
        """Policy (docs/mavlink.md, "Signing policy"): refused while armed, refused when the
        key was given with --signing-key, accepted only from a --signing-setup-from link."""
        why = None
        if self.armed:
            why = "armed"
        elif self.config.signing_key is not None:
            why = "key set by --signing-key"
        elif ep.url not in self.config.signing_setup_from:
            why = "not --signing-setup-from"
        if why is not None:
            self.statustext(mav.MAV_SEVERITY_WARNING, f"SETUP_SIGNING refused: {why}",
                            limited=True)
            return
        key = bytes(int(b) & 0xFF for b in msg.secret_key)
        if len(key) != 32:
            return
        if not any(key) and int(msg.initial_timestamp) == 0:
            self.set_signing(None)
            self.statustext(mav.MAV_SEVERITY_NOTICE, "signing disabled")
            return
        self.set_signing(key, int(msg.initial_timestamp))
        self.statustext(mav.MAV_SEVERITY_NOTICE, "signing enabled with a new key")

    _HANDLERS: ClassVar[dict[str, Callable[[Bridge, Endpoint, Any, tuple[int, int]], None]]] = {
        "HEARTBEAT": _on_heartbeat,
        "SET_POSITION_TARGET_LOCAL_NED": _on_position,
        "SET_POSITION_TARGET_GLOBAL_INT": _on_position,
        "SET_ATTITUDE_TARGET": _on_attitude,
        "COMMAND_LONG": _on_command,
        "COMMAND_INT": _on_command,
        "PARAM_REQUEST_LIST": _on_param_list,
        "PARAM_REQUEST_READ": _on_param_read,
        "PARAM_SET": _on_param_set,
        "TIMESYNC": _on_timesync,
        "SETUP_SIGNING": _on_setup_signing,
        "SET_MODE": _on_set_mode,
        "FILE_TRANSFER_PROTOCOL": _on_ftp,
        "PING": _on_ping,
        "MISSION_REQUEST_LIST": _on_mission_request_list,
        "MISSION_REQUEST_INT": _on_mission_request,
        "MISSION_REQUEST": _on_mission_request,
        "MISSION_COUNT": _on_mission_count,
        "MISSION_CLEAR_ALL": _on_mission_clear,
        "MISSION_ACK": _on_mission_ack,
        "SET_ACTUATOR_CONTROL_TARGET": _on_unsupported,
    }

    def close(self) -> None:
        """Close the endpoints and the co-simulation."""
        for ep in self.endpoints:
            ep.close()
        self.session.close()

    def __enter__(self) -> Bridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _param_id(raw: Any) -> str:
    if isinstance(raw, bytes | bytearray):
        raw = raw.decode("ascii", errors="replace")
    return str(raw).split("\x00", 1)[0]
