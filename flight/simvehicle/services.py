"""MAVLink services of the simulated vehicle: the fence upload, and small ones that let
ground stations move on.

The mission protocol (mavlink.io/en/services/mission.html) carries the geofence
(mission_type FENCE): upload MISSION_COUNT → MISSION_REQUEST_INT per item →
MISSION_ITEM_INT (or MISSION_ITEM) → MISSION_ACK with the result
(`mavsysid.flight.simvehicle.fence.FenceMonitor.upload`); download MISSION_REQUEST_LIST →
MISSION_COUNT → MISSION_REQUEST_INT/MISSION_REQUEST → MISSION_ITEM_INT/MISSION_ITEM;
MISSION_CLEAR_ALL. Missions and rally points are not simulated: their lists are empty
(MAVProxy asks at connection) and an upload is answered MAV_MISSION_UNSUPPORTED.

The rest matters not for flying, but real ground software waits for them: TIMESYNC
(MAVSDK), and MAVLink FTP, which is refused at once so that a ground station that tries
it first for the parameters (MAVProxy) falls back to PARAM_REQUEST_LIST without waiting
≈ 10 s.
"""

from __future__ import annotations

import struct

from mavsysid.flight.simvehicle.fence import FenceItem, FenceMonitor
from mavsysid.flight.simvehicle.link import mavlink

__all__ = ["MISSION_MESSAGES", "MissionProtocol", "ftp_refusal", "timesync_reply"]

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


#: The mission-protocol messages `MissionProtocol.handle` answers.
MISSION_MESSAGES = ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_REQUEST_LIST",
                    "MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_CLEAR_ALL", "MISSION_ACK")
_FENCE = M.MAV_MISSION_TYPE_FENCE
_MAX_FENCE_ITEMS = 100


class MissionProtocol:
    """The vehicle's side of the mission protocol, for its geofence.

    Parameters
    ----------
    fence : FenceMonitor
        Receives a complete upload; its items are what a download returns.
    """

    def __init__(self, fence: FenceMonitor) -> None:
        self.fence = fence
        self._expected = 0
        self._count = 0
        self._received: list[FenceItem] = []
        self._peer = (0, 0)

    def handle(self, msg) -> list:
        """The replies to one mission-protocol message."""
        kind = msg.get_type()
        mission_type = getattr(msg, "mission_type", 0)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "MISSION_REQUEST_LIST":
            count = len(self.fence.items) if mission_type == _FENCE else 0
            return [M.MAVLink_mission_count_message(*peer, count, mission_type)]
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            return self._download(msg, peer, kind == "MISSION_REQUEST_INT")
        if kind == "MISSION_CLEAR_ALL":
            if mission_type == _FENCE:
                self.fence.upload([])
            return [self._ack(peer, M.MAV_MISSION_ACCEPTED, mission_type)]
        if kind == "MISSION_COUNT":
            return self._start_upload(msg, peer, mission_type)
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._item(msg, peer, kind == "MISSION_ITEM_INT")
        return []  # MISSION_ACK closing a download

    @staticmethod
    def _ack(peer: tuple[int, int], result: int, mission_type: int):
        return M.MAVLink_mission_ack_message(*peer, result, mission_type)

    def _request(self):
        return M.MAVLink_mission_request_int_message(*self._peer, self._expected, _FENCE)

    def _start_upload(self, msg, peer: tuple[int, int], mission_type: int) -> list:
        if mission_type != _FENCE:
            return [self._ack(peer, M.MAV_MISSION_UNSUPPORTED, mission_type)]
        if msg.count > _MAX_FENCE_ITEMS:
            return [self._ack(peer, M.MAV_MISSION_NO_SPACE, mission_type)]
        self._peer, self._count, self._expected, self._received = peer, msg.count, 0, []
        if msg.count == 0:
            return [self._ack(peer, self.fence.upload([]), mission_type)]
        return [self._request()]

    def _item(self, msg, peer: tuple[int, int], integer: bool) -> list:
        if getattr(msg, "mission_type", 0) != _FENCE or self._expected >= self._count:
            return []  # not part of an upload under way
        if msg.seq != self._expected or peer != self._peer:
            return [self._request()]  # out of order: ask again for the one missing
        scale = 1e-7 if integer else 1.0
        self._received.append(FenceItem(
            msg.command, msg.frame, (msg.param1, msg.param2, msg.param3, msg.param4),
            msg.x * scale, msg.y * scale, float(msg.z)))
        self._expected += 1
        if self._expected < self._count:
            return [self._request()]
        return [self._ack(peer, self.fence.upload(self._received), _FENCE)]

    def _download(self, msg, peer: tuple[int, int], integer: bool) -> list:
        items = self.fence.items if msg.mission_type == _FENCE else ()
        if not 0 <= msg.seq < len(items):
            return [self._ack(peer, M.MAV_MISSION_INVALID_SEQUENCE, msg.mission_type)]
        item = items[msg.seq]
        if integer:
            return [M.MAVLink_mission_item_int_message(
                *peer, msg.seq, item.frame, item.command, 0, 1, *item.params,
                round(item.lat * 1e7), round(item.lon * 1e7), item.alt, _FENCE)]
        return [M.MAVLink_mission_item_message(
            *peer, msg.seq, item.frame, item.command, 0, 1, *item.params, item.lat, item.lon,
            item.alt, _FENCE)]
