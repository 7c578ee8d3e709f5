"""MAVLink parameter names for the tunable controller parameters and the bridge's own.

MAVLink parameter ids are at most 16 characters.  The controller FMU's tunable
parameters are mapped by a fixed rule (docs/mavlink.md lists them all):

========================  ================  =======================================
FMU variable              MAVLink name      valid values (checked before setting)
========================  ================  =======================================
K_pos_A[i] .. K_rate_D[i] FP_KPOS_A1 ..     finite; the A entries |A| < 1
                          FP_KRATE_D3
gamma_opt                 FP_GAMMA_OPT      > 0
W_u[i], W_v[i], W_nu[i]   FP_W_U1, FP_W_V1, > 0
                          FP_W_NU1 ...
euler_min[i], euler_max[i] FP_EUL_MIN1 ...  inside (-pi/2, pi/2), min <= max
w_pref                    FP_W_PREF         > 0
pref_omega_scale          FP_PREF_OM_SC     > 0
qp_max_iter               FP_QP_MAX_ITER    integer 1..1000
========================  ================  =======================================

The bridge's own parameters start with ``FPB_`` (setpoint-loss timeout and setpoint
limits).  Every parameter is reported as MAV_PARAM_TYPE_REAL32 (integers carry an
integral float value, no byte-wise encoding).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from mavlink_bridge.identity import PX4_PARAMETERS

_BLOCK = re.compile(r"^K_(pos|vel|att|rate)_([ABCD])\[(\d+)\]$")
_VECTOR = {"W_u": "FP_W_U", "W_v": "FP_W_V", "W_nu": "FP_W_NU", "euler_min": "FP_EUL_MIN",
           "euler_max": "FP_EUL_MAX"}
_SCALAR = {"gamma_opt": "FP_GAMMA_OPT", "w_pref": "FP_W_PREF",
           "pref_omega_scale": "FP_PREF_OM_SC", "qp_max_iter": "FP_QP_MAX_ITER"}

#: Bridge parameters: name -> (default, minimum, maximum, description)
BRIDGE_PARAMETERS: dict[str, tuple[float, float, float, str]] = {
    "FPB_SP_TIMEOUT": (0.5, 0.05, 60.0, "offboard setpoint-loss timeout (s, simulated time)"),
    "FPB_SP_XY_MAX": (100.0, 0.1, 10000.0, "largest accepted |x|, |y| of a setpoint (m)"),
    "FPB_SP_Z_MAX": (100.0, 0.1, 10000.0, "largest accepted |z| of a setpoint (m)"),
    "FPB_SP_VEL_MAX": (10.0, 0.0, 100.0, "largest accepted velocity component (m/s)"),
    "FPB_SP_ACC_MAX": (20.0, 0.0, 100.0, "largest accepted acceleration component (m/s^2)"),
    "FPB_SP_RATE_MAX": (6.0, 0.0, 50.0, "largest accepted body/yaw rate (rad/s)"),
    "FPB_SP_TILT_MAX": (1.4, 0.0, 1.5, "largest accepted |roll|, |pitch| of a setpoint (rad)"),
    **PX4_PARAMETERS,  # the identity's read-only PX4 parameters (mavlink_bridge.identity)
}


def mavlink_name(fmu_name: str) -> str | None:
    """The MAVLink id of a tunable FMU parameter (None: not mapped)."""
    m = _BLOCK.match(fmu_name)
    if m:
        return f"FP_K{m.group(1).upper()}_{m.group(2)}{m.group(3)}"
    base, _, index = fmu_name.partition("[")
    if base in _VECTOR and index.endswith("]"):
        return f"{_VECTOR[base]}{index[:-1]}"
    return _SCALAR.get(fmu_name)


@dataclass
class Parameter:
    name: str  # MAVLink id
    fmu_name: str | None  # None: a bridge parameter
    value: float


class ParameterTable:
    """The parameters a ground station sees, in a fixed order (PARAM_VALUE index)."""

    def __init__(self, tunables: Iterable[tuple[str, float]],
                 apply: Callable[[str, float], None]) -> None:
        self._apply = apply
        self.items: list[Parameter] = []
        for fmu_name, value in tunables:
            name = mavlink_name(fmu_name)
            if name is not None and len(name) <= 16:
                self.items.append(Parameter(name, fmu_name, float(value)))
        for name, (default, _, _, _) in BRIDGE_PARAMETERS.items():
            self.items.append(Parameter(name, None, default))
        self._by_name = {p.name: i for i, p in enumerate(self.items)}

    def __len__(self) -> int:
        return len(self.items)

    def index(self, name: str) -> int | None:
        return self._by_name.get(name)

    def get(self, name: str) -> float:
        return self.items[self._by_name[name]].value

    def mapping(self) -> dict[str, str]:
        """MAVLink id -> FMU variable (controller parameters only)."""
        return {p.name: p.fmu_name for p in self.items if p.fmu_name is not None}

    def set(self, name: str, value: float) -> str | None:
        """Check and apply a value; returns the reason it was refused, or None."""
        i = self._by_name.get(name)
        if i is None:
            return f"unknown parameter {name}"
        p = self.items[i]
        reason = self._check(p, value)
        if reason is not None:
            return f"{name} = {value:g} refused: {reason}"
        if p.fmu_name is not None:
            self._apply(p.fmu_name, int(value) if p.name == "FP_QP_MAX_ITER" else float(value))
        p.value = float(value)
        return None

    def _check(self, p: Parameter, value: float) -> str | None:
        if not math.isfinite(value):
            return "not finite"
        if p.fmu_name is None:
            _, lo, hi, _ = BRIDGE_PARAMETERS[p.name]
            return None if lo <= value <= hi else f"must be in [{lo:g}, {hi:g}]"
        f = p.fmu_name
        base = f.split("[")[0]
        if _BLOCK.match(f):
            if "_A[" in f and abs(value) >= 1.0:
                return "a block's pole must satisfy |A| < 1"
            return None
        if base in ("gamma_opt", "W_u", "W_v", "W_nu", "w_pref", "pref_omega_scale"):
            return None if value > 0.0 else "must be positive"
        if base == "qp_max_iter":
            ok = value == int(value) and 1 <= value <= 1000
            return None if ok else "must be an integer in 1..1000"
        if base in ("euler_min", "euler_max"):
            if abs(value) >= math.pi / 2:
                return "must be inside (-pi/2, pi/2)"
            idx = f[f.index("["):]
            other = "euler_max" if base == "euler_min" else "euler_min"
            other_value = next(q.value for q in self.items if q.fmu_name == other + idx)
            lo, hi = (value, other_value) if base == "euler_min" else (other_value, value)
            return None if lo <= hi else "euler_min must not exceed euler_max"
        return None
