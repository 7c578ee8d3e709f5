"""The mission protocol from a ground station's side (mission, fence, rally): uploads item by
item with re-requests, downloads that give back every field, refusals with the reason, clearing,
MISSION_SET_CURRENT, and MAVProxy's `wp load`.  One bridge in a thread at 4x speed on 127.0.0.1
serves the pymavlink tests (each starts from empty plans); every wait is bounded in wall time.
The upload's timeouts are wall time (mavlink_bridge/mission_protocol.py)."""

import math
import os
import struct
import threading
import time

import pytest

os.environ["MAVLINK20"] = "1"

from helpers import mavlink_harness as harness
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav

from mavlink_bridge import mission_protocol
from mavlink_bridge.handlers import missions

pytestmark = pytest.mark.mavlink  # the real-time tier (pyproject.toml)

NAN = float("nan")
MISSION, FENCE, RALLY = 0, 1, 2
GLOBAL_INT, LOCAL_NED, FRAME_MISSION, REL_ALT, REL_ALT_INT = 5, 1, 2, 3, 6
LAT, LON = 473977419, 85455938  # degrees * 1e7
# (frame, command, autocontinue, param1..4, x, y, z): every command the mission flies, in the
# global relative-altitude frames and the local one
EVERY_COMMAND = [
    (REL_ALT_INT, 22, 1, 0.0, 0.0, 0.0, NAN, LAT, LON, 10.0),  # NAV_TAKEOFF, yaw NaN: keep
    (REL_ALT_INT, 16, 1, 2.5, 0.3, 0.0, 90.0, LAT + 1234, LON - 987, 12.5),  # hold, radius, yaw
    (FRAME_MISSION, 31010, 1, 15.0, -7.5, 0.0, 0.0, 0, 0, 0.0),  # FULLPOSE_ATTITUDE r, p
    (FRAME_MISSION, 178, 1, 1.0, 1.5, -1.0, 0.0, 0, 0, 0.0),  # DO_CHANGE_SPEED 1.5 m/s
    (LOCAL_NED, 16, 0, 0.0, 0.1, 0.0, -45.0, 12345, -67890, -3.25),  # 1.2345 m, -6.789 m
    (LOCAL_NED, 19, 1, 5.0, 0.0, 0.0, 0.0, 20000, 0, -4.0),  # NAV_LOITER_TIME 5 s
    (REL_ALT, 16, 1, 0.0, 0.2, 0.0, 180.0, LAT - 55, LON + 77, 8.0),  # float frame in the INT
    (FRAME_MISSION, 20, 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0),  # NAV_RETURN_TO_LAUNCH
    (REL_ALT_INT, 21, 1, 0.0, 0.0, 0.0, NAN, 0, 0, 0.0),  # NAV_LAND here
]
SHORT = [
    (LOCAL_NED, 16, 1, 0.0, 0.2, 0.0, 0.0, 10000, 0, -3.0),
    (LOCAL_NED, 16, 1, 1.0, 0.2, 0.0, 90.0, 10000, 10000, -3.5),
    (LOCAL_NED, 19, 1, 2.0, 0.0, 0.0, 0.0, 0, 10000, -3.0),
]
POLYGON = [(GLOBAL_INT, 5001, 1, 4.0, 0.0, 0.0, 0.0, LAT + dx, LON + dy, 0.0)
           for dx, dy in ((0, 0), (2000, 0), (2000, 3000), (0, 3000))]
CIRCLE = (GLOBAL_INT, 5003, 1, 25.0, 0.0, 0.0, 0.0, LAT + 1000, LON + 1500, 0.0)
RALLY_POINTS = [(REL_ALT_INT, 5100, 1, 0.0, 0.0, 0.0, 0.0, LAT + 300, LON, 15.0),
                (REL_ALT_INT, 5100, 1, 0.0, 0.0, 0.0, 0.0, LAT, LON + 400, 20.0)]
MISSION_MESSAGES = ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "MISSION_COUNT",
                    "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_CURRENT")


