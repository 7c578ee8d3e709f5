"""Airframes of kinds the project does not ship, written as a user would (airframe files in
the documented format), for the tests that every feature works with any vehicle."""

from __future__ import annotations

from pathlib import Path

from plant import Airframe, load_airframe


def _frame(name: str, mass: float, inertia: tuple[float, float, float], ring: str,
           propulsion: str = "k_t = 1.14e-4\nk_d = 1.14e-6\nomega_max_rpm = 2000\n"
                             "time_constant = 0.0185",
           servo: tuple[float, float] | None = None) -> str:
    """An airframe file: body, propulsion, servos (time constant, +-limit in degrees) or
    none, and a [ring] given as its TOML lines."""
    text = (f'name = "{name}"\n[body]\nmass = {mass}\ninertia = {list(inertia)}\n'
            f"[propulsion]\n{propulsion}\n")
    if servo is not None:
        tau, limit = servo
        text += (f"[servo]\ntime_constant = {tau}\nalpha_limits_deg = [{-limit}, {limit}]\n"
                 f"beta_limits_deg = [{-limit}, {limit}]\n")
    return text + f"[ring]\n{ring}\n"


def _spins(n: int) -> str:
    return f"spin = {[1 if k % 2 == 0 else -1 for k in range(n)]}"


KINDS: dict[str, str] = {
    # a quadrotor whose four rotors tilt on two servos each (+-30 deg)
    "tilting_quadrotor": _frame(
        "tilting_quadrotor", 0.9, (0.008, 0.008, 0.014),
        f"count = 4\nradius = 0.18\nfirst_azimuth_deg = 45\n{_spins(4)}", servo=(0.02, 30)),
    # eight rotors on servos: the largest problem the controller derives (8 rotors, 2 servos)
    "tilting_octocopter": _frame(
        "tilting_octocopter", 1.4, (0.02, 0.02, 0.035),
        f"count = 8\nradius = 0.25\nfirst_azimuth_deg = 22.5\n{_spins(8)}", servo=(0.02, 35)),
    # a fixed-tilt hexarotor with other cant angles than the shipped one (and a beta cant)
    "canted_hexarotor": _frame(
        "canted_hexarotor", 1.0, (0.011, 0.011, 0.02),
        f"count = 6\nradius = 0.22\nfirst_azimuth_deg = 0\n{_spins(6)}\n"
        "alpha_deg = [-30, 30, -30, 30, -30, 30]\nbeta_deg = [10, -10, 10, -10, 10, -10]"),
    # a heavier tilting hexacopter: 2.4 kg, 0.30 m arms, +-30 deg servos, slower servos
    "heavy_tilting_hexacopter": _frame(
        "heavy_tilting_hexacopter", 2.4, (0.03, 0.032, 0.06),
        f"count = 6\nradius = 0.30\nfirst_azimuth_deg = 30\n{_spins(6)}",
        propulsion="k_t = 2.0e-4\nk_d = 2.4e-6\nomega_max_rpm = 2200\ntime_constant = 0.025",
        servo=(0.04, 30)),
}


def write_kind(name: str, folder: Path) -> Path:
    """The airframe file of kind ``name`` in ``folder``."""
    path = folder / f"{name}.toml"
    path.write_text(KINDS[name].lstrip(), encoding="utf-8")
    return path


def load_kind(name: str, folder: Path) -> Airframe:
    """The airframe of kind ``name`` loaded from its file in ``folder``."""
    return load_airframe(write_kind(name, folder))
