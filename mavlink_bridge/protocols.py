"""The small MAVLink services a ground station expects on connect, answered so that it
moves on at once: MAVLink FTP (a NAK) and PING.  Each function takes the received message and
the sender (system, component) and returns the messages to send back to that sender.  (The
mission protocol: :mod:`mavlink_bridge.mission_protocol`.)
"""

from __future__ import annotations

import struct
from typing import Any

from pymavlink.dialects.v20 import common as mav

# MAVLink FTP (https://mavlink.io/en/services/ftp.html): the payload starts with
# seq u16, session u8, opcode u8, size u8, req_opcode u8, burst_complete u8, padding u8,
# offset u32, then data[239].
FTP_HEADER = struct.Struct("<HBBBBBBI")
FTP_PAYLOAD = 251
OP_TERMINATE_SESSION = 1
OP_RESET_SESSIONS = 2
OP_LIST_DIRECTORY = 3
OP_OPEN_FILE_RO = 4
OP_READ_FILE = 5
OP_CREATE_FILE = 6
OP_WRITE_FILE = 7
OP_REMOVE_FILE = 8
OP_CREATE_DIRECTORY = 9
OP_REMOVE_DIRECTORY = 10
OP_OPEN_FILE_WO = 11
OP_TRUNCATE_FILE = 12
OP_RENAME = 13
OP_CALC_FILE_CRC32 = 14
OP_BURST_READ_FILE = 15
OP_LIST_DIRECTORY_WITH_TIME = 16
OP_ACK = 128
OP_NAK = 129
ERR_INVALID_SESSION = 4
ERR_UNKNOWN_COMMAND = 7
ERR_FILE_NOT_FOUND = 10

#: opcodes naming a path: there is no file system here, so no path exists
_PATH_OPS = {OP_LIST_DIRECTORY, OP_OPEN_FILE_RO, OP_CREATE_FILE, OP_REMOVE_FILE,
             OP_CREATE_DIRECTORY, OP_REMOVE_DIRECTORY, OP_OPEN_FILE_WO, OP_TRUNCATE_FILE,
             OP_RENAME, OP_CALC_FILE_CRC32, OP_LIST_DIRECTORY_WITH_TIME}
#: opcodes naming a session: none can be open
_SESSION_OPS = {OP_TERMINATE_SESSION, OP_READ_FILE, OP_WRITE_FILE, OP_BURST_READ_FILE}


def ftp_error(opcode: int) -> int:
    """The FTP error code a request gets here (every request but ResetSessions is NAKed)."""
    if opcode in _PATH_OPS:
        return ERR_FILE_NOT_FOUND
    if opcode in _SESSION_OPS:
        return ERR_INVALID_SESSION
    return ERR_UNKNOWN_COMMAND


def ftp_reply(msg: Any, src: tuple[int, int]) -> list[Any]:
    """NAK (or, for ResetSessions, ACK: there is nothing to reset) with the request's
    seq + 1, session and opcode in req_opcode, as the FTP protocol defines a reply."""
    payload = bytes(int(b) & 0xFF for b in msg.payload)
    if len(payload) < FTP_HEADER.size:
        return []
    seq, session, opcode, _, _, _, _, offset = FTP_HEADER.unpack_from(payload)
    if opcode in (OP_ACK, OP_NAK):
        return []  # a reply, not a request
    if opcode == OP_RESET_SESSIONS:
        head = FTP_HEADER.pack((seq + 1) & 0xFFFF, session, OP_ACK, 0, opcode, 0, 0, 0)
        data = b""
    else:
        head = FTP_HEADER.pack((seq + 1) & 0xFFFF, session, OP_NAK, 1, opcode, 0, 0, offset)
        data = bytes([ftp_error(opcode)])
    body = (head + data).ljust(FTP_PAYLOAD, b"\0")
    return [mav.MAVLink_file_transfer_protocol_message(0, src[0], src[1], list(body))]


def ping_reply(msg: Any, src: tuple[int, int]) -> list[Any]:
    """common.xml PING: a request has target 0/0; the answer echoes time_usec and seq
    with the target set to the requester."""
    if int(msg.target_system) != 0 or int(msg.target_component) != 0:
        return []  # a reply to someone's ping, not a request
    return [mav.MAVLink_ping_message(int(msg.time_usec), int(msg.seq), src[0], src[1])]