class Ground(harness.Flight):
    """The bridge in a thread, its mission re-requests ticked every chunk, and a pymavlink
    ground station (255/190)."""

    def __init__(self):
        super().__init__(4.0)
        self.bridge.on_chunk = lambda b: missions.tick(b, time.monotonic())

    def text(self, fragment, timeout=5.0):
        if not any(fragment in t for t in self.texts):
            self.wait("STATUSTEXT", timeout, lambda m: fragment in m.text)

    def next(self, kinds=MISSION_MESSAGES, timeout=5.0, to=(255, 190)):
        """The next mission message of ``kinds`` addressed to ``to`` (texts are kept)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = self.gcs.recv_match(blocking=True, timeout=0.02)
            if m is None:
                continue
            if m.get_type() == "STATUSTEXT":
                self._whole_text(m)
            elif m.get_type() in kinds and (m.get_type() == "MISSION_CURRENT" or (
                    m.target_system, m.target_component) == to):
                return m
        raise AssertionError(f"no {kinds} within {timeout} s (texts {self.texts[-5:]})")


@pytest.fixture(scope="module")
def bridge_ground():
    g = Ground()
    yield g
    g.close()


@pytest.fixture
def ground(bridge_ground):
    """The shared bridge with every plan cleared and nothing left to read."""
    g = bridge_ground
    g.gcs.mav.mission_clear_all_send(1, 1, mav.MAV_MISSION_TYPE_ALL)
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_ACCEPTED
    # refusal texts are rate-limited per wall second (context.STATUSTEXT_PER_S): each test
    # starts in a second of its own, so none of its texts is held back
    time.sleep(1.0 - time.monotonic() % 1.0)
    g.drain()
    g.texts.clear()
    return g


def item_int(seq, row, kind=MISSION, current=0, target=(1, 1)):
    frame, cmd, auto, p1, p2, p3, p4, x, y, z = row
    return mav.MAVLink_mission_item_int_message(*target, seq, frame, cmd, current, auto,
                                                p1, p2, p3, p4, x, y, z, kind)


def item_float(seq, row, kind=MISSION):
    frame, cmd, auto, p1, p2, p3, p4, x, y, z = row
    return mav.MAVLink_mission_item_message(1, 1, seq, frame, cmd, 0, auto, p1, p2, p3, p4,
                                            x, y, z, kind)


def upload(g, rows, kind=MISSION, legacy=False, conn=None, who=(255, 190)):
    """Upload rows answering each request; returns (final MISSION_ACK, requests seen)."""
    conn = conn or g.gcs
    conn.mav.mission_count_send(1, 1, len(rows), kind)
    seen = []
    while True:
        m = g.next(("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"), to=who)
        if m.get_type() == "MISSION_ACK":
            return m, seen
        assert m.mission_type == kind, m
        seen.append((m.get_type(), m.seq))
        make = item_float if legacy else item_int
        conn.mav.send(make(m.seq, rows[m.seq], kind))


def download(g, kind=MISSION, legacy=False):
    """Every item of the plan of ``kind`` (MISSION_REQUEST_INT, or the legacy MISSION_REQUEST)."""
    g.gcs.mav.mission_request_list_send(1, 1, kind)
    n = g.next(("MISSION_COUNT",)).count
    out = []
    for seq in range(n):
        if legacy:
            g.gcs.mav.mission_request_send(1, 1, seq, kind)
        else:
            g.gcs.mav.mission_request_int_send(1, 1, seq, kind)
        m = g.next(("MISSION_ITEM" if legacy else "MISSION_ITEM_INT",))
        assert m.seq == seq and m.mission_type == kind, m
        out.append(m)
    g.gcs.mav.mission_ack_send(1, 1, mav.MAV_MISSION_ACCEPTED, kind)
    return out


def f32(v):
    return struct.pack("<f", v)


def fields(m):
    """An item message's content, floats as their float32 bytes (NaN compares equal)."""
    return (m.frame, m.command, m.autocontinue, *(f32(getattr(m, f"param{i}")) for i in
                                                   range(1, 5)),
            m.x if isinstance(m.x, int) else f32(m.x), m.y if isinstance(m.y, int) else f32(m.y),
            f32(m.z), m.mission_type)


def row_fields(row, kind=MISSION, legacy=False):
    return fields(item_float(0, row, kind) if legacy else item_int(0, row, kind))


