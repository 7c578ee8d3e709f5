"""The geofence's geometry: inclusion polygons and circles (fence plan items) in the local
frame, and whether a point is inside.

The vehicle is inside the fence when it is inside at least one inclusion zone (a polygon
or a circle, horizontally); an empty fence contains everything.  What a breach does is the
flier's policy (the MAVLink bridge: GF_ACTION, docs/mavlink.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from orchestrator.mission import items as mi
from orchestrator.mission.items import Geodetic, MissionItem


@dataclass(frozen=True)
class Fence:
    """Inclusion zones: polygons (vertices north, east in m, in order) and circles (centre
    north, east and radius in m)."""

    polygons: tuple[np.ndarray, ...] = ()
    circles: tuple[tuple[float, float, float], ...] = ()

    @property
    def empty(self) -> bool:
        """Whether there is no zone (then nothing is a breach)."""
        return not self.polygons and not self.circles

    @classmethod
    def from_items(cls, plan: Sequence[MissionItem], geo: Geodetic | None,
                   home_alt: float) -> Fence:
        """The zones of a fence plan (checked by ``items.check_plan``: polygons complete)."""
        polygons, circles = [], []
        i = 0
        while i < len(plan):
            item = plan[i]
            if item.command == mi.FENCE_POLYGON_VERTEX_INCLUSION:
                n = int(item.param1)
                pts = [mi.target(v, geo, home_alt, (0.0, 0.0, 0.0))[:2] for v in plan[i:i + n]]
                polygons.append(np.array(pts))
                i += n
                continue
            if item.command == mi.FENCE_CIRCLE_INCLUSION:
                c = mi.target(item, geo, home_alt, (0.0, 0.0, 0.0))
                circles.append((float(c[0]), float(c[1]), float(item.param1)))
            i += 1
        return cls(tuple(polygons), tuple(circles))

    def contains(self, pos: Sequence[float] | np.ndarray) -> bool:
        """Whether the point (north, east; a third coordinate is ignored) is inside."""
        if self.empty:
            return True
        n, e = float(pos[0]), float(pos[1])
        if any((n - cn) ** 2 + (e - ce) ** 2 <= r * r for cn, ce, r in self.circles):
            return True
        return any(_inside(poly, n, e) for poly in self.polygons)


def _inside(poly: np.ndarray, n: float, e: float) -> bool:
    """Even-odd rule: a ray from the point towards +east crosses the edges an odd number
    of times when the point is inside."""
    inside = False
    m = len(poly)
    for k in range(m):
        (n1, e1), (n2, e2) = poly[k], poly[(k + 1) % m]
        if (n1 > n) != (n2 > n):
            e_cross = e1 + (n - n1) * (e2 - e1) / (n2 - n1)
            if e < e_cross:
                inside = not inside
    return inside
