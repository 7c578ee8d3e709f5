"""A place on Earth: the geodetic origin of the local NED frame and the conversions.

The simulation flies in a local NED frame; ``Origin`` is the WGS84 point of its (0, 0, 0)
(latitude, longitude in degrees, altitude in metres above mean sea level, taken as the
ellipsoid height: the bridge has no geoid model, like PX4 SITL's simulated GPS).  The
conversions are pymap3d's (``ned2geodetic``/``geodetic2ned``, WGS84), not our own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pymap3d

#: PX4 SITL's default home (Zurich Irchel park: PX4-SITL_gazebo-classic include/common.h,
#: kDefaultHome*; PX4-Autopilot simulator_sih SIH_LOC_LAT0/LON0), see docs/mavlink.md
PX4_SITL_HOME = (47.397742, 8.545594, 488.0)


@dataclass(frozen=True)
class Origin:
    """The WGS84 point (lat, lon deg; alt m AMSL) of the local NED frame's origin (default: PX4
    SITL's home)."""
    lat: float = PX4_SITL_HOME[0]  # deg
    lon: float = PX4_SITL_HOME[1]  # deg
    alt: float = PX4_SITL_HOME[2]  # m AMSL

    def __post_init__(self) -> None:
        for name, v, lo, hi in (("latitude", self.lat, -90.0, 90.0),
                                ("longitude", self.lon, -180.0, 180.0),
                                ("altitude", self.alt, -500.0, 10000.0)):
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"origin {name} {v!r} outside [{lo:g}, {hi:g}]")
        if abs(self.lat) > 89.0:
            raise ValueError(f"origin latitude {self.lat:g}: within 1 deg of a pole "
                             "the local NED frame is not usable")

    def to_geodetic(self, n: float, e: float, d: float) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt m AMSL) of the local NED point."""
        lat, lon, h = pymap3d.ned2geodetic(n, e, d, self.lat, self.lon, self.alt)
        return float(lat), float(lon), float(h)

    def to_ned(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """Local NED (m) of the geodetic point (alt m AMSL)."""
        n, e, d = pymap3d.geodetic2ned(lat, lon, alt, self.lat, self.lon, self.alt)
        return float(n), float(e), float(d)


def parse_origin(text: str) -> Origin:
    """``LAT,LON,ALT`` (degrees, degrees, metres AMSL) -> Origin; ValueError says why."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 3:
        raise ValueError(f"--origin {text!r}: expected LAT,LON,ALT (deg, deg, m AMSL)")
    try:
        lat, lon, alt = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"--origin {text!r}: LAT, LON and ALT must be numbers") from None
    return Origin(lat, lon, alt)