def test_upload_then_download_gives_every_field_back(ground):
    g = ground
    ack, seen = upload(g, EVERY_COMMAND)
    assert ack.type == mav.MAV_MISSION_ACCEPTED and ack.mission_type == MISSION, ack
    assert seen == [("MISSION_REQUEST_INT", i) for i in range(len(EVERY_COMMAND))]
    got = download(g)
    assert [fields(m) for m in got] == [row_fields(r) for r in EVERY_COMMAND]
    assert [m.current for m in got] == [1] + [0] * (len(EVERY_COMMAND) - 1)
    held = g.bridge.plans[MISSION]
    assert [(it.seq, it.x, it.y) for it in held] == [(i, r[7], r[8])
                                                     for i, r in enumerate(EVERY_COMMAND)]
    # the same plan as legacy float MISSION_ITEMs: degrees and metres
    legacy = download(g, legacy=True)
    for m, row in zip(legacy, EVERY_COMMAND, strict=True):
        scale = 1e-4 if row[0] == LOCAL_NED else 1e-7 if row[0] != FRAME_MISSION else 1.0
        assert m.x == pytest.approx(row[7] * scale, rel=1e-7, abs=1e-9)
        assert m.y == pytest.approx(row[8] * scale, rel=1e-7, abs=1e-9)
        assert f32(m.param2) == f32(row[4]) and f32(m.z) == f32(row[9])
    assert g.bridge.stats.ignored == 0


