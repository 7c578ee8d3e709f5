"""Airframe description files (TOML): loading, validation, FMU parameters.

An airframe file describes the body, the propulsion and the rotor geometry in
user units (degrees, rpm where the key says so).  Errors name the file, the
field and what is expected.  See docs/airframes.md for the format.
"""

from __future__ import annotations

import ctypes
import difflib
import hashlib
import json
import math
import sys
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from plant.common.toml_reader import FieldError, TomlTable, read_toml, resolve_file, shipped_names
from plant.effectiveness import RotorSet
from plant.landing_gear import NO_GEAR, LandingGear, parse_landing_gear
from plant.native import multirotor

if sys.version_info >= (3, 11):
    pass
else:  # pragma: no cover
    pass

MAX_ROTORS = 8
RPM = 2.0 * math.pi / 60.0
_EFFECT = {"k_t": "thrust", "k_d": "drag torque"}

# Physical plausibility of the propulsion (docs/airframes.md, "Plausible numbers"): the
# bounds fp_check_airframe applies in both FMUs (FP_* in fmu_src/common/multirotor.h; a test
# compares them), computed here in the same order so that both refuse the same airframes.
OMEGA_MAX_RPM_LIMITS = (1.0, 500000.0)
"""A rotor's top speed omega_max (rpm): no lifting rotor turns slower or faster."""
ROTOR_THRUST_LIMITS = (1e-3, 1e5)
"""A rotor's maximum thrust k_t omega_max^2 (N): 0.1 gram-force to 10 tonnes-force."""
DRAG_RATIO_MAX = 10.0
"""The drag torque per newton of thrust, k_d / k_t (m)."""
THRUST_TO_WEIGHT_LIMITS = (0.1, 100.0)
"""n k_t omega_max^2 / (m g), when g > 0."""


class AirframeError(FieldError):
    """An airframe file is missing, unreadable or inconsistent."""


