"""Benchmark: what the 3-D view (Rerun) costs.

1. Replay: scenario 1 (100 s) sent to a recording file, after the run: the wall time of
   building and writing it, and of the whole ``fullpose view RESULTS --save`` command.
2. Live: ``fullpose fly`` at speed 1.0 (a bridge in this process, no ground station), once
   without the view and once writing it (``--save``): CPU seconds of this process (every
   thread, Rerun's own included) per simulated second, the view's share of fly's.

    python tests/bench/bench_view.py [--fly-seconds 30]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mavlink_bridge.bridge import Bridge, BridgeConfig
from orchestrator.master import run
from orchestrator.output.view import LiveView, replay
from orchestrator.runner import prepare, run_scenario


def fly_cpu(seconds: float, rrd: Path | None) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of a bridge flying ``seconds`` at speed 1."""
    bridge = Bridge(BridgeConfig(urls=["udpout:127.0.0.1:9"], speed=1.0, duration=seconds))
    view = None
    if rrd is not None:
        view = LiveView(bridge.airframe, rrd, start=bridge.config.pos0)

        def on_chunk(b: Bridge) -> None:
            t = b.session.time
            view.log(t, b.state, b.ref.pos, b.ref.euler,
                     {"mode": b.mode, "armed": b.armed})

        bridge.on_chunk = on_chunk
    c0, w0 = time.process_time(), time.perf_counter()
    try:
        bridge.run()
        if view is not None:
            view.close()
    finally:
        bridge.close()
    return time.process_time() - c0, time.perf_counter() - w0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--fly-seconds", type=float, default=30.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        sc = prepare("hover_varying_orientation")
        result = run(sc)
        rep = replay(result, sc.airframe, save=out / "s1.rrd")
        size = (out / "s1.rrd").stat().st_size / 1e6
        print(f"replay, 100 s scenario 1: {rep.seconds:.2f} s to build and write "
              f"({rep.pose_rows} poses, {rep.series_rows} series rows, {size:.1f} MB)")
        run_scenario(sc, out / "res", plots=False)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "orchestrator.cli", "view", str(out / "res"),
                        "--save", str(out / "again.rrd")], check=True, capture_output=True)
        print(f"fullpose view RESULTS --save: {time.perf_counter() - t0:.2f} s wall "
              "(process start and Parquet read included)")
        cpu0, wall0 = fly_cpu(args.fly_seconds, None)
        cpu1, wall1 = fly_cpu(args.fly_seconds, out / "fly.rrd")
        s = args.fly_seconds
        print(f"fly at speed 1.0 for {s:g} s: {cpu0 / s:.4f} CPU s per simulated s without "
              f"the view ({wall0:.1f} s wall), {cpu1 / s:.4f} with it ({wall1:.1f} s wall)")
        print(f"the live view costs {100 * (cpu1 - cpu0) / cpu0:.1f} % of fly's CPU "
              f"({(cpu1 - cpu0) / s * 1e3:.1f} ms per simulated second)")


if __name__ == "__main__":
    main()
