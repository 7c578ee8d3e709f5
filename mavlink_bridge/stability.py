"""Predicted stability of a gain change, from the linear design model the gains were made for.

The controller FMU's blocks ``K_pos``/``K_vel`` (each translation axis) and ``K_att``/
``K_rate`` (each rotation axis) are the cascades ``controller.hinf`` synthesizes
(docs/robust_design.md).  For a proposed set of gains the guard builds, for the one axis the
change touches, the design model's discrete closed loop on the nominal plant (k = 1, the
shipped actuator time constant, the design's computational delay; ``hinf.interconnection``
unweighted) and the inner loop alone with the outer loop open (``hinf.inner_loop``), and
refuses the change when either has a spectral radius of 1 or more.  The margin told is
``1 - rho`` (negative: unstable).  One evaluation is a few small eigenvalue problems (~1 ms,
measured in tests/test_mavlink_bridge/test_mavlink_safety.py); it runs on a PARAM_SET, never per
step.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from controller import hinf

_GAIN = re.compile(r"^K_(pos|vel|att|rate)_[ABCD]\[(\d+)\]$")
_LOOP = {"pos": ("pos", "vel", hinf.TRANSLATION), "vel": ("pos", "vel", hinf.TRANSLATION),
         "att": ("att", "rate", hinf.ROTATION), "rate": ("att", "rate", hinf.ROTATION)}
#: refuse a change whose nominal closed loop has rho >= 1 - MARGIN
MARGIN = 1e-9


def _block(values: Mapping[str, float], loop: str, axis: str) -> hinf.Block:
    return hinf.Block.from_fmu(*(values[f"K_{loop}_{p}[{axis}]"] for p in "ABCD"))


def spectral_radius(values: Mapping[str, float], outer: str, inner: str, axis: str,
                    spec: hinf.LoopSpec) -> float:
    """Largest |eigenvalue| of the nominal closed loop and of its inner loop alone."""
    k1, k2 = _block(values, outer, axis), _block(values, inner, axis)
    cl = hinf.interconnection(spec, k1, k2, weighted=False)
    ci = hinf.inner_loop(spec, k2, weighted=False)
    return max(cl.spectral_radius(), ci.spectral_radius())


def margin(values: Mapping[str, float], fmu_name: str) -> float | None:
    """1 - rho of the loop ``fmu_name`` belongs to (None: not a loop gain)."""
    m = _GAIN.match(fmu_name)
    if m is None:
        return None
    outer, inner, spec = _LOOP[m.group(1)]
    return 1.0 - spectral_radius(values, outer, inner, m.group(2), spec)


def guard(proposed: Mapping[str, float], fmu_name: str) -> str | None:
    """The reason a change to ``fmu_name`` is refused, or None."""
    mg = margin(proposed, fmu_name)
    if mg is None or mg > MARGIN:
        return None
    return f"margin {mg:.2g}"
