"""Whether a set of gains holds for an airframe, and gains for one where they do not.

After INDI every axis has the same design model (docs/robust_design.md): the vehicle's own
nominal mass and inertia normalize the loops, so the gains do not depend on them; what they
are certified for is a model set around an **actuator lag** tau (the first-order
A(s) = 1/(tau s + 1) the INDI loops see, within x[0.7, 1.3]) and a **mismatch** k between the
nominal and the true mass (+-30 %) and inertia (+-50 %).  An airframe's lag is the slowest
actuator that moves its force and torque: the motors, and the servos where it has them.

* :func:`certified_lags`: the lags the shipped gains are certified for (the design
  airframe's tau x [0.7, 1.3]); :func:`lag_warning` the one-line warning runs print when an
  airframe lies outside the set its gains are certified for;
* :func:`check`: the gains on this airframe's own model set (its lag x [0.7, 1.3], the same
  mismatch ranges): gamma per cascade (<= 1: every weighted requirement met on every
  model), margins at the actuator input;
* :func:`synthesize`: a structured H-infinity synthesis for this airframe's model set (the
  shipped structure and weights, the performance asked scaled down with the actuator
  bandwidth for slower actuators: :func:`synthesis_specs`), with a progress bar on a
  terminal; the result is a gains file (:func:`write_gains`, :func:`read_gains`) the
  commands take with ``--gains``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from plant import Airframe, load_airframe

LAG_SCALE = (0.7, 1.3)
"""The actuator-lag range of a design's model set, relative to its nominal lag."""
DESIGN_AIRFRAME = "paper_hexacopter"
"""The airframe the shipped gains were synthesized for."""
LOOPS = (("pos", "translation", "outer"), ("vel", "translation", "inner"),
         ("att", "rotation", "outer"), ("rate", "rotation", "inner"))
"""The controller's blocks: (loop, cascade, outer or inner block of the cascade)."""
GAINS_FORMAT = 1


class GainsFileError(ValueError):
    """A gains file that cannot be read, or is not one."""


def actuator_lag(airframe: Airframe) -> float:
    """The airframe's actuator lag (s): its motors' time constant, or its servos' where it
    has servos and they are slower."""
    return max(airframe.tau_motor, airframe.tau_servo) if airframe.tilting \
        else airframe.tau_motor


@cache
def design_lag() -> float:
    """The actuator lag (s) of the shipped gains' design airframe."""
    return actuator_lag(load_airframe(DESIGN_AIRFRAME))


def certified_lags(nominal: float | None = None) -> tuple[float, float]:
    """The lag range (s) gains synthesized at ``nominal`` (default: the shipped gains'
    design airframe) are certified for."""
    tau = design_lag() if nominal is None else nominal
    return LAG_SCALE[0] * tau, LAG_SCALE[1] * tau


def lag_warning(airframe: Airframe, gains: GainsFile | None = None) -> str | None:
    """A warning when ``airframe``'s actuator lag lies outside the range ``gains`` (default:
    the shipped gains) are certified for; None inside."""
    lo, hi = certified_lags(None if gains is None else gains.lag)
    lag = actuator_lag(airframe)
    if lo * (1 - 1e-12) <= lag <= hi * (1 + 1e-12):
        return None
    which = "the shipped gains are" if gains is None else f"the gains of {gains.path} are"
    return (f"airframe {airframe.name}: its actuator lag {lag * 1e3:.4g} ms lies outside the "
            f"{lo * 1e3:.4g}-{hi * 1e3:.4g} ms {which} certified for; check them with "
            f"`fullpose design {airframe.source or airframe.name}`")


@dataclass(frozen=True)
class LoopCheck:
    """One cascade's gains on a model set."""

    cascade: str
    gamma: float                  # max weighted H-infinity norm; <= 1: certified
    phase_margin: float           # deg, at the actuator input (nominal model)
    gain_margin_db: float
    disk_alpha: float
    crossover: dict[str, float]   # rad/s of each block's loop

    @property
    def certified(self) -> bool:
        """Whether gamma <= 1: every weighted requirement met on every model."""
        return self.gamma <= 1.0


