"""MAVLink parameters: the controller FMU's tunables and the bridge's own, typed and ranged.

Names.  MAVLink parameter ids are at most 16 characters; the controller FMU's tunable
parameters are mapped by a fixed rule (docs/mavlink.md lists them all):
``K_pos_A[i] .. K_rate_D[i]`` -> ``FP_KPOS_A1 .. FP_KRATE_D3``, ``W_u[i]`` -> ``FP_W_U1``,
``W_v[i]``, ``W_nu[i]``, ``euler_min[i]``/``euler_max[i]`` -> ``FP_EUL_MIN1``/``FP_EUL_MAX1``,
``gamma_opt`` -> ``FP_GAMMA_OPT``, ``w_pref``, ``pref_omega_scale`` -> ``FP_PREF_OM_SC``,
``qp_max_iter`` -> ``FP_QP_MAX_ITER``, ``yaw_rate_max`` -> ``FP_YAW_RATE_MAX``.  The bridge's
own parameters start with ``FPB_``.

Ranges.  A controller parameter's range is the one the FMU declares in its modelDescription
(``min``/``max``, generated from fmu_src/controller/controller_vars.h; FMI's bounds are
inclusive, so an open bound is declared at the first double inside it and written in the
variable's description as ``range (a, b)``, see fmu_src/tools/mdgen.c ``write_variable``):
read from the installed FMU, never restated here.  Two further rules
refuse values that are inside the FMU's range but absurd for a flight:

* a positive weight or scale (declared range ``(0, inf)``) must stay within ``PLAUSIBLE``
  (three decades) either side of the FMU's start value (``FP_W_U1 = 1e-30`` is refused);
* a gain change must keep the linear design model's closed loop stable (the ``guard``
  callable, :mod:`mavlink_bridge.stability`).

Types.  A parameter whose FMU variable is an Integer (or a bridge parameter marked integer) is
reported as MAV_PARAM_TYPE_INT32 with the byte-wise encoding PX4 uses (the int32's four bytes
in the float field: MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE); the others as REAL32.
A PARAM_SET is decoded by its own param_type.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from mavlink_bridge.identity import INTEGER_PARAMETERS, PX4_PARAMETERS

MAV_PARAM_TYPE_UINT8, MAV_PARAM_TYPE_INT8, MAV_PARAM_TYPE_UINT16 = 1, 2, 3
MAV_PARAM_TYPE_INT16, MAV_PARAM_TYPE_UINT32, MAV_PARAM_TYPE_INT32 = 4, 5, 6
MAV_PARAM_TYPE_REAL32 = 9
#: integer types that fit the 4-byte field byte-wise (struct format of each)
_INT_FORMATS = {MAV_PARAM_TYPE_UINT8: "<B", MAV_PARAM_TYPE_INT8: "<b",
                MAV_PARAM_TYPE_UINT16: "<H", MAV_PARAM_TYPE_INT16: "<h",
                MAV_PARAM_TYPE_UINT32: "<I", MAV_PARAM_TYPE_INT32: "<i"}

#: a positive weight may move this factor either side of its FMU start value
PLAUSIBLE = 1e3

_BLOCK = re.compile(r"^K_(pos|vel|att|rate)_([ABCD])\[(\d+)\]$")
_VECTOR = {"W_u": "FP_W_U", "W_v": "FP_W_V", "W_nu": "FP_W_NU", "euler_min": "FP_EUL_MIN",
           "euler_max": "FP_EUL_MAX"}
_SCALAR = {"gamma_opt": "FP_GAMMA_OPT", "w_pref": "FP_W_PREF",
           "pref_omega_scale": "FP_PREF_OM_SC", "qp_max_iter": "FP_QP_MAX_ITER",
           "yaw_rate_max": "FP_YAW_RATE_MAX"}


@dataclass(frozen=True)
class Range:
    """An interval, closed unless told; None: unbounded on that side."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False

    def contains(self, v: float) -> bool:
        """Whether v is finite, an integer where the range is, and within the bounds."""
        if not math.isfinite(v) or (self.integer and v != int(v)):
            return False
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            return False
        return not (self.hi is not None and (v > self.hi or (self.hi_open and v == self.hi)))

    def text(self) -> str:
        """The range as a message shows it: 0..10, [0, 1], (0, inf)."""
        if self.integer and self.lo is not None and self.hi is not None:
            return f"{self.lo:g}..{self.hi:g}"
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        return f"{'(' if self.lo_open or self.lo is None else '['}{lo}, " \
               f"{hi}{')' if self.hi_open or self.hi is None else ']'}"


