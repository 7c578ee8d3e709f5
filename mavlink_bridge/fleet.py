"""Several vehicles from one ``fullpose fly``: PX4 SITL's multi-instance convention.

Instance i (0-based) is a :class:`~mavlink_bridge.bridge.Bridge` of its own (its own plant and
controller FMUs, parsers and sockets) with system id ``base.system_id + i`` (1 + i by default,
PX4's ``MAV_SYS_ID``), sending to the shared ground-station port ``udpout:127.0.0.1:14550``
and to its own offboard/API port ``udpout:127.0.0.1:14540+i``, as PX4's ``px4-rc.mavlink``
does.  Its local NED frame's origin (the geodetic point of local (0, 0, 0)) is
``spacing * i`` m east of the first vehicle's, as PX4's vehicles each have their local frame
and home where they were spawned: every vehicle starts at the same local pose, side by side
on the map.

One thread per vehicle runs the unchanged ``Bridge.run()`` (docs/mavlink.md, "Several
vehicles", for the measurements behind the choice).  The GIL is released while a bridge
waits in ``select()``/``sleep()`` between chunks, in socket calls and in the C step kernel
(ctypes), so a vehicle's Python work waits only for the others' short slices of Python
work; each FMU instance is extracted and loaded on its own, so no state is shared between
the threads.
"""

from __future__ import annotations

import copy
import dataclasses
import re
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pymavlink and the FMUs load when a fleet is made, not with the CLI
    from mavlink_bridge.bridge import Bridge, BridgeConfig, PacingStats

GCS_URL = "udpout:127.0.0.1:14550"
"""The ground station's port, shared by every vehicle (PX4: remote port 14550)."""
API_URL = "udpout:127.0.0.1:14540+i"
"""Each vehicle's offboard/API port (PX4: remote port 14540 + instance)."""
DEFAULT_URLS = (GCS_URL, API_URL)
"""The endpoints of every vehicle, as URL templates (:func:`instance_urls`)."""
MAX_VEHICLES = 16
"""The most vehicles one ``fullpose fly`` flies (docs/mavlink.md, "Several vehicles")."""
SPACING = 2.0
"""m east between consecutive vehicles' local origins."""
JOIN_TIMEOUT = 10.0  # wall s a stopped vehicle gets to finish its chunk and return

# a port written PORT+i: the instance number is added (the only template there is)
_PER_INSTANCE = re.compile(r"^(?P<head>[a-z]+:.+:)(?P<port>\d+)\+i$")


class FleetError(RuntimeError):
    """A vehicle failed; all were stopped.  The message names the vehicle by system id."""


def instance_urls(templates: Sequence[str], i: int) -> list[str]:
    """Instance i's endpoint URLs: a template whose port is written ``PORT+i`` sends to (or
    listens on) PORT + i; any other URL is used as written, by every instance."""
    out = []
    for url in templates:
        m = _PER_INSTANCE.match(url)
        out.append(url if m is None else f"{m['head']}{int(m['port']) + i}")
    return out


def is_per_instance(url: str) -> bool:
    """Whether a URL template gives each instance its own port (``PORT+i``)."""
    return _PER_INSTANCE.match(url) is not None


def fleet_configs(base: BridgeConfig, count: int, urls: Sequence[str] = DEFAULT_URLS,
                  spacing: float = SPACING) -> list[BridgeConfig]:
    """The configurations of ``count`` vehicles, each ``base`` (the configuration the single
    vehicle would fly) but for: system id ``base.system_id + i``, the endpoints
    ``instance_urls(urls, i)``, and the origin ``spacing * i`` m east of ``base.origin``.
    ValueError says why a fleet cannot be made: count outside 1..MAX_VEHICLES, a listening
    (udpin) URL all would share, or an endpoint of one vehicle that is another's."""
    from mavlink_bridge.geodesy import Origin

    if not 1 <= count <= MAX_VEHICLES:
        raise ValueError(f"{count} vehicles: between 1 and {MAX_VEHICLES}")
    if not urls:
        raise ValueError("at least one endpoint is needed")
    for url in urls:
        listening = url.partition(":")[0] in ("udpin", "udp")
        if count > 1 and listening and not is_per_instance(url):
            raise ValueError(f"endpoint {url!r} listens: {count} vehicles cannot share its "
                             "port; write it PORT+i (instance i listens on PORT + i)")
    owner: dict[str, int] = {}  # a per-instance URL -> the system id it belongs to
    configs = []
    for i in range(count):
        system_id = base.system_id + i
        mine = instance_urls(urls, i)
        for template, url in zip(urls, mine, strict=True):
            if is_per_instance(template):
                if url in owner or url in urls:
                    other = owner.get(url)
                    whose = f"system {other}'s" if other is not None else "the shared one"
                    why = (" (PX4's API port 14540+i is the ground station's 14550 from the "
                           "11th vehicle on)" if tuple(urls) == DEFAULT_URLS else "")
                    raise ValueError(f"{count} vehicles: system {system_id}'s endpoint {url} "
                                     f"is also {whose}{why}; give --gcs URLs that keep "
                                     "them apart")
                owner[url] = system_id
        if system_id > 255:
            raise ValueError(f"{count} vehicles from system id {base.system_id}: "
                             f"system id {system_id} is beyond 255")
        lat, lon, _ = base.origin.to_geodetic(0.0, spacing * i, 0.0)
        # a deep copy: a field added to BridgeConfig carries over, and no vehicle shares a
        # mutable part (Limits is updated in place from the FPB_ parameters) with another
        configs.append(dataclasses.replace(
            copy.deepcopy(base), system_id=system_id, urls=mine,
            # the same altitude: the east offset alone (the ellipsoid's curvature over a few
            # metres is far below a millimetre)
            origin=Origin(lat, lon, base.origin.alt)))
    return configs


