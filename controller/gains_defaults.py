"""Generate the controller FMU's default gains from the structured H-infinity synthesis.

    python -m controller.gains_defaults          # runs the synthesis, (re)writes the header
    python -m controller.gains_defaults --check  # exit 1 if the committed header is stale

The header is fmu_src/controller/default_gains.h: the design constants hinf.py defines (the
controller's default Ts and measurement filter, FP_DESIGN_*), and static const double arrays
fp_default_K_{pos,vel,att,rate}_{A,B,C,D}[3] (same block on the three axes: after INDI the
axes have the same design model), printed with "%.17g", plus the achieved gammas and margins in
the header comment.  The synthesis (controller/hinf.py) is deterministic: fixed starts and a
seeded generator; it takes ~30-60 s, so ``--check`` does not rerun it by default: the header
records a hash of the synthesis inputs, and ``--check`` recomputes the hash and verifies that
the header's numbers match the cached result file next to it (default_gains.json, written by
the command).  The hash covers the hinf.py/lti.py sources and this file, and the values the
synthesis reads at run time (:func:`synthesis_inputs`: sample time, filter, actuator time
constant, every loop spec with its weights and model set, the default arguments such as the
grid size, iterations and seed), so that changing any of them, in the source or at run time,
makes the check fail.  ``--check --full`` reruns the synthesis and compares the numbers
(relative 1e-6).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import inspect
import json
import math
import sys
from pathlib import Path

import numpy as np

from controller import hinf, lti
from controller.fmu_parameters import block_parameters

COMMAND = "python -m controller.gains_defaults"
ROOT = Path(__file__).resolve().parents[1]
HEADER = ROOT / "fmu_src" / "controller" / "default_gains.h"
CACHE = ROOT / "controller" / "default_gains.json"
SOURCES = ("controller/hinf.py", "controller/lti.py")  # the code that computes the gains
LOOPS = (("pos", "translation", "outer"), ("vel", "translation", "inner"),
         ("att", "rotation", "outer"), ("rate", "rotation", "inner"))


def synthesis_inputs() -> dict[str, object]:
    """Every value the synthesis reads from hinf and lti at run time: their module constants
    (upper-case names: TS, TAU_ACT, FILT_WN, FILT_ZETA, the LoopSpecs with their weights, model
    sets and actuator tau, ...) and the default arguments of their functions and methods
    (grid size, rounds, iterations, seed, norm tolerances, the Ts defaults, ...)."""
    out: dict[str, object] = {}
    for mod in (hinf, lti):
        for name, value in vars(mod).items():
            where = f"{mod.__name__}.{name}"
            if name.isupper() and not callable(value):  # (not the imported class SS)
                out[where] = value
            elif inspect.isclass(value) and value.__module__ == mod.__name__:
                for attr, member in vars(value).items():
                    if not attr.startswith("__"):
                        _add_defaults(out, f"{where}.{attr}", member)
            else:
                _add_defaults(out, where, value)
    return out


def _add_defaults(out: dict[str, object], where: str, obj: object) -> None:
    func = inspect.unwrap(getattr(obj, "__func__", obj))  # type: ignore[arg-type]  # staticmethod, lru_cache
    if inspect.isfunction(func) and func.__module__ in (hinf.__name__, lti.__name__):
        defaults = {p.name: p.default for p in inspect.signature(func).parameters.values()
                    if p.default is not inspect.Parameter.empty}
        if defaults:
            out[f"{where}()"] = defaults


def _canonical(value: object) -> str:
    """Text of a value for the hash; floats to 12 significant digits, so that a last-digit
    difference of a platform's libm (math.log in the specs' start points) does not count."""
    if value is None or isinstance(value, (bool, int, str)):
        return repr(value)
    if isinstance(value, float):
        return format(value, ".12g")
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_canonical(v)}" for k, v in sorted(value.items())) + "}"
    if isinstance(value, (tuple, list, np.ndarray)):
        return "[" + ", ".join(_canonical(v) for v in value) + "]"
    raise TypeError(f"synthesis input of type {type(value).__name__}: add it to _canonical")


def inputs_hash() -> str:
    """SHA-256 of everything the synthesis reads: the sources of hinf.py and lti.py and this
    module, and the run-time inputs (synthesis_inputs)."""
    h = hashlib.sha256()
    for rel in SOURCES:
        h.update(rel.encode())
        h.update((ROOT / rel).read_bytes().replace(b"\r\n", b"\n"))
    for name, value in sorted(synthesis_inputs().items()):
        h.update(f"{name} = {_canonical(value)}\n".encode())
    return h.hexdigest()[:16]


def run_synthesis() -> dict:
    """{'hash', 'blocks': {loop: [A, B, C, D]}, 'report': {...}} from a fresh synthesis."""
    designs = hinf.design_all()
    blocks, report = {}, {}
    for loop, cascade, which in LOOPS:
        d = designs[cascade]
        blk = d.outer if which == "outer" else d.inner
        blocks[loop] = list(blk.fmu())
    for name, d in designs.items():
        report[name] = {
            "gamma": d.gamma,
            "spectral_radius": d.spectral_radius,
            "bandwidth": d.bandwidth,
            "margins": {k: {"crossover": m.crossover, "gain_margin": m.gain_margin,
                            "phase_margin": m.phase_margin, "disk_alpha": m.disk_margin,
                            "disk_gain": list(m.disk_gain), "disk_phase": m.disk_phase}
                        for k, m in d.margins.items()},
            "summary": hinf.summary(d),
        }
    design = {"TS": hinf.TS, "FILT_WN": hinf.FILT_WN, "FILT_ZETA": hinf.FILT_ZETA}
    return {"hash": inputs_hash(), "design": design, "blocks": blocks, "report": report}


def _f(x: float) -> str:
    return f"{x:.17g}"


def _db(x: float) -> str:
    return "inf" if not math.isfinite(x) else f"{20 * math.log10(x):.1f} dB"


def render(result: dict) -> str:
    """The header default_gains.h of a synthesis result."""
    lines = [
        "/*",
        f" * GENERATED FILE - do not edit.  Regenerate with:   {COMMAND}",
        f" * Freshness: {COMMAND} --check (tests/test_controller/test_hinf.py runs the check).",
        f" * Synthesis inputs hash: {result['hash']}",
        " *",
        " * Default first-order blocks x+ = A x + B e, y = C x + D e (Ts = 2 ms, same on the",
        " * three axes) of the FullPoseController from the structured H-infinity synthesis",
        " * (controller/hinf.py, docs/robust_design.md): INDI design model with the actuator",
        " * A(s) = 1/(tau s + 1), the filter H(s), ZOH and the computational delay per cascade;",
        " * multi-model (mass/inertia mismatch, actuator tau +-30 %); gamma < 1 meets all weights.",
    ]
    for name in ("translation", "rotation"):
        rep = result["report"][name]
        lines.append(f" * {name}: gamma = {rep['gamma']:.4f}")
        for where in ("input", "inner", "outer"):
            m = rep["margins"][where]
            lines.append(f" *   loop at {where}: crossover {m['crossover']:.3g} rad/s, GM "
                         f"{_db(m['gain_margin'])}, PM {m['phase_margin']:.1f} deg, disk "
                         f"margin {m['disk_alpha']:.3f} (gain {m['disk_gain'][0]:.2f}.."
                         f"{m['disk_gain'][1]:.2f}, phase +-{m['disk_phase']:.1f} deg)")
    lines += [" */", "#ifndef FP_DEFAULT_GAINS_H", "#define FP_DEFAULT_GAINS_H", "",
              "/* The design constants the gains are made for (controller/hinf.py): the",
              " * controller's defaults of Ts, filt_wn and filt_zeta. */"]
    for name, value in sorted(result["design"].items()):
        lines.append(f"#define FP_DESIGN_{name} {float(value)!r}")  # shortest exact
    lines.append("")
    for loop, _, _ in LOOPS:
        for name, v in zip("ABCD", result["blocks"][loop], strict=True):
            lines.append(f"static const double fp_default_K_{loop}_{name}[3] = "
                         f"{{{_f(v)}, {_f(v)}, {_f(v)}}};")
    lines += ["", "#endif /* FP_DEFAULT_GAINS_H */", ""]
    return "\n".join(lines)


def controller_parameters(blocks: dict | None = None) -> dict[str, float]:
    """The shipped gains as controller FMU parameter overrides {"K_pos_A[1]": ...}."""
    if blocks is None:
        blocks = json.loads(CACHE.read_text())["blocks"]
    return block_parameters(blocks)


def check(full: bool = False) -> tuple[bool, str]:
    """(up to date, message).  The synthesis inputs are compared first: they and the shipped
    gains file are in the installed package too, the C header only in a checkout."""
    if not CACHE.is_file():
        return False, f"{CACHE.name} is missing: run {COMMAND}"
    cached = json.loads(CACHE.read_text())
    if cached.get("hash") != inputs_hash():
        return False, f"synthesis inputs changed since {HEADER.name} was generated: run {COMMAND}"
    if not HEADER.is_file():
        return False, (f"{HEADER} is missing (an installed package has no fmu_src/: check "
                       f"from a checkout): run {COMMAND}")
    if HEADER.read_text() != render(cached):
        return False, f"{HEADER} does not match {CACHE.name}: run {COMMAND}"
    if full:
        fresh = run_synthesis()
        for loop in fresh["blocks"]:
            for a, b in zip(fresh["blocks"][loop], cached["blocks"][loop], strict=True):
                if not math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9):
                    return False, f"a fresh synthesis gives other K_{loop}: run {COMMAND}"
    return True, f"{HEADER} is up to date"


def main(argv: list[str] | None = None) -> int:
    """The command: run the synthesis and write the header, or --check it; the exit status."""
    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="do not write; exit 1 if the header is stale")
    parser.add_argument("--full", action="store_true",
                        help="with --check: rerun the synthesis and compare the numbers")
    args = parser.parse_args(argv)
    if args.check:
        ok, msg = check(args.full)
        print(msg, file=sys.stdout if ok else sys.stderr)
        return 0 if ok else 1
    text = json.dumps(run_synthesis(), indent=1, sort_keys=True) + "\n"
    result = json.loads(text)
    CACHE.write_text(text)
    HEADER.write_text(render(result))
    for rep in result["report"].values():
        print(rep["summary"])
    print(f"wrote {HEADER} and {CACHE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