def fmu_range(var: Any) -> Range:
    """The range an fmpy ScalarVariable declares: min/max, and which ends are open from the
    description mdgen writes (``...; range (0, inf)``).  An open end is declared at the first
    value inside it (min 4.9e-324 for ``(0, inf)``, FMI's bounds being inclusive): the
    range's bound is the value just beyond that, the one the FMU refuses (0)."""
    lo = None if getattr(var, "min", None) in (None, "") else float(var.min)
    hi = None if getattr(var, "max", None) in (None, "") else float(var.max)
    desc = str(getattr(var, "description", "") or "")
    lo_open = hi_open = False
    if "; range " in desc:
        text = desc.rsplit("; range ", 1)[1].strip()
        lo_open, hi_open = text.startswith("("), text.endswith(")")
    integer = getattr(var, "type", "Real") == "Integer"
    if lo is not None and lo_open:
        lo = lo - 1 if integer else math.nextafter(lo, -math.inf)
    if hi is not None and hi_open:
        hi = hi + 1 if integer else math.nextafter(hi, math.inf)
    return Range(lo, hi, lo_open, hi_open, integer=integer)


@dataclass(frozen=True)
class BridgeParam:
    """A parameter of the bridge itself (FPB_*): its name, default, range and description."""
    name: str
    default: float
    range: Range
    description: str


#: the bridge's own parameters; FPB_SP_TIMEOUT defaults to PX4's COM_OF_LOSS_T (1.0 s,
#: PX4-Autopilot src/modules/commander/commander_params.c)
BRIDGE_PARAMETERS: tuple[BridgeParam, ...] = (
    BridgeParam("FPB_SP_TIMEOUT", 1.0, Range(0.05, 60.0),
                "offboard setpoint-loss timeout (s, simulated time; PX4 COM_OF_LOSS_T)"),
    BridgeParam("FPB_SP_STALE", 0.25, Range(0.02, 60.0),
                "a setpoint older than this is not flown: hold the pose (s)"),
    BridgeParam("FPB_SP_XY_MAX", 100.0, Range(0.1, 10000.0),
                "largest accepted |x|, |y| of a setpoint (m)"),
    BridgeParam("FPB_SP_Z_MAX", 100.0, Range(0.1, 10000.0),
                "largest accepted |z| of a setpoint (m)"),
    BridgeParam("FPB_SP_VEL_MAX", 10.0, Range(0.0, 100.0),
                "largest accepted velocity component (m/s)"),
    BridgeParam("FPB_SP_ACC_MAX", 20.0, Range(0.0, 100.0),
                "largest accepted acceleration component (m/s^2)"),
    BridgeParam("FPB_SP_RATE_MAX", 6.0, Range(0.0, 50.0),
                "largest accepted body/yaw rate (rad/s)"),
    BridgeParam("FPB_SP_TILT_MAX", 1.4, Range(0.0, 1.5),
                "largest accepted |roll|, |pitch| of a setpoint (rad)"),
)


