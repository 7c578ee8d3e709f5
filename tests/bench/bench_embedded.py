"""The controller on the emulated Cortex-M7: instructions per sample and what they cost on a
flight controller, and how far the processor-in-the-loop runs are from the FMU's.

    python tests/bench/bench_embedded.py [--duration S] [--scenarios a,b,c]

For each scenario: the run with the controller image under QEMU (``fullpose run --pil``) and
the run with the controller FMU, then per sample the instructions of the whole controller
call (``fpc_step``) and of the guidance and allocation QPs alone (the controller's own
timing outputs t_guid, t_alloc, read on the board timer), mean / p99 / max, as microseconds
at 480 MHz with 1 cycle per instruction (orchestrator/pil/cost.py says why) and as a share
of the 2 ms period; then the largest difference of the rotor commands and of the positions
to the FMU run, and which of libm's functions gave other results than the host's (glibc's,
through Python's math) on the same arguments in the run (the tracing image records every
call).  The host's own time per sample (the FMU's t_step on this machine) is printed beside
as the peer.  Also: flash, RAM and stack of the image.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from orchestrator.master import CoSimulation  # noqa: E402
from orchestrator.pil.build import build_embedded  # noqa: E402
from orchestrator.pil.cost import CLOCK_HZ, CPI, microseconds, period_share  # noqa: E402
from orchestrator.pil.instance import PilController  # noqa: E402
from orchestrator.pil.target import LIBM, instructions  # noqa: E402
from orchestrator.scenario.catalogue import load_scenario  # noqa: E402
from orchestrator.scenario.model import Scenario  # noqa: E402
from orchestrator.sim.fmu3 import open_fmu  # noqa: E402
from plant import plant_fmu  # noqa: E402

DEFAULT = ("hover", "hover_varying_orientation", "rotor_failure_detected",
           "fixed_tilt_translation")


def row(label: str, ins: np.ndarray) -> str:
    """mean / p99 / max instructions and their time and period share."""
    mean, p99, worst = float(ins.mean()), float(np.percentile(ins, 99)), float(ins.max())
    return (f"  {label:11s} {mean:9.0f} {p99:9.0f} {worst:9.0f}   {microseconds(mean):7.1f} "
            f"{microseconds(p99):7.1f} {microseconds(worst):7.1f} us   "
            f"{100 * period_share(worst):5.2f} %")


def libm_report(sc: Scenario, trace_elf: Path) -> str:
    """The run again on the tracing image: per libm function, the calls and how many gave
    another result than the host's C library on the same arguments, and by how many ulps."""
    plant = open_fmu(plant_fmu(2), "plant")
    ctrl = PilController(trace_elf, trace_libm=True)
    try:
        CoSimulation(sc, fmus=(plant, ctrl)).run()
    finally:
        plant.close()
        ctrl.close()
    calls = np.concatenate(ctrl.libm_calls) if ctrl.libm_calls else np.zeros((0, 4))
    parts = []
    for i, name in enumerate(LIBM):
        sel = calls[calls[:, 0] == i]
        if not len(sel):
            continue
        fn = getattr(math, name)
        want = np.array([fn(x, y) if name in ("atan2", "hypot") else fn(x)
                         for _, x, y, _ in sel])
        ulps = np.abs(sel[:, 3] - want) / np.spacing(np.abs(want))
        parts.append(f"{name} {int(np.count_nonzero(sel[:, 3] != want))} of {len(sel)} "
                     f"(max {ulps.max():.0f} ulp)")
    dropped = f"; {ctrl.libm_dropped} calls not recorded" if ctrl.libm_dropped else ""
    return "; ".join(parts) + dropped


