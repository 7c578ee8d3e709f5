"""Benchmark: the bridge's pacing under load (prints figures, asserts nothing).

Four cases, each a bridge at speed 1 flying a position setpoint in OFFBOARD for
``--duration`` simulated seconds, with the host busy (``--busy`` Python busy loops in other
processes, default 2: both cores of the CI machine) and with or without a fuzzer process
sending ``--rate`` datagrams/s (default 2,500: random bytes, mutated and truncated
setpoints, NaN setpoints and valid setpoints, as the fuzz test of
tests/test_mavlink_bridge/test_mavlink_bridge.py).  Each case runs with the input time
budget (the default) and without it (the pre-budget behaviour: RX_TIME_LATE = RX_TIME_SHARE
= inf, a count-only bound).  Reported: the worst lag behind wall time, chunks late by more
than a chunk period, datagrams handled, and whether OFFBOARD survived (the ground station's
20 Hz setpoints compete with the flood).

Usage: python tests/bench/bench_pacing.py [--duration 10] [--busy 2] [--rate 2500]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import os
import socket
import statistics
import sys
import threading
import time
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"

from pymavlink import mavutil

from mavlink_bridge import bridge as bridge_mod
from mavlink_bridge.bridge import Bridge, BridgeConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: the shared helpers
from helpers.mavlink_harness import POS_ONLY, fuzz_datagrams


def _busy(stop: mp.synchronize.Event) -> None:
    x = 0
    while not stop.is_set():
        for _ in range(10000):
            x += 1


def _fuzz(port: int, rate: float, stop: mp.synchronize.Event) -> None:
    datagrams = fuzz_datagrams(mavutil.mavlink.MAVLink(None, 255, 190))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    t0, sent = time.perf_counter(), 0
    while not stop.is_set():
        if sent > (time.perf_counter() - t0) * rate:
            time.sleep(0.0005)
            continue
        data = next(datagrams)
        try:
            sock.sendto(data, ("127.0.0.1", port))
        except OSError:
            pass
        sent += 1


def run_case(duration: float, busy: int, rate: float, budget: bool) -> dict[str, Any]:
    saved = bridge_mod.RX_TIME_LATE, bridge_mod.RX_TIME_SHARE
    if not budget:
        bridge_mod.RX_TIME_LATE = bridge_mod.RX_TIME_SHARE = math.inf
    gcs_port = _free_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{gcs_port}", source_system=255,
                                     source_component=190, dialect="common")
    b = Bridge(BridgeConfig(urls=[f"udpout:127.0.0.1:{gcs_port}"], speed=1.0,
                            duration=duration))
    dest = b.endpoints[0].sock.getsockname()[1]
    stop = mp.Event()
    procs = [mp.Process(target=_busy, args=(stop,), daemon=True) for _ in range(busy)]
    if rate > 0:
        procs.append(mp.Process(target=_fuzz, args=(dest, rate, stop), daemon=True))
    b.armed, b.mode, b.last_setpoint = True, "OFFBOARD", 0.0
    keep = threading.Event()

    def setpoints() -> None:  # a ground station streaming at 20 Hz from a thread
        while not keep.is_set():
            gcs.mav.set_position_target_local_ned_send(0, 1, 1, 1, POS_ONLY, 0.3, 0.0, -3.0,
                                                       0, 0, 0, 0, 0, 0, 0, 0)
            while gcs.recv_match(blocking=False) is not None:
                pass
            time.sleep(0.05)

    try:
        for p in procs:
            p.start()
        th = threading.Thread(target=setpoints, daemon=True)
        th.start()
        time.sleep(0.5)  # the load is up
        stats = b.run()
        keep.set()
        th.join(2)
        return {"max_lag_ms": 1e3 * stats.max_lag, "late": stats.late_chunks,
                "chunks": stats.chunks, "datagrams": stats.datagrams,
                "speed": stats.achieved_speed,
                "lost": sum("offboard lost" in t for t in b.events), "mode": b.mode}
    finally:
        stop.set()
        for p in procs:
            p.join(5)
        b.close()
        gcs.close()
        bridge_mod.RX_TIME_LATE, bridge_mod.RX_TIME_SHARE = saved


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="simulated s per case")
    parser.add_argument("--busy", type=int, default=2, help="busy-loop processes")
    parser.add_argument("--rate", type=float, default=2500.0, help="fuzz datagrams/s")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each case, interleaved")
    args = parser.parse_args()
    print(f"host: {os.cpu_count()} cpus, load average {os.getloadavg()[0]:.2f} at start; "
          f"{args.busy} busy processes; {args.duration:g} s per case")
    print(f"{'input budget':13s} {'fuzzer':>8s} {'max lag ms':>11s} {'late chunks':>14s} "
          f"{'datagrams':>10s} {'speed':>6s}  mode at end (offboard losses)")
    lags: dict[tuple[float, bool], list[float]] = {}
    for _ in range(args.repeat):
        for rate in (0.0, args.rate):
            for budget in (False, True):
                r = run_case(args.duration, args.busy, rate, budget)
                lags.setdefault((rate, budget), []).append(r["max_lag_ms"])
                print(f"{'time+count' if budget else 'count only':13s} {rate:8.0f} "
                      f"{r['max_lag_ms']:11.1f} {r['late']:6d}/{r['chunks']:<7d} "
                      f"{r['datagrams']:10d} {r['speed']:6.3f}  {r['mode']} ({r['lost']})",
                      flush=True)
    print(f"\nworst lag over {args.repeat} runs (median), ms; load average at end "
          f"{os.getloadavg()[0]:.2f}")
    for (rate, budget), v in lags.items():
        v = sorted(v)
        print(f"{'time+count' if budget else 'count only':13s} fuzzer {rate:6.0f}/s: "
              f"worst {v[-1]:7.1f}  median {statistics.median(v):7.1f}")


if __name__ == "__main__":
    main()