@dataclass(frozen=True)
class Airframe:
    """A validated airframe, in SI units and radians."""

    name: str
    description: str
    source: str
    mass: float
    inertia: np.ndarray  # (3, 3)
    gravity: float
    k_t: float
    k_d: float
    omega_min: float
    omega_max: float
    tau_motor: float
    tau_servo: float
    tilting: bool
    positions: np.ndarray  # (n, 3)
    spins: np.ndarray  # (n,) int
    gamma: np.ndarray  # (n,)
    alpha_limits: np.ndarray  # (n, 2); equal columns = fixed tilt
    beta_limits: np.ndarray  # (n, 2)
    gear: LandingGear | None = None  # the landing gear (None: no ground contact)

    @property
    def n_rotors(self) -> int:
        """Number of rotors."""
        return int(self.positions.shape[0])

    def native_buffer(self) -> ctypes.Array[ctypes.c_char]:
        """The airframe as the C core's ``FpAirframe`` (the struct both models embed),
        written row by row of the airframe table at the offsets the C core gives."""
        lib = multirotor()
        buf = ctypes.create_string_buffer(lib.fp_airframe_size())
        values = self.table_values()
        for row in airframe_table():
            data = np.ascontiguousarray(values[row.name], dtype=np.int32 if row.integer
                                        else np.float64).reshape(-1)
            if data.size != row.rows * row.cols:
                raise AirframeError(self.source, row.name, f"{data.size} values for a "
                                    f"{row.rows} x {row.cols} variable")
            ctypes.memmove(ctypes.addressof(buf) + row.offset, data.ctypes.data, data.nbytes)
        return buf

    def rotor_set(self) -> RotorSet:
        """The rotors, for the rotor math of the C core (:mod:`plant.effectiveness`)."""
        lib = multirotor()
        native = ctypes.create_string_buffer(lib.fp_rotor_set_size())
        if lib.fp_rotor_set_from_airframe(self.native_buffer(), native) != 0:
            raise AirframeError(self.source, "", f"invalid rotor set (n = {self.n_rotors}, "
                                f"k_t = {self.k_t})")
        return RotorSet(
            native=native.raw,
            k_t=self.k_t,
            k_d=self.k_d,
            positions=self.positions,
            spins=self.spins.astype(np.int32),
            gamma=self.gamma,
            alpha_limits=self.alpha_limits,
            beta_limits=self.beta_limits,
            omega_limits=(self.omega_min, self.omega_max),
        )

    def table_values(self) -> dict[str, np.ndarray]:
        """The airframe's numbers by row of the airframe variable table both FMUs share
        (``fmu_src/common/airframe_vars.h``), each as an array of the row's shape (rotor rows
        padded to the table's 8 slots: spin +1, zeros elsewhere)."""
        n, slots = self.n_rotors, MAX_ROTORS

        def rotors(values: np.ndarray, fill: float = 0.0) -> np.ndarray:
            out = np.full((slots, *values.shape[1:]), fill, dtype=float)
            out[:n] = values
            return out

        return {
            "n_rotors": np.array([n]), "mass": np.array([self.mass]),
            "inertia": self.inertia, "g": np.array([self.gravity]),
            "k_t": np.array([self.k_t]), "k_d": np.array([self.k_d]),
            "rotor_pos": rotors(self.positions), "rotor_dir": rotors(self.spins, 1.0),
            "rotor_gamma": rotors(self.gamma),
            "alpha_min": rotors(self.alpha_limits[:, 0]),
            "alpha_max": rotors(self.alpha_limits[:, 1]),
            "beta_min": rotors(self.beta_limits[:, 0]),
            "beta_max": rotors(self.beta_limits[:, 1]),
            "omega_min": np.array([self.omega_min]), "omega_max": np.array([self.omega_max]),
            "tau_motor": np.array([self.tau_motor]), "tau_servo": np.array([self.tau_servo]),
        }

    def fmu_parameters(self) -> dict[str, float | int | bool]:
        """Start values of both FMUs' airframe variables, keyed by variable name: every row
        of the table the C core declares (:func:`airframe_table`), elementwise
        (``rotor_pos[2,3]``), nothing else."""
        values = self.table_values()
        p: dict[str, float | int | bool] = {}
        for row in airframe_table():
            if row.name not in values:
                raise AirframeError(self.source, row.name, "an airframe variable of the FMUs "
                                    "that Airframe.table_values does not provide")
            flat = np.asarray(values[row.name], dtype=float).reshape(-1)
            if flat.size != row.rows * row.cols:
                raise AirframeError(self.source, row.name, f"{flat.size} values for a "
                                    f"{row.rows} x {row.cols} variable")
            for k, v in enumerate(flat):
                p[row.element(k)] = int(v) if row.integer else float(v)
        return p

    def plant_parameters(self) -> dict[str, float | int]:
        """Start values of the plant FMU's own airframe numbers (beyond the shared table):
        the landing gear's contact parameters (:mod:`plant.landing_gear`)."""
        return dict(NO_GEAR) if self.gear is None else self.gear.plant_parameters()

    def record(self) -> dict[str, Any]:
        """Every number of the airframe as JSON-ready data (``repr``-exact floats), what a
        results folder stores so that its figures and 3-D view never reload the file."""
        return {"name": self.name, "description": self.description, "source": self.source,
                "mass": self.mass, "inertia": self.inertia.tolist(), "gravity": self.gravity,
                "k_t": self.k_t, "k_d": self.k_d, "omega_min": self.omega_min,
                "omega_max": self.omega_max, "tau_motor": self.tau_motor,
                "tau_servo": self.tau_servo, "tilting": self.tilting,
                "positions": self.positions.tolist(), "spins": self.spins.tolist(),
                "gamma": self.gamma.tolist(), "alpha_limits": self.alpha_limits.tolist(),
                "beta_limits": self.beta_limits.tolist(),
                **({} if self.gear is None else {"landing_gear": self.gear.record()})}

    def digest(self) -> str:
        """SHA-256 of :meth:`record`'s numbers (name and source excluded)."""
        numbers = {k: v for k, v in self.record().items()
                   if k not in ("name", "description", "source")}
        return hashlib.sha256(json.dumps(numbers, sort_keys=True).encode()).hexdigest()

    @staticmethod
    def from_record(doc: dict[str, Any]) -> Airframe:
        """The inverse of :meth:`record`; AirframeError when the record is malformed."""
        try:
            n = len(doc["positions"])
            arrays = {"inertia": (3, 3), "positions": (n, 3), "spins": (n,), "gamma": (n,),
                      "alpha_limits": (n, 2), "beta_limits": (n, 2)}
            values = {k: np.array(doc[k], dtype=int if k == "spins" else float)
                      for k in arrays}
            for k, shape in arrays.items():
                if values[k].shape != shape or not np.all(np.isfinite(values[k])):
                    raise ValueError(f"{k}: expected finite numbers of shape {shape}")
            if not 1 <= n <= MAX_ROTORS:
                raise ValueError(f"positions: expected 1..{MAX_ROTORS} rotors, got {n}")
            return Airframe(
                name=str(doc["name"]), description=str(doc.get("description", "")),
                source=str(doc.get("source", "")), mass=float(doc["mass"]),
                inertia=values["inertia"], gravity=float(doc["gravity"]),
                k_t=float(doc["k_t"]), k_d=float(doc["k_d"]),
                omega_min=float(doc["omega_min"]), omega_max=float(doc["omega_max"]),
                tau_motor=float(doc["tau_motor"]), tau_servo=float(doc["tau_servo"]),
                tilting=bool(doc["tilting"]), positions=values["positions"],
                spins=values["spins"], gamma=values["gamma"],
                alpha_limits=values["alpha_limits"], beta_limits=values["beta_limits"],
                gear=(LandingGear.from_record(doc["landing_gear"]) if "landing_gear" in doc
                      else None))
        except (KeyError, TypeError, ValueError) as e:
            raise AirframeError("<airframe record>", "", f"not an airframe record: {e}") from None

    def hover_trim(self, euler: object = (0.0, 0.0, 0.0)) -> tuple[np.ndarray, ...]:
        """(alpha, beta, omega) holding hover at the given attitude (C core)."""
        e = np.asarray(euler, dtype=float)
        rs = self.rotor_set()
        # f_b = -R^T m g e_z with R = Rz(psi) Ry(theta) Rx(phi); its third row is needed only
        c_phi, s_phi = math.cos(e[0]), math.sin(e[0])
        c_th, s_th = math.cos(e[1]), math.sin(e[1])
        row3 = np.array([-s_th, s_phi * c_th, c_phi * c_th])
        wrench = np.concatenate([-self.mass * self.gravity * row3, np.zeros(3)])
        return rs.preferred_config(wrench)