def test_legacy_float_upload_round_trips(ground):
    g = ground
    rows = [(REL_ALT_INT, 22, 1, 0.0, 0.0, 0.0, 0.0, 47.3977419, 8.5455938, 10.0),
            (LOCAL_NED, 16, 1, 1.0, 0.25, 0.0, 30.0, 1.2345, -6.789, -3.25),
            (FRAME_MISSION, 31010, 1, 10.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            (REL_ALT, 21, 0, 0.0, 0.0, 0.0, NAN, 47.3977, 8.5456, 0.0)]
    ack, seen = upload(g, rows, legacy=True)
    assert ack.type == mav.MAV_MISSION_ACCEPTED, ack
    # asked with MISSION_REQUEST_INT first; a MISSION_ITEM answer switches to MISSION_REQUEST
    assert seen == [("MISSION_REQUEST_INT", 0)] + [("MISSION_REQUEST", i) for i in (1, 2, 3)]
    assert [fields(m) for m in download(g, legacy=True)] == [row_fields(r, legacy=True)
                                                             for r in rows]
    as_int = download(g)
    assert (as_int[0].x, as_int[0].y) == (round(f32_value(47.3977419) * 1e7),
                                          round(f32_value(8.5455938) * 1e7))
    assert (as_int[1].x, as_int[1].y) == (12345, -67890)


def f32_value(v):
    return struct.unpack("<f", f32(v))[0]


def test_fence_and_rally_round_trip_and_clear_all(ground):
    g = ground
    fence = [*POLYGON, CIRCLE]
    assert upload(g, fence, FENCE)[0].type == mav.MAV_MISSION_ACCEPTED
    assert upload(g, RALLY_POINTS, RALLY)[0].type == mav.MAV_MISSION_ACCEPTED
    assert upload(g, SHORT)[0].type == mav.MAV_MISSION_ACCEPTED
    assert [fields(m) for m in download(g, FENCE)] == [row_fields(r, FENCE) for r in fence]
    assert [fields(m) for m in download(g, RALLY)] == [row_fields(r, RALLY)
                                                       for r in RALLY_POINTS]
    assert [m.current for m in download(g, FENCE)] == [0] * 5  # current: mission items only
    g.gcs.mav.mission_clear_all_send(1, 1, FENCE)
    ack = g.next(("MISSION_ACK",))
    assert (ack.type, ack.mission_type) == (mav.MAV_MISSION_ACCEPTED, FENCE)
    assert download(g, FENCE) == [] and len(download(g, RALLY)) == 2
    g.gcs.mav.mission_clear_all_send(1, 1, mav.MAV_MISSION_TYPE_ALL)
    ack = g.next(("MISSION_ACK",))
    assert (ack.type, ack.mission_type) == (mav.MAV_MISSION_ACCEPTED, 255)
    assert download(g) == [] and download(g, RALLY) == []
    # MISSION_COUNT 0 clears too
    assert upload(g, RALLY_POINTS, RALLY)[0].type == mav.MAV_MISSION_ACCEPTED
    assert upload(g, [], RALLY)[0].type == mav.MAV_MISSION_ACCEPTED
    assert download(g, RALLY) == []


@pytest.mark.parametrize("rows, kind, result, text", [
    ([SHORT[0], SHORT[1], (FRAME_MISSION, 34, 1, 5.0, 1.0, 0, 0, 0, 0, 0.0)], MISSION,
     mav.MAV_MISSION_UNSUPPORTED, "mission upload refused: item 2: orbits not supported"),
    ([(LOCAL_NED, 17, 1, 0.0, 0.0, 0.0, 0.0, 0, 0, -3.0)], MISSION, mav.MAV_MISSION_UNSUPPORTED,
     "item 0: unlimited loiter not supported"),
    ([SHORT[0], (11, 16, 1, 0.0, 0.2, 0.0, 0.0, LAT, LON, 5.0)], MISSION,
     mav.MAV_MISSION_UNSUPPORTED_FRAME, "item 1: terrain altitude unsupported"),
    ([(LOCAL_NED, 16, 1, NAN, 0.2, 0.0, 0.0, 0, 0, -3.0)], MISSION,
     mav.MAV_MISSION_INVALID_PARAM1, "item 0: param1 not finite"),
    ([(LOCAL_NED, 16, 1, 0.0, 0.2, 0.0, 0.0, 0, 0, NAN)], MISSION,
     mav.MAV_MISSION_INVALID_PARAM7, "item 0: z not finite"),
    (POLYGON[:3], FENCE, mav.MAV_MISSION_INVALID_PARAM1,
     "fence upload refused: item 0: polygon of 4 vertices incomplete"),
    ([(REL_ALT_INT, 16, 1, 0.0, 0.0, 0.0, 0.0, LAT, LON, 9.0)], RALLY,
     mav.MAV_MISSION_UNSUPPORTED, "rally upload refused: item 0: command 16 not supported"),
], ids=["orbit", "loiter-unlimited", "terrain-frame", "nan-param", "nan-z", "polygon", "rally"])
def test_refused_upload_keeps_the_plan_held(ground, rows, kind, result, text):
    g = ground
    before = RALLY_POINTS if kind == RALLY else [*POLYGON, CIRCLE] if kind == FENCE else SHORT
    assert upload(g, before, kind)[0].type == mav.MAV_MISSION_ACCEPTED
    ack, seen = upload(g, rows, kind)
    assert (ack.type, ack.mission_type) == (result, kind), ack
    assert len(seen) == len(rows)  # refused at the bad item (the polygon: at the end)
    g.text(text)
    assert [fields(m) for m in download(g, kind)] == [row_fields(r, kind) for r in before]


def test_too_many_items_and_unknown_types_refused(ground):
    g = ground
    g.gcs.mav.mission_count_send(1, 1, 501, MISSION)
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_NO_SPACE
    g.text("mission upload refused: 501 items, at most 500")
    g.gcs.mav.mission_count_send(1, 1, 65, FENCE)
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_NO_SPACE
    for send in (lambda: g.gcs.mav.mission_count_send(1, 1, 2, 7),
                 lambda: g.gcs.mav.mission_request_list_send(1, 1, 7),
                 lambda: g.gcs.mav.mission_request_int_send(1, 1, 0, 7),
                 lambda: g.gcs.mav.mission_clear_all_send(1, 1, 7)):
        send()
        ack = g.next(("MISSION_ACK",))
        assert (ack.type, ack.mission_type) == (mav.MAV_MISSION_UNSUPPORTED, 7)
    g.gcs.mav.mission_request_int_send(1, 1, 0, MISSION)  # the mission is empty
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_INVALID_SEQUENCE


def test_lost_and_out_of_order_items_are_requested_again(ground):
    g = ground
    send = g.gcs.mav.send
    g.gcs.mav.mission_count_send(1, 1, 3, MISSION)
    assert g.next(("MISSION_REQUEST_INT",)).seq == 0
    send(item_int(0, SHORT[0]))
    assert g.next(("MISSION_REQUEST_INT",)).seq == 1
    send(item_int(2, SHORT[2]))  # item 1 lost on the way: asked for again at once
    assert g.next(("MISSION_REQUEST_INT",)).seq == 1
    send(item_int(0, SHORT[0]))  # a duplicate: dropped, no answer
    # item 1 lost again: the re-request comes after the item timeout
    t0 = time.monotonic()
    again = g.next(("MISSION_REQUEST_INT", "MISSION_ACK"), timeout=3.0)
    waited = time.monotonic() - t0
    assert (again.get_type(), again.seq) == ("MISSION_REQUEST_INT", 1), again
    assert mission_protocol.ITEM_TIMEOUT - 0.1 < waited < mission_protocol.ITEM_TIMEOUT + 1.0
    send(item_int(1, SHORT[1]))
    assert g.next(("MISSION_REQUEST_INT",)).seq == 2
    send(item_int(2, SHORT[2]))
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_ACCEPTED
    send(item_int(2, SHORT[2]))  # our ACK lost: the last item again gets it again
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_ACCEPTED
    assert [fields(m) for m in download(g)] == [row_fields(r) for r in SHORT]
    # an item beyond the count, or of another plan type, ends the upload with an error
    g.gcs.mav.mission_count_send(1, 1, 2, MISSION)
    assert g.next(("MISSION_REQUEST_INT",)).seq == 0
    send(item_int(5, SHORT[0]))
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_INVALID_SEQUENCE
    g.gcs.mav.mission_count_send(1, 1, 2, MISSION)
    assert g.next(("MISSION_REQUEST_INT",)).seq == 0
    send(item_int(0, RALLY_POINTS[0], kind=RALLY))
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_ERROR
    send(item_int(1, SHORT[1]))  # no upload any more
    assert g.next(("MISSION_ACK",)).type == mav.MAV_MISSION_ERROR
    g.text("no upload in progress")
    assert [fields(m) for m in download(g)] == [row_fields(r) for r in SHORT]


def test_one_upload_at_a_time_and_a_silent_one_is_given_up(ground):
    g = ground
    other = mavutil.mavlink_connection(f"udpout:127.0.0.1:{g.bridge_port()}", source_system=250,
                                       source_component=190, dialect="common")
    try:
        g.gcs.mav.mission_count_send(1, 1, 2, MISSION)
        assert g.next(("MISSION_REQUEST_INT",)).seq == 0
        other.mav.mission_count_send(1, 1, 1, RALLY)  # while 255/190 uploads
        ack = g.next(("MISSION_ACK",), to=(250, 190))
        assert (ack.type, ack.mission_type) == (mav.MAV_MISSION_DENIED, RALLY)
        g.text("rally upload refused: busy with an upload from 255/190")
        # 255/190 falls silent: re-requested ITEM_RETRIES times, then cancelled
        silence = mission_protocol.ITEM_TIMEOUT * (mission_protocol.ITEM_RETRIES + 1)
        t0 = time.monotonic()
        requests = 0
        while True:
            m = g.next(("MISSION_REQUEST_INT", "MISSION_ACK"), timeout=silence + 3.0)
            if m.get_type() == "MISSION_ACK":
                break
            requests += 1
        assert m.type == mav.MAV_MISSION_OPERATION_CANCELLED
        assert requests == mission_protocol.ITEM_RETRIES
        assert time.monotonic() - t0 > silence - 0.6
        g.text(f"mission upload refused: no item 0 for {silence:g} s")
        ack, _ = upload(g, RALLY_POINTS[:1], RALLY, conn=other, who=(250, 190))
        assert ack.type == mav.MAV_MISSION_ACCEPTED
        # the ground station cancels its own upload
        g.gcs.mav.mission_count_send(1, 1, 2, MISSION)
        assert g.next(("MISSION_REQUEST_INT",)).seq == 0
        g.gcs.mav.mission_ack_send(1, 1, mav.MAV_MISSION_OPERATION_CANCELLED, MISSION)
        time.sleep(0.2)
        assert upload(g, RALLY_POINTS, RALLY, conn=other, who=(250, 190))[0].type == 0
        assert download(g) == [] and len(download(g, RALLY)) == 2
    finally:
        other.close()


def test_set_current_answered_with_mission_current(ground):
    g = ground
    assert upload(g, SHORT)[0].type == mav.MAV_MISSION_ACCEPTED
    g.gcs.mav.mission_set_current_send(1, 1, 2)
    cur = g.next(("MISSION_CURRENT",), timeout=3.0)
    while cur.seq != 2:  # a streamed MISSION_CURRENT sent before ours
        cur = g.next(("MISSION_CURRENT",), timeout=3.0)
    assert (cur.seq, cur.total) == (2, 3)
    assert g.bridge.mission_current == 2
    assert [m.current for m in download(g)] == [0, 0, 1]
    g.gcs.mav.mission_set_current_send(1, 1, 7)
    ack = g.next(("MISSION_ACK",))
    assert ack.type == mav.MAV_MISSION_INVALID_SEQUENCE
    g.text("mission item 7 not set current")
    assert g.bridge.mission_current == 2


def _download_when_held(port, n, found, stop):
    """A second ground station: once the bridge holds a mission of n items, download it."""
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=254,
                                      source_component=190, dialect="common")
    try:
        while not stop.is_set() and conn.recv_match(type="HEARTBEAT", blocking=True,
                                                     timeout=0.5) is None:
            pass
        while not stop.is_set():
            conn.mav.mission_request_list_send(1, 1, MISSION)
            m = conn.recv_match(type="MISSION_COUNT", blocking=True, timeout=0.5)
            if m is not None and m.count == n:
                break
            time.sleep(0.3)
        for seq in range(n):
            for _ in range(5):
                conn.mav.mission_request_int_send(1, 1, seq, MISSION)
                m = conn.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=1.0)
                if m is not None and m.seq == seq:
                    found.append(m)
                    break
        conn.mav.mission_ack_send(1, 1, 0, MISSION)
    finally:
        conn.close()