class Fleet:
    """Vehicles flown together, one thread each: :meth:`run` until every vehicle's duration
    ends, :meth:`stop` (or Ctrl-C in :meth:`run`) ends them all, and a vehicle that fails
    stops the others (:class:`FleetError`).  Opens a Bridge per configuration (closing
    those opened when one cannot be); a context manager that closes them."""

    def __init__(self, configs: Sequence[BridgeConfig]) -> None:
        from mavlink_bridge.bridge import Bridge

        if not configs:
            raise ValueError("a fleet needs a vehicle")
        self.bridges: list[Bridge] = []
        self._threads: list[threading.Thread] = []
        try:
            for config in configs:
                self.bridges.append(Bridge(config))
        except BaseException:
            self.close()
            raise
        self.failures: list[tuple[int, BaseException]] = []  # (system id, what it raised)
        self.cpu_time = [0.0] * len(self.bridges)  # CPU s of each vehicle's thread
        self._lock = threading.Lock()

    @property
    def system_ids(self) -> list[int]:
        """The vehicles' MAVLink system ids, in instance order."""
        return [b.config.system_id for b in self.bridges]

    @property
    def stats(self) -> list[PacingStats]:
        """Each vehicle's pacing statistics (final once :meth:`join` returned)."""
        return [b.stats for b in self.bridges]

    def start(self) -> None:
        """Start every vehicle's thread (each vehicle's clock starts as its thread does)."""
        if self._threads:
            raise RuntimeError("the fleet was started already")
        for i, bridge in enumerate(self.bridges):
            # daemon: a vehicle stuck in an FMU call must not keep the process alive after
            # the command has reported it
            t = threading.Thread(target=self._fly, args=(i,), daemon=True,
                                 name=f"fullpose-sys{bridge.config.system_id}")
            self._threads.append(t)
        for t in self._threads:
            t.start()

    def _fly(self, i: int) -> None:
        bridge = self.bridges[i]
        cpu0 = time.thread_time()
        try:
            bridge.run()
        except BaseException as e:  # whatever it is: run() reports it
            with self._lock:
                self.failures.append((bridge.config.system_id, e))
            self.stop()  # one vehicle down: the fleet ends (the others after their chunk)
        finally:
            self.cpu_time[i] = time.thread_time() - cpu0

    def stop(self) -> None:
        """Ask every vehicle to end after its current chunk (thread-safe)."""
        for bridge in self.bridges:
            bridge.stop()

    def alive(self) -> bool:
        """Whether a vehicle's thread still runs."""
        return any(t.is_alive() for t in self._threads)

    def join(self, timeout: float = JOIN_TIMEOUT) -> None:
        """Wait for the vehicles' threads to end, each at most ``timeout`` s; a thread still
        running after that is reported as a failure of its vehicle."""
        for t, bridge in zip(self._threads, self.bridges, strict=False):
            t.join(timeout)
            if t.is_alive():
                with self._lock:
                    self.failures.append((bridge.config.system_id, TimeoutError(
                        f"did not stop within {timeout:g} s")))

    def run(self) -> list[PacingStats]:
        """Start the vehicles and wait until all have ended; returns their pacing statistics.
        Ctrl-C (or any exception in this thread) stops them all, waits for them and is raised
        again; a vehicle that failed stopped the others and is raised as :class:`FleetError`
        once all have ended (``failures`` holds every vehicle's exception)."""
        self.start()
        try:
            # short joins: the main thread stays responsive to Ctrl-C
            while self.alive():
                for t in self._threads:
                    t.join(0.1)
        except BaseException:
            self.stop()
            self.join()
            raise
        self.join()
        if self.failures:
            raise FleetError(self.describe_failure())
        return self.stats

    def describe_failure(self) -> str:
        """The first failure, for a terminal: which vehicle, what it raised, that all
        stopped."""
        system_id, e = self.failures[0]
        text = str(e)
        if not text:
            text = type(e).__name__
        elif not isinstance(e, (ValueError, RuntimeError, OSError)):
            text = f"{type(e).__name__}: {text}"  # e.g. a KeyError's bare key says little
        return f"system {system_id}: {text} (all {len(self.bridges)} vehicles stopped)"

    def close(self) -> None:
        """Stop the vehicles and close their endpoints and co-simulations.  A vehicle whose
        thread has not ended within JOIN_TIMEOUT keeps its FMUs (freeing them under a running
        step would crash the process; the daemon thread ends with it)."""
        self.stop()
        ended = []
        for i in range(len(self.bridges)):
            t = self._threads[i] if i < len(self._threads) else None
            if t is not None:
                t.join(JOIN_TIMEOUT)
            ended.append(t is None or not t.is_alive())
        for bridge, done in zip(self.bridges, ended, strict=True):
            if done:
                bridge.close()

    def __enter__(self) -> Fleet:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