@dataclass(frozen=True)
class TableRow:
    """One row of the airframe variable table (``fmu_src/common/airframe_vars.h``)."""

    name: str
    rows: int
    cols: int
    integer: bool
    offset: int
    """Byte offset of the row's member in the C core's ``FpAirframe``."""

    def element(self, k: int) -> str:
        """The FMI name of element k (row-major): ``mass``, ``rotor_dir[3]``,
        ``rotor_pos[2,1]``."""
        if self.rows * self.cols == 1:
            return self.name
        if self.cols == 1:
            return f"{self.name}[{k + 1}]"
        return f"{self.name}[{k // self.cols + 1},{k % self.cols + 1}]"


@cache
def airframe_table() -> tuple[TableRow, ...]:
    """The airframe variable table both FMUs share, as the C core declares it
    (``libfp_multirotor``): what an airframe is, in the FMUs' words."""
    lib = multirotor()
    out = []
    for i in range(lib.fp_airframe_variable_count()):
        name = ctypes.create_string_buffer(64)
        rows, cols = ctypes.c_int32(), ctypes.c_int32()
        integer, offset = ctypes.c_int32(), ctypes.c_int32()
        if lib.fp_airframe_variable(i, name, 64, ctypes.byref(rows), ctypes.byref(cols),
                                    ctypes.byref(integer), ctypes.byref(offset)) != 0:
            raise RuntimeError(f"libfp_multirotor: airframe table row {i} unreadable")
        out.append(TableRow(name.value.decode(), rows.value, cols.value, bool(integer.value),
                            offset.value))
    return tuple(out)


# ---------------------------------------------------------------------------
# Loading


def list_airframes() -> list[str]:
    """Names of the airframe files shipped with the package."""
    return shipped_names("plant", "airframes")