@dataclass(frozen=True)
class DesignCheck:
    """The gains against one airframe's model set."""

    airframe: str
    lag: float
    certified_lags: tuple[float, float]
    loops: tuple[LoopCheck, ...]

    @property
    def certified(self) -> bool:
        """Whether both cascades are certified."""
        return all(lp.certified for lp in self.loops)

    def report(self) -> list[str]:
        """Lines for a terminal."""
        lo, hi = self.certified_lags
        inside = lo * (1 - 1e-12) <= self.lag <= hi * (1 + 1e-12)
        out = [f"airframe          {self.airframe}",
               f"actuator lag      {self.lag * 1e3:.4g} ms ({'inside' if inside else 'outside'}"
               f" the gains' certified {lo * 1e3:.4g}-{hi * 1e3:.4g} ms)"]
        for lp in self.loops:
            cross = ", ".join(f"{k} {v:.3g} rad/s" for k, v in lp.crossover.items())
            out.append(f"{lp.cascade:17s} gamma {lp.gamma:.4f} "
                       f"({'certified' if lp.certified else 'NOT certified'}); at the actuator "
                       f"input PM {lp.phase_margin:.1f} deg, GM {lp.gain_margin_db:.1f} dB, "
                       f"disk {lp.disk_alpha:.3f}; crossover {cross}")
        out.append("verdict           " + ("the gains hold for this airframe" if self.certified
                                           else "the gains are not certified for this airframe"))
        return out


@dataclass(frozen=True)
class GainsFile:
    """Gains for an airframe: the blocks as the controller's parameters, the lag they were
    synthesized at, and the synthesis' gammas."""

    path: str
    airframe: str
    lag: float
    blocks: dict[str, tuple[float, float, float, float]]
    gamma: dict[str, float]

    def controller_parameters(self) -> dict[str, float]:
        """The ``K_*`` parameters of the controller FMU."""
        from controller.fmu_parameters import block_parameters

        return block_parameters(self.blocks)


def _specs(lag: float) -> dict[str, Any]:
    """The shipped loop specifications (weights, model set) around the actuator lag ``lag``."""
    from controller import hinf

    return {s.name: dataclasses.replace(s, tau=lag) for s in hinf.SPECS}


def synthesis_specs(lag: float) -> dict[str, Any]:
    """What a synthesis for an airframe of actuator lag ``lag`` asks: the shipped weights
    around ``lag``; for actuators slower than the design airframe's (r = its lag / ``lag``
    < 1) the performance requirements scaled with the actuator bandwidth: the sensitivity
    bandwidths w1, w2 and the disturbance bandwidth wd by r, the disturbance bound d_max by
    1 / r (a slower vehicle is asked for proportionally slower tracking; the robustness
    weight at the actuator input stays).  With the shipped weights a 40 ms lag reaches gamma
    1.09 / 1.11 (not certified), with the scaled ones 0.71 / 0.61."""
    r = min(1.0, design_lag() / lag)
    return {name: dataclasses.replace(s, w1=s.w1 * r, w2=s.w2 * r, wd=s.wd * r,
                                      d_max=s.d_max / r, start=s.start if r == 1.0 else ())
            for name, s in _specs(lag).items()}


def _loop_check(design: Any) -> LoopCheck:
    m = design.margins["input"]
    gm = 20 * math.log10(m.gain_margin) if math.isfinite(m.gain_margin) else math.inf
    return LoopCheck(design.spec.name, float(design.gamma), float(m.phase_margin), gm,
                     float(m.disk_margin), {k: float(v) for k, v in design.bandwidth.items()})


def shipped_blocks() -> dict[str, tuple[float, float, float, float]]:
    """The shipped gains as {loop: (A, B, C, D)}."""
    from controller.gains_defaults import CACHE

    blocks = json.loads(CACHE.read_text(encoding="utf-8"))["blocks"]
    return {k: (float(v[0]), float(v[1]), float(v[2]), float(v[3])) for k, v in blocks.items()}


