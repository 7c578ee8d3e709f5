"""Airframes of kinds the project does not ship, written as a user would (airframe files in
the documented format), for the tests that every feature works with any vehicle."""

from __future__ import annotations

from pathlib import Path

from plant import Airframe, load_airframe

_PROPULSION = """
[propulsion]
k_t = 1.14e-4
k_d = 1.14e-6
omega_min_rpm = 0
omega_max_rpm = 2000
time_constant = 0.0185
"""

KINDS: dict[str, str] = {
    # a quadrotor whose four rotors tilt on two servos each (+-30 deg)
    "tilting_quadrotor": """
name = "tilting_quadrotor"
[body]
mass = 0.9
inertia = [0.008, 0.008, 0.014]
""" + _PROPULSION + """
[servo]
time_constant = 0.02
alpha_limits_deg = [-30, 30]
beta_limits_deg = [-30, 30]
[ring]
count = 4
radius = 0.18
first_azimuth_deg = 45
spin = [1, -1, 1, -1]
""",
    # eight rotors on servos: the largest problem the controller derives (8 rotors, 2 servos)
    "tilting_octocopter": """
name = "tilting_octocopter"
[body]
mass = 1.4
inertia = [0.02, 0.02, 0.035]
""" + _PROPULSION + """
[servo]
time_constant = 0.02
alpha_limits_deg = [-35, 35]
beta_limits_deg = [-35, 35]
[ring]
count = 8
radius = 0.25
first_azimuth_deg = 22.5
spin = [1, -1, 1, -1, 1, -1, 1, -1]
""",
    # a fixed-tilt hexarotor with other cant angles than the shipped one (and a beta cant)
    "canted_hexarotor": """
name = "canted_hexarotor"
[body]
mass = 1.0
inertia = [0.011, 0.011, 0.02]
""" + _PROPULSION + """
[ring]
count = 6
radius = 0.22
first_azimuth_deg = 0
spin = [1, -1, 1, -1, 1, -1]
alpha_deg = [-30, 30, -30, 30, -30, 30]
beta_deg = [10, -10, 10, -10, 10, -10]
""",
    # a heavier tilting hexacopter: 2.4 kg, 0.30 m arms, +-30 deg servos, slower servos
    "heavy_tilting_hexacopter": """
name = "heavy_tilting_hexacopter"
[body]
mass = 2.4
inertia = [0.03, 0.032, 0.06]
[propulsion]
k_t = 2.0e-4
k_d = 2.4e-6
omega_min_rpm = 0
omega_max_rpm = 2200
time_constant = 0.025
[servo]
time_constant = 0.04
alpha_limits_deg = [-30, 30]
beta_limits_deg = [-30, 30]
[ring]
count = 6
radius = 0.30
first_azimuth_deg = 30
spin = [1, -1, 1, -1, 1, -1]
""",
}


def write_kind(name: str, folder: Path) -> Path:
    """The airframe file of kind ``name`` in ``folder``."""
    path = folder / f"{name}.toml"
    path.write_text(KINDS[name].lstrip(), encoding="utf-8")
    return path


def load_kind(name: str, folder: Path) -> Airframe:
    """The airframe of kind ``name`` loaded from its file in ``folder``."""
    return load_airframe(write_kind(name, folder))
