"""Structured scalar signals of time with analytic derivatives (scenario references and
disturbances).

Every signal evaluates on float64 arrays of times and returns arrays of the same shape:

- ``value(t)``              the signal
- ``derivative(t, order)``  its first (``order=1``) or second (``order=2``) time derivative,
  computed in closed form (never by finite differences), so the controller's velocity,
  acceleration and Euler-rate feed-forward inputs are exact.

Signal types (TOML spelling in brackets; every number must be finite):

``Constant`` (``3.0`` or ``{ type = "constant", value = 3.0 }``)
    value.  Derivatives 0.
``Sine`` (``type = "sine"``)
    ``offset + amplitude * sin(omega * t + phase)``; ``amplitude``, ``omega`` (angular
    frequency, **rad/s**; required), ``phase`` (rad, default 0), ``offset`` (default 0).
``Chirp`` (``type = "chirp"``)
    ``offset + amplitude * sin(theta(t))`` with ``theta(t) = phase + integral_0^t omega(s) ds``;
    the angular frequency ``omega(s)`` is ``omega0`` before ``t0``, ramps linearly to
    ``omega1`` at ``t1`` and stays there (rad/s).  Keys ``amplitude``, ``omega0``,
    ``omega1``, ``t1`` (required), ``t0`` (default 0, must be >= 0, < t1), ``phase``,
    ``offset``.  The second derivative includes the term ``amplitude cos(theta) domega/dt``
    (so it jumps at ``t0`` and ``t1``).
``Steps`` (``type = "steps"``)
    Piecewise constant: ``initial`` (default 0) before ``times[0]``, then ``values[i]`` from
    ``times[i]`` (inclusive) to ``times[i+1]``.  ``times`` strictly increasing, as many
    ``values`` as ``times``.  Derivatives are 0: the impulses of the jumps are *not* fed
    forward (use ``waypoints`` for a smooth transition the controller can anticipate).
``Ramp`` (``type = "ramp"``)
    ``from`` until ``t0``, linear to ``to`` at ``t1`` (``t1 > t0``), ``to`` afterwards.
    First derivative is the slope on ``[t0, t1)`` and 0 elsewhere; the second derivative is 0
    (the corner impulses are not fed forward).
``Waypoints`` (``type = "waypoints"``)
    Smooth waypoints: ``times`` (strictly increasing) and ``values`` (as many); between
    consecutive waypoints a quintic minimum-jerk segment
    ``v_i + (v_{i+1} - v_i) (10 s^3 - 15 s^4 + 6 s^5)``, ``s = (t - t_i) / (t_{i+1} - t_i)``,
    with zero velocity and acceleration at every waypoint: the value is C2, so the
    acceleration feed-forward is continuous.  Constant before the first and after the last.
``Sum`` (an array ``[a, b, ...]`` of any of the above, or ``{ type = "sum", terms = [...] }``)
    The sum of its terms.

``Scaled`` (a factor times a signal) is not written in files; the scenario loader uses it for
unit conversions (degrees to radians).  :func:`value_range` gives a signal's range over all
t >= 0 in closed form (the scenario's plausibility checks look beyond the run's end).

:func:`parse_signal` turns a TOML value into a signal; errors are :class:`ScenarioError` naming
the file, the full dotted field (``reference.attitude_deg.roll.amplitude``) and what is expected.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike

from orchestrator.scenario.reader import FieldReader, ScenarioError, is_number

SIGNAL_TYPES = ("constant", "sine", "chirp", "steps", "ramp", "waypoints", "sum")


def _times(t: ArrayLike) -> np.ndarray:
    return np.asarray(t, dtype=np.float64)


# ---------------------------------------------------------------------------
# Signal types


class Signal(ABC):
    """A scalar function of time with analytic first and second derivatives."""

    def value(self, t: ArrayLike) -> np.ndarray:
        """The signal at times ``t`` (same shape as ``t``)."""
        return self._eval(_times(t), 0)

    def derivative(self, t: ArrayLike, order: int = 1) -> np.ndarray:
        """The ``order``-th time derivative (1 or 2) at times ``t``, in closed form."""
        if order not in (1, 2):
            raise ValueError(f"derivative order must be 1 or 2, got {order!r}")
        return self._eval(_times(t), order)

    @abstractmethod
    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        """Derivative of the given order (0 = value) at float64 times ``t``."""

    def __add__(self, other: Signal) -> Sum:
        return Sum((self, other))

    def scaled(self, factor: float) -> Signal:
        """The signal times factor."""
        return Scaled(float(factor), self)


@dataclass(frozen=True)
class Constant(Signal):
    """A constant level."""
    level: float

    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        return np.full(t.shape, self.level if order == 0 else 0.0)


@dataclass(frozen=True)
class Sine(Signal):
    """``offset + amplitude sin(omega t + phase)``, omega in rad/s."""

    amplitude: float
    omega: float
    phase: float = 0.0
    offset: float = 0.0

    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        arg = self.omega * t + self.phase
        if order == 0:
            return self.offset + self.amplitude * np.sin(arg)
        if order == 1:
            return self.amplitude * self.omega * np.cos(arg)
        return -self.amplitude * (self.omega * self.omega) * np.sin(arg)  # (no OverflowError)


@dataclass(frozen=True)
class Chirp(Signal):
    """Sine whose angular frequency ramps linearly from omega0 (at t0) to omega1 (at t1)."""

    amplitude: float
    omega0: float
    omega1: float
    t1: float
    t0: float = 0.0
    phase: float = 0.0
    offset: float = 0.0

    def __post_init__(self) -> None:
        if not (0.0 <= self.t0 < self.t1):
            raise ValueError(f"chirp needs 0 <= t0 < t1, got t0={self.t0}, t1={self.t1}")

    @property
    def sweep_rate(self) -> float:
        """d omega / dt on [t0, t1], rad/s^2."""
        return (self.omega1 - self.omega0) / (self.t1 - self.t0)

    def phase_angle(self, t: ArrayLike) -> np.ndarray:
        """theta(t) = phase + integral_0^t omega(s) ds."""
        t = _times(t)
        u = np.clip(t, self.t0, self.t1) - self.t0
        sweep = 0.5 * u**2 + (self.t1 - self.t0) * np.maximum(t - self.t1, 0.0)
        return self.phase + self.omega0 * t + self.sweep_rate * sweep

    def angular_frequency(self, t: ArrayLike) -> np.ndarray:
        """omega(t) = d theta / dt."""
        t = _times(t)
        return self.omega0 + self.sweep_rate * (np.clip(t, self.t0, self.t1) - self.t0)

    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        theta = self.phase_angle(t)
        if order == 0:
            return self.offset + self.amplitude * np.sin(theta)
        w = self.angular_frequency(t)
        if order == 1:
            return self.amplitude * w * np.cos(theta)
        dw = np.where((t >= self.t0) & (t < self.t1), self.sweep_rate, 0.0)
        return self.amplitude * (np.cos(theta) * dw - np.sin(theta) * w**2)


@dataclass(frozen=True)
class Steps(Signal):
    """Piecewise constant, right-continuous: ``values[i]`` on ``[times[i], times[i+1])``."""

    times: tuple[float, ...]
    values: tuple[float, ...]
    initial: float = 0.0

    def __post_init__(self) -> None:
        if len(self.times) != len(self.values) or not self.times:
            raise ValueError("steps need as many values as times, at least one")
        if any(b <= a for a, b in pairwise(self.times)):
            raise ValueError("step times must be strictly increasing")

    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        if order:
            return np.zeros(t.shape)
        levels = np.array((self.initial, *self.values))
        return levels[np.searchsorted(np.array(self.times), t, side="right")]


@dataclass(frozen=True)
class Ramp(Signal):
    """``start`` until t0, linear to ``end`` at t1, ``end`` afterwards."""

    start: float
    end: float
    t0: float
    t1: float

    def __post_init__(self) -> None:
        if not self.t1 > self.t0:
            raise ValueError(f"ramp needs t1 > t0, got t0={self.t0}, t1={self.t1}")

    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        span = self.t1 - self.t0
        if order == 0:
            u = np.clip((t - self.t0) / span, 0.0, 1.0)
            return self.start + (self.end - self.start) * u
        if order == 1:
            inside = (t >= self.t0) & (t < self.t1)
            return np.where(inside, (self.end - self.start) / span, 0.0)
        return np.zeros(t.shape)


@dataclass(frozen=True)
class Waypoints(Signal):
    """Quintic minimum-jerk segments through waypoints, at rest at each of them (C2)."""

    times: tuple[float, ...]
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.times) != len(self.values) or not self.times:
            raise ValueError("waypoints need as many values as times, at least one")
        if any(b <= a for a, b in pairwise(self.times)):
            raise ValueError("waypoint times must be strictly increasing")

    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        times = np.array(self.times)
        values = np.array(self.values)
        n = len(times)
        if n == 1:
            return np.full(t.shape, values[0] if order == 0 else 0.0)
        seg = np.clip(np.searchsorted(times, t, side="right") - 1, 0, n - 2)
        t_a, span = times[seg], times[seg + 1] - times[seg]
        delta = values[seg + 1] - values[seg]
        s = np.clip((t - t_a) / span, 0.0, 1.0)
        inside = (t >= times[0]) & (t < times[-1])
        if order == 0:
            return values[seg] + delta * s**3 * (10.0 - 15.0 * s + 6.0 * s**2)
        if order == 1:
            ds = 30.0 * s**2 * (1.0 - s) ** 2
            return np.where(inside, delta * ds / span, 0.0)
        dds = 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s)
        return np.where(inside, delta * dds / span**2, 0.0)


@dataclass(frozen=True)
class Sum(Signal):
    """The sum of ``terms``.  ``spelling`` records how a file wrote them, to name a term's
    field: ``""`` for an array (``x[2]``), ``".terms"`` for a sum table (``x.terms[2]``)."""

    terms: tuple[Signal, ...]
    spelling: str = dataclass_field(default="", compare=False)

    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        out = np.zeros(t.shape)
        for term in self.terms:
            out = out + term._eval(t, order)
        return out


@dataclass(frozen=True)
class Scaled(Signal):
    """``factor * signal`` (unit conversions)."""

    factor: float
    signal: Signal

    def _eval(self, t: np.ndarray, order: int) -> np.ndarray:
        return self.factor * self.signal._eval(t, order)


ZERO = Constant(0.0)


def value_range(signal: Signal) -> tuple[float, float] | None:
    """``(min, max)`` (bounds, inf/sup) of the signal's values over all t >= 0 in closed form,
    or None when there is none -- a sum of more than one time-varying term (sines of
    different frequencies, ramps that cancel: sample it instead) or a chirp that stops
    oscillating (``omega1 = 0``).

    A sine (``omega != 0``) or a chirp (``omega1 != 0``) sweeps ``offset +- |amplitude|``;
    steps, ramps and waypoints are monotone between their corners, so their range is that of
    the value at t = 0 and the corner values after it.
    """
    if isinstance(signal, Constant):
        return signal.level, signal.level
    if isinstance(signal, (Sine, Chirp)):
        if (signal.omega if isinstance(signal, Sine) else signal.omega1) != 0.0:
            a = abs(signal.amplitude)
            return signal.offset - a, signal.offset + a
        if isinstance(signal, Chirp) and signal.omega0 != 0.0:
            return None
        return _span(signal, [])
    if isinstance(signal, (Steps, Waypoints)):
        later = zip(signal.times, signal.values, strict=True)
        return _span(signal, [v for t, v in later if t > 0.0])
    if isinstance(signal, Ramp):
        return _span(signal, [signal.end])
    if isinstance(signal, Scaled):
        inner = value_range(signal.signal)
        if inner is None:
            return None
        ends = sorted((signal.factor * inner[0], signal.factor * inner[1]))
        return ends[0], ends[1]
    if isinstance(signal, Sum):
        ranges = [value_range(term) for term in signal.terms]
        if any(r is None for r in ranges):
            return None
        known = [r for r in ranges if r is not None]
        if sum(r[0] != r[1] for r in known) > 1:
            return None
        return sum(r[0] for r in known), sum(r[1] for r in known)
    return None


def _span(signal: Signal, corners: list[float]) -> tuple[float, float]:
    values = [float(signal.value(np.zeros(1))[0]), *corners]
    return min(values), max(values)


# ---------------------------------------------------------------------------
def _frequency_hint(key: str) -> str:
    if key in ("frequency", "freq", "omega_hz", "frequency_hz", "w"):
        return " (angular frequencies are given as 'omega', 'omega0', 'omega1', in rad/s)"
    return ""


_SIGNAL_KEYS: dict[str, tuple[str, ...]] = {
    "constant": ("value",),
    "sine": ("amplitude", "omega", "phase", "offset"),
    "chirp": ("amplitude", "omega0", "omega1", "t0", "t1", "phase", "offset"),
    "steps": ("times", "values", "initial"),
    "ramp": ("from", "to", "t0", "t1"),
    "waypoints": ("times", "values"),
    "sum": ("terms",),
}

_SIGNAL_HELP = (f"a number, a table with type = one of {', '.join(SIGNAL_TYPES)}, "
                "or an array of those (their sum)")


def parse_signal(raw: object, source: str, field: str) -> Signal:
    """A TOML value as a signal: number -> constant, table -> typed, array -> sum."""
    if is_number(raw):
        x = float(raw)  # type: ignore[arg-type]
        if not math.isfinite(x):
            raise ScenarioError(source, field, f"expected a finite number, got {raw!r}")
        return Constant(x)
    if isinstance(raw, list):
        if not raw:
            raise ScenarioError(source, field, f"empty array: expected {_SIGNAL_HELP}")
        return Sum(tuple(parse_signal(item, source, f"{field}[{k + 1}]")
                         for k, item in enumerate(raw)))
    if not isinstance(raw, dict):
        raise ScenarioError(source, field, f"expected {_SIGNAL_HELP}, got {raw!r}")
    r = FieldReader(source, raw, f"{field}.")
    if "type" not in raw:
        raise ScenarioError(source, f"{field}.type", "missing: a signal table needs "
                            f"type = one of {', '.join(SIGNAL_TYPES)}")
    kind = r.string("type", choices=SIGNAL_TYPES)
    r.used.update(_SIGNAL_KEYS[kind])  # unknown keys first: a typo is not "missing omega"
    r.reject_unknown(lambda k: _frequency_hint(k) or
                     f" (a {kind} signal takes {', '.join(_SIGNAL_KEYS[kind])})")
    signal: Signal
    if kind == "constant":
        signal = Constant(r.number("value"))
    elif kind == "sine":
        signal = Sine(amplitude=r.number("amplitude"), omega=r.number("omega"),
                      phase=r.number("phase", 0.0), offset=r.number("offset", 0.0))
    elif kind == "chirp":
        t0 = r.number("t0", 0.0, nonnegative=True)
        t1 = r.number("t1")
        if not t1 > t0:
            raise r.fail("t1", f"expected a time after t0 = {t0:g}, got {t1:g}")
        signal = Chirp(amplitude=r.number("amplitude"), omega0=r.number("omega0"),
                       omega1=r.number("omega1"), t0=t0, t1=t1,
                       phase=r.number("phase", 0.0), offset=r.number("offset", 0.0))
    elif kind in ("steps", "waypoints"):
        times = r.numbers("times", increasing=True)
        values = r.numbers("values")
        if len(values) != len(times):
            raise r.fail("values", f"expected {len(times)} values (one per time), "
                         f"got {len(values)}")
        if kind == "steps":
            signal = Steps(times, values, r.number("initial", 0.0))
        else:
            signal = Waypoints(times, values)
    elif kind == "ramp":
        t0, t1 = r.number("t0"), r.number("t1")
        if not t1 > t0:
            raise r.fail("t1", f"expected a time after t0 = {t0:g}, got {t1:g}")
        signal = Ramp(start=r.number("from"), end=r.number("to"), t0=t0, t1=t1)
    else:  # sum
        terms = r.raw("terms")
        if not isinstance(terms, list) or not terms:
            raise r.fail("terms", f"expected a non-empty array of signals ({_SIGNAL_HELP})")
        inner = parse_signal(terms, source, f"{field}.terms")
        assert isinstance(inner, Sum)
        signal = Sum(inner.terms, spelling=".terms")
    return signal
