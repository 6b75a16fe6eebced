"""Pelco-D over RS-485/RS-232: pure ``bytes`` encoders, an incremental parser, and decoders.

A command is 7 bytes: sync ``0xFF``, address (1-255), command 1, command 2,
data 1, data 2, and a checksum, the sum of bytes 2 to 6 modulo 256. Extended
commands (command 2 odd, command 1 zero) set absolute positions: pan ``0x4B``
and tilt ``0x4D`` in hundredths of a degree (0 to 35999), zoom ``0x4F`` as a
fraction of the lens's range scaled to 0-65535; queries ``0x51``, ``0x53``,
``0x55`` are answered with ``0x59``, ``0x5B``, ``0x5D`` carrying the value.
Devices that answer every other command do so with the 4-byte general response
``FF addr alarms checksum``. Pelco-D has no error replies: a device ignores a
packet with a bad checksum. Everything here is pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

from .packets import Packet

SYNC = 0xFF
FRAME_LEN = 7
GENERAL_LEN = 4
#: One turn in the protocol's angle unit (hundredths of a degree).
FULL_TURN = 36000

SET_PAN, SET_TILT, SET_ZOOM = 0x4B, 0x4D, 0x4F
QUERY_PAN, QUERY_TILT, QUERY_ZOOM = 0x51, 0x53, 0x55
REPLY_PAN, REPLY_TILT, REPLY_ZOOM = 0x59, 0x5B, 0x5D
SET_PRESET, CLEAR_PRESET, GO_TO_PRESET = 0x03, 0x05, 0x07
#: The extended-response opcodes this module knows (position answers).
REPLY_OPCODES = frozenset((REPLY_PAN, REPLY_TILT, REPLY_ZOOM))
#: Which answer each query gets.
QUERY_REPLY = {QUERY_PAN: REPLY_PAN, QUERY_TILT: REPLY_TILT, QUERY_ZOOM: REPLY_ZOOM}
#: Command 1 bits 5 and 6 are reserved (zero) in every Pelco-D command.
_RESERVED = 0x60


def checksum(body: bytes) -> int:
    """Pelco-D checksum: the sum of the bytes after the sync byte, modulo 256."""
    return sum(body) & 0xFF


def frame(address: int, cmd1: int, cmd2: int, data1: int = 0, data2: int = 0) -> bytes:
    """A 7-byte Pelco-D packet with its checksum."""
    if not 1 <= address <= 255:
        raise ValueError(f"Pelco-D address must be 1-255, got {address}")
    body = bytes((address, cmd1, cmd2, data1, data2))
    return bytes((SYNC,)) + body + bytes((checksum(body),))


def _value(address: int, opcode: int, value: int) -> bytes:
    if not 0 <= value <= 0xFFFF:
        raise ValueError(f"Pelco-D data value must be 0-65535, got {value}")
    return frame(address, 0x00, opcode, value >> 8, value & 0xFF)


def wrap_angle(units: int) -> int:
    """A signed angle in hundredths of a degree as Pelco-D sends it: 0 to 35999."""
    return units % FULL_TURN


def unwrap_angle(value: int) -> int:
    """Inverse of :func:`wrap_angle`, into (-18000, 18000]."""
    value %= FULL_TURN
    return value - FULL_TURN if value > FULL_TURN // 2 else value


# ----------------------------------------------------------------------------------------
# Controller -> device
# ----------------------------------------------------------------------------------------


def set_pan_position(address: int, units: int) -> bytes:
    """Set pan position (0x4B), ``units`` in hundredths of a degree (wrapped to 0-35999)."""
    return _value(address, SET_PAN, wrap_angle(units))


def set_tilt_position(address: int, units: int) -> bytes:
    """Set tilt position (0x4D), ``units`` in hundredths of a degree (wrapped to 0-35999)."""
    return _value(address, SET_TILT, wrap_angle(units))


def set_zoom_position(address: int, position: int) -> bytes:
    """Set zoom position (0x4F), 0 (wide) to 65535 (tele)."""
    return _value(address, SET_ZOOM, position)


def query(address: int, opcode: int) -> bytes:
    """Position query: ``QUERY_PAN``, ``QUERY_TILT`` or ``QUERY_ZOOM``."""
    if opcode not in QUERY_REPLY:
        raise ValueError(f"not a Pelco-D position query: 0x{opcode:02x}")
    return frame(address, 0x00, opcode)


def preset(address: int, opcode: int, number: int) -> bytes:
    """Set (0x03), clear (0x05) or go to (0x07) preset ``number`` (1-255)."""
    if opcode not in (SET_PRESET, CLEAR_PRESET, GO_TO_PRESET):
        raise ValueError(f"not a Pelco-D preset command: 0x{opcode:02x}")
    if not 1 <= number <= 255:
        raise ValueError(f"preset number must be 1-255, got {number}")
    return frame(address, 0x00, opcode, 0x00, number)


def stop(address: int) -> bytes:
    """Stop all motion (all command bits clear)."""
    return frame(address, 0x00, 0x00)


# ----------------------------------------------------------------------------------------
# Device -> controller
# ----------------------------------------------------------------------------------------


def position_reply(address: int, opcode: int, value: int) -> bytes:
    """Extended response ``FF addr 00 opcode MSB LSB checksum`` (``REPLY_PAN`` ...)."""
    if opcode not in REPLY_OPCODES:
        raise ValueError(f"not a Pelco-D position reply: 0x{opcode:02x}")
    return _value(address, opcode, value)


def general_response(address: int, alarms: int = 0) -> bytes:
    """General response ``FF addr alarms checksum``."""
    body = bytes((address, alarms))
    return bytes((SYNC,)) + body + bytes((checksum(body),))


# ----------------------------------------------------------------------------------------
# Framing and decoding
# ----------------------------------------------------------------------------------------


def _is_command(candidate: bytes) -> bool:
    """A 7-byte candidate with a good checksum and clear reserved bits (extended: command 1 zero)."""
    cmd1, cmd2 = candidate[2], candidate[3]
    if cmd1 & _RESERVED or (cmd2 & 1 and cmd1):
        return False
    return candidate[6] == checksum(candidate[1:6])


class PelcoDParser:
    """Incremental Pelco-D framing that resynchronises on garbage.

    At each sync byte it waits for a whole candidate; a candidate that fails its
    checksum (or sets reserved bits) costs one byte, and the search goes on at
    the next sync byte, so a burst of noise loses at most the packets it
    overlaps. ``replies=False`` reads what a device receives (7-byte commands);
    ``replies=True`` reads what a controller receives: position answers (7
    bytes, opcode in :data:`REPLY_OPCODES`) and general responses (4 bytes).
    Skipped bytes are counted in ``garbage_bytes``, candidates that failed in
    ``rejected``.

    Pelco-D has no escaping, so noise that happens to form a checksum-valid
    candidate (about 1 in 256 sync bytes in random noise, fewer with the
    structural checks) is returned as a packet; a caller checks the address
    and opcode it expects.
    """

    def __init__(self, replies: bool = False) -> None:
        self.replies = replies
        self._buf = bytearray()
        self._offset = 0
        self.garbage_bytes = 0
        self.rejected = 0

    def _skip(self, n: int) -> None:
        del self._buf[:n]
        self._offset += n
        self.garbage_bytes += n

    def _take(self, n: int, out: list[Packet]) -> None:
        out.append(Packet(bytes(self._buf[:n]), self._offset, self._offset + n))
        del self._buf[:n]
        self._offset += n

    def feed(self, data: bytes) -> list[Packet]:
        """Consume ``data``; return the packets it completed, in order."""
        self._buf += data
        out: list[Packet] = []
        buf = self._buf
        while buf:
            i = buf.find(SYNC)
            if i < 0:
                self._skip(len(buf))
                break
            if i:
                self._skip(i)
            if self.replies:
                if len(buf) < GENERAL_LEN:
                    break
                if buf[2] == 0 and buf[3] in REPLY_OPCODES:
                    if len(buf) < FRAME_LEN:
                        break
                    if buf[6] == checksum(buf[1:6]):
                        self._take(FRAME_LEN, out)
                        continue
                if buf[3] == checksum(buf[1:3]):
                    self._take(GENERAL_LEN, out)
                    continue
                self.rejected += 1
                self._skip(1)
            else:
                if len(buf) < FRAME_LEN:
                    break
                if _is_command(bytes(buf[:FRAME_LEN])):
                    self._take(FRAME_LEN, out)
                else:
                    self.rejected += 1
                    self._skip(1)
        return out


@dataclass(frozen=True)
class Message:
    """A decoded 7-byte packet; ``value`` is data 1 and 2 as one 16-bit number."""

    address: int
    cmd1: int
    cmd2: int
    data1: int
    data2: int

    @property
    def value(self) -> int:
        return (self.data1 << 8) | self.data2


@dataclass(frozen=True)
class GeneralResponse:
    """A decoded 4-byte general response."""

    address: int
    alarms: int


def decode(packet: bytes) -> Message | GeneralResponse:
    """Decode a packet framed by :class:`PelcoDParser` (checksum already checked)."""
    if len(packet) == GENERAL_LEN:
        return GeneralResponse(packet[1], packet[2])
    if len(packet) != FRAME_LEN:
        raise ValueError(f"Pelco-D packets are 4 or 7 bytes, got {len(packet)}")
    return Message(*packet[1:6])
