"""UDP endpoints (pymavlink sockets) and MAVLink 2 signing.

An endpoint URL is a pymavlink connection string restricted to UDP:
``udpout:HOST:PORT`` (send to a ground station listening there, replies come back
to our port: how PX4 SITL talks to QGroundControl/MAVSDK) or ``udpin:HOST:PORT``
(listen).  A ``udpin`` endpoint sends only to its peers: the addresses that sent it a
valid MAVLink HEARTBEAT (signed, while signing is on) within the last
:data:`PEER_TIMEOUT` seconds, at most :data:`MAX_PEERS` of them; a datagram that is not
such a heartbeat never makes its sender a peer.  ``udpout`` sockets are bound to
127.0.0.1 when the destination is a loopback address, so nothing off the machine can
reach the bridge unless the user names another address.

Each endpoint has its own MAVLink 2 sender (sequence numbers, signing link id) and its
own parser.  Incoming datagrams are parsed one by one (a malformed one cannot leave
bytes behind that corrupt the next) and signatures are checked here, not by
pymavlink's parser, so that a forged signature cannot advance a stream's timestamp
(pymavlink records the timestamp before it compares the signature).
"""

from __future__ import annotations

import hashlib
import ipaddress
import os
import socket
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"  # pymavlink's mavutil picks its dialect module from this

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

MAVLINK_IFLAG_SIGNED = 0x01
#: Signing timestamps count 10 us units since 2015-01-01 00:00:00 UTC.
SIGNING_EPOCH = 1420070400
STALE_LIMIT = 60 * 100_000  # a new stream may lag our clock by one minute at most
MAX_DATAGRAM = 65535
PEER_TIMEOUT = 10.0  # s of wall time without a heartbeat before a udpin peer is dropped
MAX_PEERS = 8  # udpin peers at most (the longest silent one makes room)

Address = tuple[str, int]
"""A UDP (host, port)."""


def signing_now() -> int:
    """The MAVLink 2 signing timestamp of now (10 us units since 2015-01-01 UTC)."""
    return int((time.time() - SIGNING_EPOCH) * 100_000)


def signature_error(key: bytes, msgbuf: bytes | bytearray, incompat_flags: int) -> str | None:
    """None if the message is signed with key (the signature alone: no timestamp check),
    else why not."""
    if not incompat_flags & MAVLINK_IFLAG_SIGNED or len(msgbuf) < 13:
        return "unsigned"
    digest = hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6]
    return None if digest == bytes(msgbuf[-6:]) else "bad signature"


def _stamp(msgbuf: bytes | bytearray) -> int:
    tlow, thigh = struct.unpack("<IH", bytes(msgbuf[-12:-6]))
    return int(tlow | (thigh << 32))


def fresh_stamp(msgbuf: bytes | bytearray, now: int) -> bool:
    """Whether a signed message's timestamp is within STALE_LIMIT of now (10 us units)."""
    return _stamp(msgbuf) + STALE_LIMIT >= now


def load_key(path: str | Path) -> bytes:
    """A 32-byte signing key from a file: 32 raw bytes, 64 hex digits, or a passphrase
    (hashed with SHA-256 as MAVProxy's ``signing setup PASSPHRASE`` does)."""
    data = Path(path).read_bytes()
    if len(data) == 32:
        return data
    text = data.decode("utf-8", errors="strict").strip()
    if len(text) == 64:
        try:
            return bytes.fromhex(text)
        except ValueError:
            pass
    if not text:
        raise ValueError(f"{path}: empty signing key file")
    return hashlib.sha256(text.encode("utf-8")).digest()


@dataclass
class Signing:
    """Signing state shared by all endpoints (the key is the vehicle's)."""

    key: bytes | None = None
    timestamp: int = 0  # our latest timestamp (10 us units)
    streams: dict[tuple[int, int, int], int] = field(default_factory=dict)
    refused: dict[str, int] = field(default_factory=dict)

    @property
    def enabled(self) -> bool:
        """Whether signing is on (a key is set)."""
        return self.key is not None

    def enable(self, key: bytes | None, initial_timestamp: int = 0) -> None:
        """Use key from now on (None: off), the timestamp never going backwards; the streams' last
        timestamps are forgotten."""
        self.key = key
        self.streams.clear()
        self.timestamp = max(self.timestamp, initial_timestamp, signing_now())

    def verify(self, msgbuf: bytes | bytearray, incompat_flags: int, src: tuple[int, int]
               ) -> str | None:
        """None if the message carries a valid signature with our key, else why not."""
        assert self.key is not None
        why = signature_error(self.key, msgbuf, incompat_flags)
        if why is not None:
            return why
        link_id = msgbuf[-13]
        stamp = _stamp(msgbuf)
        stream = (link_id, src[0], src[1])
        last = self.streams.get(stream)
        if last is not None and stamp <= last:
            return "replayed"
        if last is None and stamp + STALE_LIMIT < max(self.timestamp, signing_now()):
            return "stale timestamp"
        self.streams[stream] = stamp
        self.timestamp = max(self.timestamp, stamp)
        return None

    def count(self, reason: str) -> None:
        """Count an incoming message refused for reason."""
        self.refused[reason] = self.refused.get(reason, 0) + 1