def resolve_airframe(name_or_path: str | Path) -> Path:
    """The airframe file a name or path stands for (a shipped name, or a file)."""
    return resolve_file(name_or_path, "plant", "airframes", "airframe", AirframeError)


def load_airframe(name_or_path: str | Path) -> Airframe:
    """Load and validate an airframe file, or a shipped airframe by name."""
    path = resolve_airframe(name_or_path)
    return parse_airframe(read_toml(path, AirframeError), str(path))


class _Reader(TomlTable):
    """Typed access to an airframe file's table with errors that name the field."""

    error = AirframeError

    def table(self, key: str, required: bool = True) -> _Reader | None:
        self.used.add(key)
        if key not in self.data:
            if required:
                raise self.fail(key, "missing table")
            return None
        value = self.data[key]
        if not isinstance(value, dict):
            raise self.fail(key, "expected a table")
        return _Reader(self.source, value, f"{self.field(key)}.")

    def numbers(self, key: str, length: int | None = None,
                default: list[float] | None = None) -> list[float]:
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise self.fail(key, "missing (expected an array of numbers)")
            return default
        value = self.data[key]
        if not isinstance(value, list) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
        ):
            raise self.fail(key, f"expected an array of numbers, got {value!r}")
        if length is not None and len(value) != length:
            raise self.fail(key, f"expected {length} numbers, got {len(value)}")
        if not all(math.isfinite(float(v)) for v in value):
            raise self.fail(key, "expected finite numbers")
        return [float(v) for v in value]

    def limits_deg(self, key: str) -> tuple[float, float]:
        lo, hi = self.numbers(key, 2)
        if lo > hi:
            raise self.fail(key, f"lower limit {lo} exceeds upper limit {hi}")
        if lo < -90 or hi > 90:
            raise self.fail(key, "limits must be within [-90, 90] degrees")
        return math.radians(lo), math.radians(hi)

    def reject_unknown(self) -> None:
        """An error for the first field the parser never asked for, with the closest field
        it did ask for (present or not) as a suggestion."""
        for key in self.data:
            if key not in self.used:
                close = difflib.get_close_matches(key, sorted(self.used), n=1, cutoff=0.6)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise self.fail(key, "unknown field" + hint)


def _inertia(body: _Reader) -> np.ndarray:
    raw = body.data.get("inertia")
    body.used.add("inertia")
    if raw is None:
        raise body.fail("inertia", "missing (expected [Ixx, Iyy, Izz] or a 3x3 matrix)")
    if isinstance(raw, list) and len(raw) == 3 and all(isinstance(r, list) for r in raw):
        numeric = all(
            len(r) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in r)
            for r in raw
        )
        matrix = np.array(raw, dtype=float) if numeric else np.full((3, 3), np.nan)
        if not np.all(np.isfinite(matrix)):
            raise body.fail("inertia", "expected a 3x3 matrix of finite numbers")
    else:
        matrix = np.diag(body.numbers("inertia", 3))
    if not np.allclose(matrix, matrix.T, rtol=0, atol=1e-12 * np.abs(matrix).max()):
        raise body.fail("inertia", "matrix must be symmetric")
    eig = np.linalg.eigvalsh(matrix)
    if not np.all(eig > 0):
        raise body.fail("inertia", f"must be positive definite (eigenvalues {eig.tolist()})")
    return matrix


def _per_rotor(reader: _Reader, key: str, n: int, default: float) -> list[float]:
    values = reader.numbers(key, None, [default] * n)
    if len(values) != n:
        raise reader.fail(key, f"expected {n} values (one per rotor), got {len(values)}")
    return values