def check(airframe: Airframe, gains: GainsFile | None = None) -> DesignCheck:
    """``gains`` (default: the shipped ones) on ``airframe``'s model set, against the
    requirements they were synthesized for (:func:`synthesis_specs` of their lag)."""
    from controller import hinf

    blocks = shipped_blocks() if gains is None else gains.blocks
    lag = actuator_lag(airframe)
    weights_lag = design_lag() if gains is None else gains.lag
    out = []
    for name, asked in synthesis_specs(weights_lag).items():
        spec = dataclasses.replace(asked, tau=lag)
        outer = next(loop for loop, c, w in LOOPS if c == name and w == "outer")
        inner = next(loop for loop, c, w in LOOPS if c == name and w == "inner")
        design = hinf.analyse(spec, hinf.Block.from_fmu(*blocks[outer]),
                              hinf.Block.from_fmu(*blocks[inner]))
        out.append(_loop_check(design))
    return DesignCheck(airframe.name, lag, certified_lags(None if gains is None else gains.lag),
                       tuple(out))


def synthesize(airframe: Airframe, progress: bool | None = None) -> tuple[GainsFile,
                                                                           DesignCheck]:
    """Gains synthesized for ``airframe``'s model set (about 10-20 s per cascade), and their
    check.  A progress bar (one step per cascade) shows on a terminal, quiet in pipes."""
    from tqdm import tqdm

    from controller import hinf

    lag = actuator_lag(airframe)
    blocks: dict[str, tuple[float, float, float, float]] = {}
    gamma: dict[str, float] = {}
    loops = []
    specs = synthesis_specs(lag)
    with tqdm(total=len(specs), desc=f"synthesis for {airframe.name}", unit="cascade",
              disable=None if progress is None else not progress) as bar:
        for name, spec in specs.items():
            bar.set_postfix_str(name)
            design = hinf.synthesize(spec)
            for loop, cascade, which in LOOPS:
                if cascade == name:
                    blk = design.outer if which == "outer" else design.inner
                    blocks[loop] = blk.fmu()
            gamma[name] = float(design.gamma)
            loops.append(_loop_check(design))
            bar.update(1)
    gains = GainsFile("", airframe.name, lag, blocks, gamma)
    return gains, DesignCheck(airframe.name, lag, certified_lags(lag), tuple(loops))


def write_gains(path: Path, gains: GainsFile) -> Path:
    """The gains file (JSON), written whole (a temporary file moved into place)."""
    doc = {"format": GAINS_FORMAT, "airframe": gains.airframe, "actuator_lag": gains.lag,
           "certified_lags": list(certified_lags(gains.lag)), "gamma": gains.gamma,
           "blocks": {k: list(v) for k, v in gains.blocks.items()}}
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def read_gains(path: str | Path) -> GainsFile:
    """A gains file written by :func:`write_gains`; GainsFileError naming the file, the field
    and the reason otherwise."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise GainsFileError(f"{p}: gains file not found") from None
    except (OSError, ValueError) as e:
        raise GainsFileError(f"{p}: not a readable gains file ({e})") from None
    if not isinstance(doc, dict) or doc.get("format") != GAINS_FORMAT:
        raise GainsFileError(f"{p}: not a fullpose gains file (format {GAINS_FORMAT})")
    blocks = doc.get("blocks")
    if not isinstance(blocks, Mapping) or set(blocks) != {loop for loop, _, _ in LOOPS}:
        raise GainsFileError(f"{p}: field 'blocks': expected the loops "
                             f"{', '.join(loop for loop, _, _ in LOOPS)}")
    parsed: dict[str, tuple[float, float, float, float]] = {}
    for loop, values in blocks.items():
        if not (isinstance(values, list) and len(values) == 4 and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in values)):
            raise GainsFileError(f"{p}: field 'blocks.{loop}': expected 4 finite numbers "
                                 "(A, B, C, D)")
        if not -1.0 < values[0] < 1.0:
            raise GainsFileError(f"{p}: field 'blocks.{loop}': A = {values[0]!r} must lie in "
                                 "(-1, 1) (a stable block)")
        parsed[loop] = (float(values[0]), float(values[1]), float(values[2]), float(values[3]))
    lag = doc.get("actuator_lag")
    if isinstance(lag, bool) or not isinstance(lag, (int, float)) or not lag > 0:
        raise GainsFileError(f"{p}: field 'actuator_lag': expected a positive number of s")
    raw = doc.get("gamma")
    gamma = raw if isinstance(raw, dict) else {}
    return GainsFile(str(p), str(doc.get("airframe", "")), float(lag), parsed,
                     {str(k): float(v) for k, v in gamma.items()
                      if isinstance(v, (int, float))})
