"""The MAVLink tests' ground station: a Bridge in a thread and one pymavlink client that
listens for it on a free loopback port (tests/test_mavlink_*.py; conftest.py puts this
folder on sys.path, since pytest's importlib mode keeps test modules apart).  Importers set
MAVLINK20=1 before importing it, as pymavlink picks its dialect module when first imported."""

from __future__ import annotations

import math
import random
import socket
import subprocess
import sys
import sysconfig
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from mavlink_bridge.bridge import Bridge, BridgeConfig
from mavlink_bridge.geometry import euler_to_quat

ROOT = Path(__file__).resolve().parents[2]
POS_ONLY = 0b0000_1101_1111_1000  # x, y, z, yaw used
ATT_ONLY = 0b0100_0111  # quaternion used (rates and throttle ignored)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def fuzz_datagrams(mav: Any, seed: int = 1234) -> Iterator[bytes]:
    """Hostile datagrams without end, built with the pymavlink encoder ``mav``: random bytes
    (30 %), a valid position setpoint with 1-4 bytes changed, a third of them truncated
    (30 %), the setpoint with x NaN (10 %), a MAVLink 2 start byte and noise (10 %), and the
    valid setpoint itself (20 %: a flood)."""
    rng = random.Random(seed)
    good = mav.set_position_target_local_ned_encode(
        0, 1, 1, 1, POS_ONLY, 0.3, 0.0, -3.0, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)
    nan = mav.set_position_target_local_ned_encode(
        0, 1, 1, 1, POS_ONLY, math.nan, 0.0, -3.0, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)
    while True:
        kind = rng.random()
        if kind < 0.3:
            yield rng.randbytes(rng.randint(0, 300))
        elif kind < 0.6:
            b = bytearray(good)
            for _ in range(rng.randint(1, 4)):
                b[rng.randrange(len(b))] = rng.randrange(256)
            yield bytes(b[: rng.randint(1, len(b))]) if rng.random() < 0.3 else bytes(b)
        elif kind < 0.7:
            yield nan
        elif kind < 0.8:
            yield bytes([0xFD]) + rng.randbytes(rng.randint(0, 280))
        else:
            yield good