def _check_propulsion(prop: _Reader, k_t: float, k_d: float, omega_max: float) -> float:
    """A rotor's maximum thrust k_t omega_max^2 (N) after the plausibility bounds of the
    rotor speed, the thrust and the drag torque (fp_check_airframe's, in its order: the
    first bound missed is blamed on the field it names)."""
    rpm = omega_max / RPM
    lo, hi = (v * RPM for v in OMEGA_MAX_RPM_LIMITS)
    if not lo <= omega_max <= hi:
        what = (f"below {OMEGA_MAX_RPM_LIMITS[0]:g} rpm, slower" if omega_max < lo else
                f"beyond {OMEGA_MAX_RPM_LIMITS[1]:g} rpm, faster")
        raise prop.fail("omega_max_rpm", f"{rpm:.5g} rpm is {what} than any rotor turns "
                        "(see 'Plausible numbers' in docs/airframes.md)")
    t_max = k_t * (omega_max * omega_max)
    t_lo, t_hi = ROTOR_THRUST_LIMITS
    if not t_lo <= t_max <= t_hi:
        what = (f"below {t_lo:g} N, less" if t_max < t_lo else f"beyond {t_hi:g} N, more")
        raise prop.fail("k_t", f"{k_t:.5g} N/(rad/s)^2 gives a rotor a maximum thrust "
                        f"k_t omega_max^2 = {t_max:.5g} N at {rpm:.5g} rpm, {what} than any "
                        "rotor's; is k_t in N/(rad/s)^2?")
    ratio = k_d / k_t
    if not ratio <= DRAG_RATIO_MAX:
        raise prop.fail("k_d", f"{k_d:.5g} N m/(rad/s)^2 gives a drag torque per newton of "
                        f"thrust k_d / k_t = {ratio:.5g} m, beyond {DRAG_RATIO_MAX:g} m, more "
                        "than any rotor's; is k_d in N m/(rad/s)^2?")
    return t_max


def _check_thrust_to_weight(body: _Reader, n: int, t_max: float, mass: float,
                            gravity: float) -> None:
    """The thrust-to-weight ratio n k_t omega_max^2 / (m g) within its plausibility bounds
    (under gravity; fp_check_airframe's rule)."""
    if not gravity > 0.0:
        return
    weight = mass * gravity
    ratio = n * t_max / weight
    lo, hi = THRUST_TO_WEIGHT_LIMITS
    if not lo <= ratio <= hi:
        what = f"below {lo:g}" if ratio < lo else f"beyond {hi:g}"
        raise body.fail("mass", f"{mass:.5g} kg: the thrust-to-weight ratio n k_t "
                        f"omega_max^2 / (m g) = {n} x {t_max:.5g} N / {weight:.5g} N = "
                        f"{ratio:.5g} is {what}, not a vehicle's; is the mass in kg?")