class Endpoint:
    """One UDP endpoint: a pymavlink socket, a MAVLink 2 sender and a parser."""

    def __init__(self, url: str, link_id: int, system: int = 1, component: int = 1) -> None:
        scheme, _, rest = url.partition(":")
        if scheme not in ("udpout", "udpin", "udp") or rest.count(":") != 1:
            raise ValueError(f"endpoint {url!r}: use udpout:HOST:PORT or udpin:HOST:PORT")
        host, port = rest.rsplit(":", 1)
        if not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"endpoint {url!r}: bad port")
        self.url = url
        self.conn: Any = mavutil.mavlink_connection(url, source_system=system,
                                                    source_component=component,
                                                    dialect="common", autoreconnect=False)
        self.sock: socket.socket = self.conn.port
        if scheme == "udpout" and _is_loopback(host):
            self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.listening = scheme in ("udpin", "udp")
        self.peers: dict[Address, float] = {}  # udpin: address -> wall time of its heartbeat
        self.sender = mavlink2.MAVLink(self, system, component)
        self.sender.signing.link_id = link_id
        self.parser = mavlink2.MAVLink(None, 0, 0)
        self.parser.robust_parsing = True
        self.link_id = link_id
        self.intervals: dict[int, float] = {}  # message id -> interval (s); <= 0: off
        self.next_due: dict[int, float] = {}
        self.sent = 0

    def set_signing(self, signing: Signing) -> None:
        """Sign what this endpoint sends with the shared signing state."""
        s = self.sender.signing
        s.secret_key = signing.key
        s.sign_outgoing = signing.key is not None
        s.timestamp = signing.timestamp

    def send(self, msg: Any) -> None:
        """Send one message; a socket error drops it, never the loop."""
        try:
            self.sender.send(msg)
        except (OSError, struct.error, ValueError):
            pass  # a full socket buffer or an unreachable peer must not stop the loop

    def write(self, buf: bytes) -> None:
        """The sender's output: to the destination (udpout) or to every peer (udpin)."""
        if not self.listening:
            self.conn.write(buf)
            self.sent += 1
            return
        now = time.monotonic()
        for addr, seen in list(self.peers.items()):
            if now - seen > PEER_TIMEOUT:
                del self.peers[addr]
                continue
            try:
                self.sock.sendto(buf, addr)
                self.sent += 1
            except OSError:
                pass

    def admit(self, addr: Address) -> None:
        """A udpin endpoint's peer: addr sent a valid heartbeat (the caller checked it)."""
        if not self.listening:
            return
        if addr not in self.peers and len(self.peers) >= MAX_PEERS:
            del self.peers[min(self.peers, key=self.peers.__getitem__)]
        self.peers[addr] = time.monotonic()

    def receive(self, budget: int, deadline: float = float("inf")
                ) -> Iterator[tuple[bytes, Any, Address]]:
        """Up to ``budget`` datagrams, as (datagram, parsed message or None, sender) per
        message; no datagram is started once ``time.perf_counter()`` has passed ``deadline``."""
        for i in range(budget):
            if i and time.perf_counter() >= deadline:
                return
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. ECONNREFUSED after a send to a closed port
                continue
            for raw, msg in self._parse(bytes(data)):
                yield raw, msg, (str(addr[0]), int(addr[1]))

    def _parse(self, data: bytes) -> Iterator[tuple[bytes, Any]]:
        p = self.parser
        try:
            msgs = p.parse_buffer(data) or []
        except Exception:  # a hostile datagram can make pymavlink raise anything
            msgs = []
        finally:
            p.buf = bytearray()
            p.buf_index = 0
            p.expected_length = mavlink2.HEADER_LEN_V1 + 2
        if not msgs:
            yield data, None
        for m in msgs:
            yield data, (None if m.get_type() == "BAD_DATA" or m.get_type().startswith("UNKNOWN")
                         else m)

    def close(self) -> None:
        """Close the endpoint's socket."""
        self.conn.close()


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