def main() -> int:
    """Print the table; exit 0."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--scenarios", default=",".join(DEFAULT))
    args = ap.parse_args()
    built = build_embedded(Path(ROOT / "build" / "embedded-m7"))
    m = built.memory
    print(f"image {built.elf}: flash {m.flash} B, RAM {m.ram} B (+ {m.stack} B stack region); "
          f"libfpc.a {built.library_flash} B code and constants, {built.library_ram} B static data")
    print(f"time at {CLOCK_HZ / 1e6:.0f} MHz, {CPI:g} cycle per instruction; share of the "
          "2 ms period at the worst sample")
    for name in args.scenarios.split(","):
        sc = load_scenario(name)
        sc = dataclasses.replace(sc, duration=min(args.duration, sc.duration))
        fmu = CoSimulation(sc, timing=True).run()  # (timing changes no result)
        t0 = time.perf_counter()
        pil_run = CoSimulation(sc, timing=True, pil=built.elf)
        res = pil_run.run()
        wall = time.perf_counter() - t0
        on = res.meta["controller_on"]
        cols = res.columns
        data, ref = np.asarray(res.data), np.asarray(fmu.data)
        rows = min(len(data), len(ref))
        shift = int(str(on["machine"]).rsplit("=", 1)[1])

        def ticks_of(col: str, data: np.ndarray = data, rows: int = rows,
                     cols: tuple[str, ...] = tuple(cols), shift: int = shift) -> np.ndarray:
            # the board timer's seconds (pil/board.c) back to ticks, then instructions
            return np.asarray(instructions(np.round(data[1:rows, cols.index(col)] * 25e6),
                                           shift))

        step_ins = ticks_of("ctrl.t_step")
        print(f"\n{name} ({sc.duration:g} s, airframe {sc.airframe.name}, {rows - 1} samples, "
              f"{wall:.1f} s wall)")
        print(f"  {'':11s} {'mean':>9s} {'p99':>9s} {'max':>9s}   {'mean':>7s} {'p99':>7s} "
              f"{'max':>7s}      period")
        print(row("sample", step_ins))
        print(row("guidance QP", ticks_of("ctrl.t_guid")))
        print(row("alloc. QP", ticks_of("ctrl.t_alloc")))
        host = np.asarray(fmu.data)[1:, list(fmu.columns).index("ctrl.t_step")] * 1e6
        print(f"  peer: the FMU's sample on this host {host.mean():.1f} us mean, "
              f"{np.percentile(host, 99):.1f} p99, {host.max():.1f} max: the target at "
              f"{CLOCK_HZ / 1e6:.0f} MHz takes "
              f"{microseconds(float(step_ins.mean())) / host.mean():.0f}x as long")
        cmd = [i for i, c in enumerate(cols) if c.startswith(("ctrl.omega_cmd", "ctrl.alpha_cmd",
                                                              "ctrl.beta_cmd"))]
        pos = [cols.index(f"plant.pos[{k}]") for k in (1, 2, 3)]
        dcmd = np.abs(data[:rows, cmd] - ref[:rows, cmd])
        rel = dcmd / np.maximum(np.abs(ref[:rows, cmd]), 1e-300)
        dpos = np.abs(data[:rows, pos] - ref[:rows, pos]).max()
        same = int(np.count_nonzero(np.all(dcmd == 0, axis=1)))
        print(f"  to the FMU: commands equal to the bit in {same} of {rows} samples, largest "
              f"difference {dcmd.max():.3g} ({rel.max():.2g} relative); positions within "
              f"{dpos:.3g} m")
        print("  libm calls whose result differs from the host's: "
              + libm_report(sc, built.trace_elf))
        print(f"  fpc_start {on['start_instructions']:.0f} instructions "
              f"({microseconds(float(on['start_instructions'])) / 1e3:.1f} ms); stack "
              f"{on['stack_bytes']} B per sample, {on['start_stack_bytes']} B in fpc_start; "
              f"heap {on['heap_bytes_in_samples']} B and {on['format_calls_in_samples']} "
              "text formatting calls during the samples")
    return 0


if __name__ == "__main__":
    sys.exit(main())