def parse_airframe(data: dict[str, Any], source: str = "<airframe>") -> Airframe:
    """An airframe from a TOML document already read (source names it in errors)."""
    top = _Reader(source, data)
    name = top.string("name")
    description = top.string("description", "")

    body = top.table("body")
    assert body is not None
    mass = body.number("mass", positive=True)
    inertia = _inertia(body)
    gravity = body.number("gravity", 9.81, nonnegative=True)
    body.reject_unknown()

    prop = top.table("propulsion")
    assert prop is not None
    k_t = prop.number("k_t", positive=True)
    k_d = prop.number("k_d", nonnegative=True)
    omega_min = prop.number("omega_min_rpm", 0.0, nonnegative=True) * RPM
    omega_max = prop.number("omega_max_rpm", positive=True) * RPM
    if omega_min > omega_max:
        raise prop.fail("omega_min_rpm", "exceeds omega_max_rpm")
    square = omega_max * omega_max  # (float products overflow to inf; ** would raise)
    for key, k in (("k_t", k_t), ("k_d", k_d)):
        if not math.isfinite(k * square):
            what = (f"its square, {omega_max:.5g}^2 (rad/s)^2," if math.isinf(square) else
                    f"the rotor {_EFFECT[key]} {key} omega_max^2 = {k:.5g} x {square:.5g}")
            raise prop.fail("omega_max_rpm", f"{omega_max:.5g} rad/s: {what} is beyond the "
                            "range of a double (1.8e308)")
    t_max = _check_propulsion(prop, k_t, k_d, omega_max)
    tau_motor = prop.number("time_constant", positive=True)
    prop.reject_unknown()

    servo = top.table("servo", required=False)
    tilting = servo is not None
    if servo is not None:
        tau_servo = servo.number("time_constant", positive=True)
        alpha_lim = servo.limits_deg("alpha_limits_deg")
        beta_lim = servo.limits_deg("beta_limits_deg")
        servo.reject_unknown()
    else:
        tau_servo = tau_motor

    ring = top.table("ring", required=False)
    rotors_raw = data.get("rotor")
    top.used.add("rotor")
    if (ring is None) == (rotors_raw is None):
        raise AirframeError(source, "ring", "give exactly one of [ring] or [[rotor]] entries")

    positions: list[list[float]] = []
    spins: list[int] = []
    gammas: list[float] = []
    fixed_alpha: list[float] = []
    fixed_beta: list[float] = []
    if ring is not None:
        n = int(ring.number("count", positive=True))
        if ring.data.get("count") != n or not 1 <= n <= MAX_ROTORS:
            raise ring.fail("count", f"expected an integer in 1..{MAX_ROTORS}")
        radius = ring.number("radius", positive=True)
        first = math.radians(ring.number("first_azimuth_deg", 0.0))
        height = ring.number("height", 0.0)
        spin_values = ring.numbers("spin", n)
        fixed_alpha = [math.radians(a) for a in _per_rotor(ring, "alpha_deg", n, 0.0)]
        fixed_beta = [math.radians(b) for b in _per_rotor(ring, "beta_deg", n, 0.0)]
        for k in range(n):
            az = first + 2.0 * math.pi * k / n
            positions.append([radius * math.cos(az), radius * math.sin(az), height])
            gammas.append(az)
        spins = [int(s) for s in spin_values]
        if any(s not in (-1, 1) or s != v for s, v in zip(spins, spin_values, strict=True)):
            raise ring.fail("spin", "each spin must be +1 or -1")
        ring.reject_unknown()
    else:
        if not isinstance(rotors_raw, list) or not all(isinstance(r, dict) for r in rotors_raw):
            raise AirframeError(source, "rotor", "expected an array of tables [[rotor]]")
        if not 1 <= len(rotors_raw) <= MAX_ROTORS:
            raise AirframeError(source, "rotor", f"expected 1..{MAX_ROTORS} rotors")
        for k, raw in enumerate(rotors_raw):
            r = _Reader(source, raw, f"rotor[{k + 1}].")
            positions.append(r.numbers("position", 3))
            spin = r.number("spin")
            if spin not in (-1.0, 1.0):
                raise r.fail("spin", "must be +1 or -1")
            spins.append(int(spin))
            gammas.append(math.radians(r.number("gamma_deg", 0.0)))
            fixed_alpha.append(math.radians(r.number("alpha_deg", 0.0)))
            fixed_beta.append(math.radians(r.number("beta_deg", 0.0)))
            r.reject_unknown()
    gear_table = top.table("landing_gear", required=False)
    gear = None
    if gear_table is not None:
        gear = parse_landing_gear(gear_table)
        gear_table.reject_unknown()
    top.reject_unknown()

    n = len(positions)
    _check_thrust_to_weight(body, n, t_max, mass, gravity)
    if tilting:
        if any(a != 0 for a in fixed_alpha + fixed_beta):
            raise AirframeError(source, "servo", "fixed tilt angles (alpha_deg/beta_deg) need "
                                "a frame without [servo]; with servos the tilt is commanded")
        alpha_limits = np.tile(alpha_lim, (n, 1))
        beta_limits = np.tile(beta_lim, (n, 1))
    else:
        alpha_limits = np.column_stack([fixed_alpha, fixed_alpha])
        beta_limits = np.column_stack([fixed_beta, fixed_beta])
    for k in range(n):
        if abs(alpha_limits[k, 0]) > math.pi / 2 or abs(beta_limits[k, 0]) > math.pi / 2:
            raise AirframeError(source, "alpha_deg", "fixed tilts must be within [-90, 90] deg")

    return Airframe(
        name=name,
        description=description,
        source=source,
        mass=mass,
        inertia=inertia,
        gravity=gravity,
        k_t=k_t,
        k_d=k_d,
        omega_min=omega_min,
        omega_max=omega_max,
        tau_motor=tau_motor,
        tau_servo=tau_servo,
        tilting=tilting,
        positions=np.array(positions, dtype=float),
        spins=np.array(spins, dtype=int),
        gamma=np.array(gammas, dtype=float),
        alpha_limits=np.asarray(alpha_limits, dtype=float),
        beta_limits=np.asarray(beta_limits, dtype=float),
        gear=gear,
    )
