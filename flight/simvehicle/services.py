"""Small MAVLink services the simulated vehicle answers so that ground stations move on.

None of them matters for flying, but real ground software waits for them: TIMESYNC
(MAVSDK), an empty mission, fence and rally list (MAVProxy asks at connection), and
MAVLink FTP, which is refused at once so that a ground station that tries it first for
the parameters (MAVProxy) falls back to PARAM_REQUEST_LIST without waiting ≈ 10 s.
"""

from __future__ import annotations

import struct

from mavsysid.flight.simvehicle.link import mavlink

__all__ = ["ftp_refusal", "mission_count", "timesync_reply"]

M = mavlink
# MAVLink FTP opcodes and errors (mavlink.io/en/services/ftp.html).
_TERMINATE_SESSION, _RESET_SESSIONS, _ACK, _NAK = 1, 2, 128, 129
_FILE_OPS = frozenset(range(3, 16))
_FILE_NOT_FOUND, _UNKNOWN_COMMAND = 10, 7
_HEADER = "<HBBBBBBI"  # seq, session, opcode, size, req_opcode, burst_complete, pad, offset


def timesync_reply(msg, now_ns: int):
    """The answer to a TIMESYNC request (tc1 = 0), or None for anything else."""
    if msg.tc1 != 0:
        return None
    return M.MAVLink_timesync_message(now_ns, msg.ts1)


def mission_count(msg):
    """MISSION_COUNT 0 for a MISSION_REQUEST_LIST of any mission type."""
    return M.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), 0,
                                           msg.mission_type)


def ftp_refusal(msg):
    """The FTP reply to a FILE_TRANSFER_PROTOCOL request: ACK for ending sessions, else NAK
    (file not found for file operations, unknown command otherwise)."""
    seq, session, opcode = struct.unpack_from("<HBB", bytes(msg.payload[:4]))
    if opcode in (_TERMINATE_SESSION, _RESET_SESSIONS):
        reply = struct.pack(_HEADER, (seq + 1) & 0xFFFF, session, _ACK, 0, opcode, 0, 0, 0)
    else:
        error = _FILE_NOT_FOUND if opcode in _FILE_OPS else _UNKNOWN_COMMAND
        reply = struct.pack(_HEADER + "B", (seq + 1) & 0xFFFF, session, _NAK, 1, opcode, 0, 0,
                            0, error)
    return M.MAVLink_file_transfer_protocol_message(
        0, msg.get_srcSystem(), msg.get_srcComponent(), list(reply.ljust(251, b"\0")))