def stream(f: Flight, seconds: float, send: Callable[[], None]) -> None:
    """Call ``send`` every 20 ms of wall time for ``seconds``, draining what comes back."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        send()
        f.drain()
        time.sleep(0.02)


@contextmanager
def mavsdk_session(**config: Any) -> Iterator[tuple[Bridge, Any, list[Any]]]:
    """A bridge in a thread (speed 2, 120 s unless ``config`` says otherwise; ``config`` goes
    to BridgeConfig) and MAVSDK connected to it as a ground station: yields (bridge, the
    discovered system, a list for the plugins the test makes); after the test the plugins and
    MAVSDK are destroyed and the bridge is stopped and closed."""
    from mavsdk import ComponentType, Configuration, ConnectionResult, Mavsdk

    port = free_port()
    config = {"speed": 2.0, "duration": 120.0, "start": "air", **config}
    bridge = Bridge(BridgeConfig(urls=[f"udpout:127.0.0.1:{port}"], **config))
    thread = threading.Thread(target=bridge.run, daemon=True)
    thread.start()
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    plugins: list[Any] = []
    try:
        result = sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        assert result == ConnectionResult.SUCCESS, result
        system = sdk.first_autopilot(10.0)
        assert system is not None, "no autopilot discovered"
        yield bridge, system, plugins
    finally:
        for plugin in plugins:
            plugin.destroy()
        sdk.destroy()
        bridge.stop()
        thread.join(timeout=10)
        bridge.close()
    assert not thread.is_alive()


def flight_fixture(make: Callable[[], Flight]) -> Any:
    """The ``flight`` fixture of a test module: a flight made by ``make`` for each test,
    closed after it (``flight = harness.flight_fixture(Flight)``)."""

    @pytest.fixture
    def flight() -> Any:
        f = make()
        yield f
        f.close()

    return flight


class Flight:
    """``config`` goes to BridgeConfig (``urls`` aside: the client's port)."""

    def __init__(self, speed: float = 4.0, system: int = 255, component: int = 190,
                 dialect: str = "common", **config: Any) -> None:
        self.port = free_port()
        self.gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.port}",
                                              source_system=system,
                                              source_component=component, dialect=dialect)
        self.src = (system, component)
        self._chunks: dict[int, dict[int, str]] = {}
        url = f"udpout:127.0.0.1:{self.port}"
        config.setdefault("duration", 120.0)
        config.setdefault("start", "air")  # hovering at pos0 (ground flights say "ground")
        self.bridge = Bridge(BridgeConfig(urls=[url], speed=speed, **config))
        self.thread = threading.Thread(target=self.bridge.run, daemon=True)
        self.thread.start()
        self.texts: list[str] = []
        self.wait("HEARTBEAT", 10.0)

    def bridge_port(self) -> int:
        """The UDP port the bridge's endpoint listens on (where a stranger would send)."""
        return int(self.bridge.endpoints[0].sock.getsockname()[1])

    def close(self) -> None:
        self.bridge.stop()
        self.thread.join(timeout=10)
        self.bridge.close()
        self.gcs.close()

    def wait(self, kind: str, timeout: float = 5.0, cond: Callable[[Any], bool] = lambda m: True,
             during: Callable[[], None] | None = None) -> Any:
        """The first ``kind`` message meeting ``cond`` (``during`` runs between reads)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if during is not None:
                during()
            m = self.gcs.recv_match(blocking=True, timeout=0.02)
            if m is None:
                continue
            if m.get_type() == "STATUSTEXT" and not self._whole_text(m):
                continue  # a chunk of a longer text: the message is its last chunk
            if m.get_type() == kind and cond(m):
                return m
        raise AssertionError(f"no {kind} within {timeout} s (texts {self.texts[-5:]})")

    def drain(self) -> None:
        while (m := self.gcs.recv_match(blocking=False)) is not None:
            if m.get_type() == "STATUSTEXT":
                self._whole_text(m)

    def _whole_text(self, m: Any) -> bool:
        """Reassemble MAVLink 2 STATUSTEXT chunks (id, chunk_seq; a text shorter than 50
        characters ends one): on the last, ``m.text`` becomes the whole text, which joins
        ``texts``; False while a longer text is still coming."""
        if m.id != 0:
            parts = self._chunks.setdefault(m.id, {})
            parts[m.chunk_seq] = m.text
            if len(m.text) >= 50:
                return False
            m.text = "".join(parts[k] for k in sorted(parts))
            del self._chunks[m.id]
        self.texts.append(m.text)
        return True

    def command(self, cmd: int, *params: float, expect: int | None = None) -> Any:
        p = list(params) + [0.0] * (7 - len(params))
        self.gcs.mav.command_long_send(1, 1, cmd, 0, *p)
        ack = self.wait("COMMAND_ACK", 3.0, lambda m: m.command == cmd)
        if expect is not None:
            assert ack.result == expect, ack
        return ack

    def position(self, x: float, y: float, z: float, yaw: float = 0.0, mask: int = POS_ONLY,
                 frame: int = 1) -> None:
        self.gcs.mav.set_position_target_local_ned_send(0, 1, 1, frame, mask, x, y, z,
                                                        0, 0, 0, 0, 0, 0, yaw, 0)

    def attitude(self, roll: float, pitch: float, yaw: float, mask: int = ATT_ONLY) -> None:
        self.gcs.mav.set_attitude_target_send(0, 1, 1, mask, euler_to_quat(roll, pitch, yaw),
                                              0, 0, 0, 0.5, [0.0, 0.0, 0.0])

    def offboard(self, expect: int | None = 0) -> Any:
        return self.command(176, 1, 6, 0, expect=expect)


def mavproxy_session(tmp_path: Path, fly_args: Sequence[str], modules: str,
                     commands: Sequence[tuple[str, float]], settle: float = 6.0,
                     setup: Sequence[str] = ()) -> tuple[str, str]:
    """``fullpose fly`` (speed 2) and a headless MAVProxy on one UDP port.  MAVProxy starts
    once the vehicle is up (it sends requests before it hears one, which a udpin link cannot
    deliver) with ``modules``; it gets the ``setup`` commands at once, then, after ``settle``
    s, each of ``commands`` followed by its wait (s).  Returns (MAVProxy's output, fly's
    output)."""
    # the script installed beside the running interpreter, not one found on PATH
    exe = Path(sysconfig.get_path("scripts")) / "mavproxy.py"
    if not exe.is_file():
        pytest.fail(f"{exe} missing: MAVProxy is a test dependency: pip install '.[test]'")
    port = free_port()
    fly = subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "fly", "--gcs", f"udpout:127.0.0.1:{port}",
         "--speed", "2", "--duration", "40", *fly_args], cwd=ROOT, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    assert fly.stdout is not None
    fly_lines = []
    for line in fly.stdout:
        fly_lines.append(line)
        if line.startswith("mavlink endpoint"):
            break
    proxy = subprocess.Popen(
        [str(exe), f"--master=udpin:127.0.0.1:{port}", "--nowait",
         f"--default-modules={modules}", "--state-basedir", str(tmp_path)], cwd=tmp_path,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert proxy.stdin is not None
    try:
        for command in setup:
            proxy.stdin.write(command + "\n")
        proxy.stdin.flush()
        time.sleep(settle)
        for command, after in commands:
            proxy.stdin.write(command + "\n")
            proxy.stdin.flush()
            time.sleep(after)
        out, _ = proxy.communicate(timeout=30)
    finally:
        proxy.kill()
        fly.kill()
        rest, _ = fly.communicate(timeout=10)
    return out, "".join(fly_lines) + (rest or "")
