"""Bounded work per sender: token buckets for the requests that make the bridge send or
compute much (parameter lists, parameter reads and sets, mission and file transfers,
commands), per sender (the UDP address a datagram came from) and for all senders together,
so that no stranger flooding requests can push the loop behind real time
(docs/mavlink.md, "Bounded work per sender").  A request beyond its budget is dropped and
counted; a MAVLink client retries after its own timeout, as over a lossy link."""

from __future__ import annotations

from dataclasses import dataclass

#: message name -> the request class it counts against
REQUEST_CLASS = {
    "PARAM_REQUEST_LIST": "param_list",
    "PARAM_REQUEST_READ": "param",
    "PARAM_SET": "param",
    "MISSION_REQUEST_LIST": "transfer",
    "MISSION_REQUEST_INT": "transfer",
    "MISSION_REQUEST": "transfer",
    "MISSION_COUNT": "transfer",
    "MISSION_CLEAR_ALL": "transfer",
    "FILE_TRANSFER_PROTOCOL": "transfer",
    "COMMAND_LONG": "command",
    "COMMAND_INT": "command",
    "SET_MODE": "command",
    "SETUP_SIGNING": "command",
    "PING": "command",
}


@dataclass(frozen=True)
class Rate:
    """A token bucket's refill rate (requests per wall second) and depth (a burst)."""

    per_second: float
    burst: float


#: class -> (rate per sender, rate for all senders together).  A parameter list sends every
#: parameter (a few hundred PARAM_VALUE): one per sender every 2 s, 2 per second in all.
RATES: dict[str, tuple[Rate, Rate]] = {
    "param_list": (Rate(0.5, 2.0), Rate(2.0, 4.0)),
    "param": (Rate(100.0, 200.0), Rate(400.0, 800.0)),
    "transfer": (Rate(50.0, 100.0), Rate(200.0, 400.0)),
    "command": (Rate(50.0, 100.0), Rate(200.0, 400.0)),
}
MAX_SENDERS = 1024  # buckets kept per class; the least recently used beyond are forgotten


class _Bucket:
    __slots__ = ("stamp", "tokens")

    def __init__(self, burst: float, now: float) -> None:
        self.tokens = burst
        self.stamp = now

    def take(self, rate: Rate, now: float) -> bool:
        self.tokens = min(rate.burst, self.tokens + (now - self.stamp) * rate.per_second)
        self.stamp = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


class RequestBudget:
    """The buckets of every request class, per sender and in all."""

    def __init__(self, rates: dict[str, tuple[Rate, Rate]] | None = None) -> None:
        self.rates = RATES if rates is None else rates
        self._senders: dict[str, dict[object, _Bucket]] = {k: {} for k in self.rates}
        self._all: dict[str, _Bucket] = {}
        self.dropped: dict[str, int] = {}

    def allow(self, kind: str, sender: object, now: float) -> bool:
        """Whether a message named kind from sender may be handled now (wall time ``now``,
        s); messages of no request class always may."""
        cls = REQUEST_CLASS.get(kind)
        if cls is None:
            return True
        own_rate, all_rate = self.rates[cls]
        buckets = self._senders[cls]
        own = buckets.pop(sender, None) or _Bucket(own_rate.burst, now)
        buckets[sender] = own  # most recently used last
        if len(buckets) > MAX_SENDERS:
            del buckets[next(iter(buckets))]
        every = self._all.get(cls) or self._all.setdefault(cls, _Bucket(all_rate.burst, now))
        if own.take(own_rate, now) and every.take(all_rate, now):
            return True
        self.dropped[cls] = self.dropped.get(cls, 0) + 1
        return False