@pytest.mark.clients
def test_mavproxy_wp_load_uploads_a_qgc_wpl_plan(tmp_path):
    # QGC WPL 110: seq current frame command p1 p2 p3 p4 x(lat) y(lon) z autocontinue
    rows = [(0, 1, 3, 22, 0, 0, 0, 0, 47.3977419, 8.5455938, 10.0, 1),
            (1, 0, 3, 16, 2.0, 0.3, 0, 45.0, 47.3979, 8.5458, 12.0, 1),
            (2, 0, 2, 31010, 12.0, -6.0, 0, 0, 0, 0, 0, 1),
            (3, 0, 2, 178, 1, 2.0, -1, 0, 0, 0, 0, 1),
            (4, 0, 3, 19, 3.0, 0, 0, 0, 47.3980, 8.5460, 12.0, 1),
            (5, 0, 2, 20, 0, 0, 0, 0, 0, 0, 0, 1)]
    plan = tmp_path / "plan.txt"
    plan.write_text("QGC WPL 110\n" + "".join("\t".join(str(v) for v in r) + "\n"
                                                for r in rows))
    port = harness.free_port()
    found, stop = [], threading.Event()
    checker = threading.Thread(target=_download_when_held, args=(port, len(rows), found, stop),
                               daemon=True)
    checker.start()
    try:
        out, fly = harness.mavproxy_session(
            tmp_path, ["--gcs", f"udpout:127.0.0.1:{port}"], "wp",
            [(f"wp load {plan}", 3.0), ("wp list", 3.0)])
    finally:
        stop.set()
        checker.join(timeout=10)
    assert "Got MISSION_ACK: TYPE_MISSION: ACCEPTED" in out, out
    # `wp list` downloads them back
    assert "Requesting 6 waypoints" in out and "Saved 6 waypoints" in out, out
    assert len(found) == len(rows), (found, out, fly)
    for m, r in zip(found, rows, strict=True):
        assert (m.seq, m.frame, m.command, m.autocontinue) == (r[0], r[2], r[3], r[11])
        assert [f32(getattr(m, f"param{i}")) for i in range(1, 5)] == [f32(v) for v in r[4:8]]
        if r[2] == REL_ALT:  # MAVProxy sends int(degrees * 1e7)
            assert (m.x, m.y) == (int(r[8] * 1e7), int(r[9] * 1e7))
        assert f32(m.z) == f32(r[10])
    assert not math.isnan(found[0].param1)