#: the PX4 parameters flight from the ground reads (mavlink_bridge.auto), PX4's names and
#: meanings so that ground stations set them as they do on PX4 (MAVSDK's
#: set_takeoff_altitude writes MIS_TAKEOFF_ALT, set_maximum_speed MPC_XY_VEL_MAX,
#: set_return_to_launch_altitude RTL_RETURN_ALT).  Defaults are PX4's where they suit a
#: vehicle of a metre flown in a room-sized space, smaller where PX4's are made for fields
#: (docs/mavlink.md lists both).
FLIGHT_PARAMETERS: tuple[BridgeParam, ...] = (
    BridgeParam("MIS_TAKEOFF_ALT", 2.5, Range(0.5, 80.0),
                "takeoff altitude above home (m; PX4 default 2.5)"),
    BridgeParam("MPC_XY_CRUISE", 1.0, Range(0.1, 20.0),
                "horizontal speed of missions, go-to and returns (m/s; PX4 5)"),
    BridgeParam("MPC_XY_VEL_MAX", 5.0, Range(0.1, 20.0),
                "largest horizontal speed a speed change may ask for (m/s; PX4 12)"),
    BridgeParam("MPC_Z_VEL_MAX_UP", 1.0, Range(0.1, 8.0), "climb speed (m/s; PX4 3)"),
    BridgeParam("MPC_Z_VEL_MAX_DN", 0.7, Range(0.1, 4.0), "descent speed (m/s; PX4 1.5)"),
    BridgeParam("MPC_LAND_SPEED", 0.5, Range(0.1, 2.0),
                "landing descent speed (m/s; PX4 0.7)"),
    BridgeParam("MPC_ACC_HOR", 2.0, Range(0.5, 15.0),
                "horizontal acceleration of auto flight (m/s^2; PX4 3)"),
    BridgeParam("MPC_ACC_UP_MAX", 1.5, Range(0.5, 15.0),
                "vertical acceleration upwards (m/s^2; PX4 4)"),
    BridgeParam("MPC_ACC_DOWN_MAX", 1.5, Range(0.5, 15.0),
                "vertical acceleration downwards (m/s^2; PX4 3)"),
    BridgeParam("NAV_ACC_RAD", 0.1, Range(0.01, 20.0),
                "acceptance radius of items giving none (m; PX4 10)"),
    BridgeParam("RTL_RETURN_ALT", 3.0, Range(0.0, 150.0),
                "altitude above home a return climbs to first (m; PX4 60)"),
    BridgeParam("COM_DISARM_LAND", 2.0, Range(-1.0, 20.0),
                "disarm this long after landing (s; <= 0: never; PX4 2)"),
    BridgeParam("COM_DISARM_PRFLT", 10.0, Range(-1.0, 20.0),
                "disarm this long after arming without a takeoff (s; <= 0: never; PX4 10)"),
    BridgeParam("GF_ACTION", 2.0, Range(0.0, 5.0, integer=True),
                "geofence breach: 0 none, 1 warning, 2 hold, 3 return, 5 land (4 refused: "
                "no flight termination here; PX4 2)"),
)


def identity_parameters() -> list[BridgeParam]:
    """The PX4 parameters ground stations require (mavlink_bridge.identity), read-only: their
    range is their value."""
    return [BridgeParam(name, value, Range(lo, hi, integer=name in INTEGER_PARAMETERS), text)
            for name, (value, lo, hi, text) in PX4_PARAMETERS.items()]


def mavlink_name(fmu_name: str) -> str | None:
    """The MAVLink id of a tunable FMU parameter (None: not mapped)."""
    m = _BLOCK.match(fmu_name)
    if m:
        return f"FP_K{m.group(1).upper()}_{m.group(2)}{m.group(3)}"
    base, _, index = fmu_name.partition("[")
    if base in _VECTOR and index.endswith("]"):
        return f"{_VECTOR[base]}{index[:-1]}"
    return _SCALAR.get(fmu_name)


def encode(value: float, integer: bool) -> tuple[float, int]:
    """(param_value, param_type) of a PARAM_VALUE: integers byte-wise as INT32."""
    if integer:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0], MAV_PARAM_TYPE_INT32
    return float(value), MAV_PARAM_TYPE_REAL32


def decode(raw: float, param_type: int) -> float | None:
    """The value a PARAM_SET carries, by its param_type (None: a type we cannot read)."""
    if param_type == MAV_PARAM_TYPE_REAL32:
        return float(raw)
    fmt = _INT_FORMATS.get(param_type)
    if fmt is None:
        return None
    data = struct.pack("<f", raw)
    size = struct.calcsize(fmt)
    return float(struct.unpack(fmt, data[:size])[0])


@dataclass
class Parameter:
    """A parameter as ground stations see it: its MAVLink id, the controller FMU variable it stands
    for (None: a bridge parameter), value, range and MAVLink type."""
    name: str  # MAVLink id
    fmu_name: str | None  # None: a bridge parameter
    value: float
    range: Range
    start: float  # the value at start-up (FMU start or bridge default)

    @property
    def integer(self) -> bool:
        """Whether it is an integer parameter (sent as INT32)."""
        return self.range.integer


MAV_PARAM_ERROR_DOES_NOT_EXIST = 1
MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE = 2
MAV_PARAM_ERROR_PERMISSION_DENIED = 3
MAV_PARAM_ERROR_TYPE_UNSUPPORTED = 6
MAV_PARAM_ERROR_TYPE_MISMATCH = 7


