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
from collections.abc import Callable
from typing import Any

import numpy as np

from mavlink_bridge import auto, telemetry
from mavlink_bridge.context import (
    COMPONENT_ID,
    DEFAULT_URLS,
    BridgeConfig,
    Context,
    PacingStats,
)
from mavlink_bridge.handlers import HANDLERS, missions, signing
from mavlink_bridge.links import Address, Endpoint
from mavlink_bridge.telemetry import mav

__all__ = ["DEFAULT_URLS", "Bridge", "BridgeConfig", "PacingStats"]

RX_BATCH = 8  # datagrams handled between clock checks
RX_BUDGET_LATE = 32  # datagrams handled per chunk while behind wall time
RX_TIME_LATE = 0.0005  # wall s of input handling per chunk while behind wall time
RX_TIME_SHARE = 0.5  # ... and at most this share of a chunk period while waiting for it
INFEASIBLE_REPORT_S = 0.5  # infeasible this long (simulated s) before it is reported
FEASIBLE_CLEAR_S = 1.0  # feasible this long before the report is cleared
MU_SETTLED = 1.0  # deg: mu_c (the feasible attitude) is held once it stays this close ...
MU_WINDOW = 0.5  # ... over this window (simulated s)
MU_REPORT_LATEST = 3.0  # reported by then in any case (simulated s of infeasibility)


class Bridge(Context):
    """The co-simulation paced to wall-clock time behind MAVLink 2 endpoints: one thread steps the
    loop in chunks, routes what the ground stations send to the handlers
    (:mod:`mavlink_bridge.handlers`) and streams telemetry (docs/mavlink.md)."""

    def __init__(self, config: BridgeConfig) -> None:
        super().__init__(config)
        self.feasible = True  # as reported (with hysteresis)
        self._feasible_since = 0.0  # simulated time the FMU's flag last changed
        self._feasible_raw = True
        self._mu_c_window: deque[tuple[float, np.ndarray]] = deque()
        self._stop = False
        self._rx_window: tuple[float, int] = (0.0, 0)
        self.on_chunk: Callable[[Bridge], None] | None = None

    # -- the loop ----------------------------------------------------------------

    def stop(self) -> None:
        """Ask the loop to end after its current chunk (thread-safe)."""
        self._stop = True

    def run(self) -> PacingStats:
        """Fly until stop() or the configured duration; returns the pacing statistics (final
        also when the loop ends by an exception, e.g. Ctrl-C: ``self.stats``)."""
        t0 = time.perf_counter()
        try:
            self._loop(t0)
        finally:
            self.stats.wall_time = time.perf_counter() - t0
            self.stats.sim_time = self.session.time
            self.stats.sent = sum(ep.sent for ep in self.endpoints)
        return self.stats

    def _loop(self, t0: float) -> None:
        cfg, s = self.config, self.session
        chunk_dt = s.step_size * s.chunk
        self._rx_window = (t0, 0)
        # one control sample at the start pose before any input is taken: the controller's
        # reference shaping takes its first sample's reference as given, so a setpoint that
        # arrived before it would be flown as a raw jump (a 10 m step at full thrust)
        s.advance(1)
        self.refresh()
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
            self.busy += now - busy0
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

    def _step(self) -> None:
        s = self.session
        if self.control_active:
            if s.time - self.last_setpoint <= self.stale:
                self.ref.integrate(self.pos_sp, self.att_sp, s.step_size * s.chunk)
            elif not self.frozen:
                self.freeze()
        elif self.armed:
            auto.step(self)
        s.set_reference(**self.ref.as_inputs())
        s.advance()
        self.refresh()
        self.battery.update(self.thrust_fraction(), s.step_size * s.chunk)
        self._watch()
        auto.watch_ground(self)
        auto.watch_fence(self)
        missions.tick(self, time.monotonic())  # an upload's item requested again when lost
        self._publish()

    @property
    def control_active(self) -> bool:
        """Whether offboard setpoints steer the vehicle (armed and in OFFBOARD)."""
        return self.armed and self.mode == "OFFBOARD"

    def _watch(self) -> None:
        t = self.session.time
        if self.mode == "OFFBOARD" and t - self.last_setpoint > self.timeout:
            self.hold()
            self.set_mode("HOLD")
            self.statustext(mav.MAV_SEVERITY_WARNING,
                            f"offboard lost: no setpoint for {self.timeout:g} s, holding")
        # infeasible attitude: reported once it lasted INFEASIBLE_REPORT_S, naming the
        # feasible attitude mu_c the controller holds; cleared after FEASIBLE_CLEAR_S
        # (and once mu_c has settled: within MU_SETTLED deg over the last MU_WINDOW s, else
        # at MU_REPORT_LATEST s)
        raw = bool(self.state["ctrl"]["feasible"][0] > 0.5)
        mu_c = np.degrees(self.state["ctrl"]["mu_c"][:2])
        self._mu_c_window.append((t, mu_c))
        while self._mu_c_window and self._mu_c_window[0][0] < t - MU_WINDOW - 1e-9:
            self._mu_c_window.popleft()
        if raw != self._feasible_raw:
            self._feasible_raw, self._feasible_since = raw, t
        lasted = t - self._feasible_since
        if self.feasible and not raw and lasted >= INFEASIBLE_REPORT_S - 1e-9 and (
                lasted >= MU_REPORT_LATEST or self._mu_c_settled(t)):
            self.feasible = False
            mu = np.degrees(self.state["ctrl"]["mu_c"])
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

    # -- output ----------------------------------------------------------------------

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
        for data, msg, addr in ep.receive(budget, deadline):
            if data is not last:
                last = data
                self._count_datagram()
            if msg is None:
                self.stats.malformed += 1
                continue
            self.stats.messages += 1
            try:
                self._handle(ep, msg, addr)
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

    def _handle(self, ep: Endpoint, msg: Any, addr: Address) -> None:
        kind = msg.get_type()
        hdr = msg.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        if src == (self.config.system_id, COMPONENT_ID):
            self.stats.ignored += 1  # our own messages looped back
            return
        self.sender = addr
        if signing.refused(self, msg, src):
            return
        if kind == "HEARTBEAT" and (self.signed or not self.signing.enabled):
            ep.admit(addr)  # a udpin endpoint sends to the senders of valid heartbeats only
        if not self.budget.allow(kind, (ep.link_id, addr), time.monotonic()):
            self.stats.throttled += 1
            self.statustext(mav.MAV_SEVERITY_WARNING,
                            f"{kind[:24]} from {addr[0]}:{addr[1]} throttled", limited=True)
            return
        handler = HANDLERS.get(kind)
        if handler is None:
            self.stats.ignored += 1
            return
        target = (getattr(msg, "target_system", 0), getattr(msg, "target_component", 0))
        if target[0] not in (0, self.config.system_id) or target[1] not in (0, COMPONENT_ID):
            self.stats.ignored += 1
            return
        handler(self, ep, msg, src)

    def __enter__(self) -> Bridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