@dataclass(frozen=True)
class Refused:
    """Why a parameter set was refused: the text told by STATUSTEXT and the MAV_PARAM_ERROR
    code a PARAM_ERROR carries (what MAVSDK and QGroundControl turn into an error result)."""

    reason: str
    code: int

    def __str__(self) -> str:
        return self.reason


#: Guard: (proposed {FMU name: value} of every controller parameter, the FMU name changed)
#: -> the reason the change is refused, or None
Guard = Callable[[Mapping[str, float], str], str | None]


class ParameterTable:
    """The parameters a ground station sees, in a fixed order (PARAM_VALUE index)."""

    def __init__(self, tunables: Iterable[tuple[str, float, Range]],
                 apply: Callable[[str, float], None], guard: Guard | None = None) -> None:
        self._apply = apply
        self._guard = guard
        self.items: list[Parameter] = []
        for fmu_name, value, rng in tunables:
            name = mavlink_name(fmu_name)
            if name is not None and len(name) <= 16:
                self.items.append(Parameter(name, fmu_name, float(value), rng, float(value)))
        for bp in (*BRIDGE_PARAMETERS, *FLIGHT_PARAMETERS, *identity_parameters()):
            if bp.name not in {p.name for p in self.items}:
                self.items.append(Parameter(bp.name, None, bp.default, bp.range, bp.default))
        self._by_name = {p.name: i for i, p in enumerate(self.items)}

    def __len__(self) -> int:
        return len(self.items)

    def index(self, name: str) -> int | None:
        """The parameter's index in PARAM_VALUE messages, or None for an unknown name."""
        return self._by_name.get(name)

    def get(self, name: str) -> float:
        """The value of a parameter, by MAVLink id."""
        return self.items[self._by_name[name]].value

    def mapping(self) -> dict[str, str]:
        """MAVLink id -> FMU variable (controller parameters only)."""
        return {p.name: p.fmu_name for p in self.items if p.fmu_name is not None}

    def controller_values(self) -> dict[str, float]:
        """The controller FMU's tunable variables as the parameters now set them."""
        return {p.fmu_name: p.value for p in self.items if p.fmu_name is not None}

    def set(self, name: str, value: float, param_type: int = MAV_PARAM_TYPE_REAL32
            ) -> Refused | None:
        """Check and apply a value; returns why it was refused, or None."""
        i = self._by_name.get(name)
        if i is None:
            return Refused(f"unknown parameter {name}", MAV_PARAM_ERROR_DOES_NOT_EXIST)
        p = self.items[i]
        if param_type != MAV_PARAM_TYPE_REAL32 and not p.integer:
            return Refused(f"{name} refused: a REAL32 parameter", MAV_PARAM_ERROR_TYPE_MISMATCH)
        reason = self._check(p, value, param_type)
        if reason is not None:
            return Refused(f"{name} {value:.4g} refused: {reason}",
                           MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE)
        if p.fmu_name is not None:
            self._apply(p.fmu_name, int(value) if p.integer else float(value))
        p.value = float(value)
        return None

    def _check(self, p: Parameter, value: float, param_type: int) -> str | None:
        if not math.isfinite(value):
            return "not finite"
        if p.integer and param_type == MAV_PARAM_TYPE_REAL32 and value != int(value):
            return "an integer parameter"
        if not p.range.contains(value):
            return f"outside {p.range.text()}"
        if p.name == "GF_ACTION" and value == 4:
            return "flight termination is not simulated"
        if p.fmu_name is None:
            return None
        r = p.range
        if r.lo == 0.0 and r.lo_open and r.hi is None and p.start > 0:
            lo, hi = p.start / PLAUSIBLE, p.start * PLAUSIBLE
            if not lo <= value <= hi:
                return f"outside [{lo:.3g}, {hi:.3g}]"
        base, _, idx = p.fmu_name.partition("[")
        if base in ("euler_min", "euler_max"):
            other = ("euler_max" if base == "euler_min" else "euler_min") + "[" + idx
            other_value = next(q.value for q in self.items if q.fmu_name == other)
            lo, hi = (value, other_value) if base == "euler_min" else (other_value, value)
            if lo > hi:
                return "euler_min above euler_max"
        if self._guard is not None:
            proposed = self.controller_values()
            proposed[p.fmu_name] = float(value)
            return self._guard(proposed, p.fmu_name)
        return None
