"""Sony VISCA over RS-232: pure ``bytes`` encoders, an incremental parser, and decoders.

A packet is a header byte ``0x80 | sender << 4 | receiver``, 1 to 14 message
bytes (all below 0x80 for every message here, though a camera must answer one that
holds a higher byte, with a syntax error), and the terminator ``0xFF``: at most 16
bytes. The controller is address 0, cameras 1 to 7, 8 is broadcast.
Cameras hold two command buffers ("sockets" 1 and 2): a command is answered
with ACK ``z0 4y FF`` when it is taken into socket y, and Completion
``z0 5y FF`` when it is done; inquiries are answered at once with
``z0 50 <data> FF``; errors are ``z0 6y <code> FF`` (``z = 8 + camera``).

Positions travel as 4 nibbles (one per byte, most significant first), signed
16-bit two's complement for pan and tilt. Everything here is pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

from .packets import Packet

TERMINATOR = 0xFF
#: Longest legal packet, header and terminator included.
MAX_PACKET = 16
#: Receiver address of a broadcast.
BROADCAST = 8
#: Command and reply bytes (message byte 0 and, for commands, the category bytes after it).
_COMMAND, _INQUIRY = 0x01, 0x09
_PAN_TILTER, _CAMERA = 0x06, 0x04
_ABSOLUTE, _PT_POSITION, _ZOOM_DIRECT = 0x02, 0x12, 0x47
_ADDRESS_SET, _NETWORK_CHANGE = 0x30, 0x38
_IF_CLEAR = bytes((_COMMAND, 0x00, 0x01))
#: The bytes a packet can start with: a controller's to cameras 1-7 and the broadcast (``81``-``88``),
#: and a camera's to the controller (``90``, ``a0``, ... ``f0``).
HEADERS = frozenset((*range(0x81, 0x89), *range(0x90, 0xF1, 0x10)))


class ErrorCode(IntEnum):
    """The error byte of ``z0 6y <code> FF``."""

    MESSAGE_LENGTH = 0x01
    SYNTAX = 0x02
    BUFFER_FULL = 0x03
    CANCELLED = 0x04
    NO_SOCKET = 0x05
    NOT_EXECUTABLE = 0x41


class ViscaError(ValueError):
    """A packet a camera must reject; ``code`` is the error reply it answers with."""

    def __init__(self, code: ErrorCode, message: str):
        super().__init__(message)
        self.code = code


# ----------------------------------------------------------------------------------------
# Nibbles
# ----------------------------------------------------------------------------------------


def encode_nibbles(value: int, count: int = 4) -> bytes:
    """``value`` as ``count`` nibbles, most significant first; negative values in two's complement."""
    bits = 4 * count
    if not -(1 << (bits - 1)) <= value < (1 << bits):
        raise ValueError(f"{value} does not fit in {count} nibbles")
    v = value & ((1 << bits) - 1)
    return bytes((v >> (4 * (count - 1 - i))) & 0x0F for i in range(count))


def decode_nibbles(data: bytes, signed: bool) -> int:
    """Inverse of :func:`encode_nibbles`; a byte above 0x0F is a :class:`ViscaError` (syntax)."""
    if any(b > 0x0F for b in data):
        raise ViscaError(ErrorCode.SYNTAX, f"position byte above 0x0F in {data.hex(' ')}")
    v = 0
    for b in data:
        v = (v << 4) | b
    bits = 4 * len(data)
    if signed and v >= 1 << (bits - 1):
        v -= 1 << bits
    return v


# ----------------------------------------------------------------------------------------
# Controller -> camera
# ----------------------------------------------------------------------------------------


def _to(address: int, *body: int) -> bytes:
    if not 1 <= address <= BROADCAST:
        raise ValueError(f"VISCA address must be 1-8, got {address}")
    return bytes((0x80 | address, *body, TERMINATOR))


def address_set(first: int = 1) -> bytes:
    """AddressSet broadcast ``88 30 0w FF``: the first camera on the chain takes address ``first``."""
    return _to(BROADCAST, _ADDRESS_SET, first)


def if_clear(address: int = BROADCAST) -> bytes:
    """IF_Clear ``8x 01 00 01 FF``: empty the camera's command buffers (broadcast by default)."""
    return _to(address, *_IF_CLEAR)


def cancel(address: int, socket: int) -> bytes:
    """Cancel ``8x 2y FF``: stop the command in socket ``y``."""
    return _to(address, 0x20 | socket)


def pan_tilt_absolute(address: int, pan_speed: int, tilt_speed: int, pan: int, tilt: int) -> bytes:
    """Pan-tilt absolute position ``8x 01 06 02 VV WW 0Y0Y0Y0Y 0Z0Z0Z0Z FF`` (positions in device units)."""
    return _to(address, _COMMAND, _PAN_TILTER, _ABSOLUTE, pan_speed, tilt_speed,
               *encode_nibbles(pan), *encode_nibbles(tilt))


def zoom_direct(address: int, position: int) -> bytes:
    """Zoom direct ``8x 01 04 47 0p0q0r0s FF`` (0 is wide)."""
    if position < 0:
        raise ValueError(f"zoom position must be >= 0, got {position}")
    return _to(address, _COMMAND, _CAMERA, _ZOOM_DIRECT, *encode_nibbles(position))


def pan_tilt_position_inquiry(address: int) -> bytes:
    """Pan-tilt position inquiry ``8x 09 06 12 FF``."""
    return _to(address, _INQUIRY, _PAN_TILTER, _PT_POSITION)


def zoom_position_inquiry(address: int) -> bytes:
    """Zoom position inquiry ``8x 09 04 47 FF``."""
    return _to(address, _INQUIRY, _CAMERA, _ZOOM_DIRECT)


# ----------------------------------------------------------------------------------------
# Camera -> controller
# ----------------------------------------------------------------------------------------


def _from(address: int, *body: int) -> bytes:
    if not 1 <= address <= 7:
        raise ValueError(f"VISCA camera address must be 1-7, got {address}")
    return bytes((0x80 | (address << 4), *body, TERMINATOR))


def ack(address: int, socket: int) -> bytes:
    """ACK ``z0 4y FF``: the command was taken into socket ``y``."""
    return _from(address, 0x40 | socket)


def completion(address: int, socket: int, payload: bytes = b"") -> bytes:
    """Completion ``z0 5y FF``; with ``socket`` 0 and a payload, an inquiry's answer."""
    return _from(address, 0x50 | socket, *payload)


def error(address: int, socket: int, code: ErrorCode) -> bytes:
    """Error ``z0 6y <code> FF``."""
    return _from(address, 0x60 | socket, int(code))


def network_change(address: int) -> bytes:
    """Network Change ``z0 38 FF``: a camera was (re)connected; the controller must re-address."""
    return _from(address, _NETWORK_CHANGE)


def address_set_reply(next_address: int) -> bytes:
    """What comes back from the last camera of an AddressSet: ``88 30 0w FF``, ``w`` = its address + 1."""
    return _to(BROADCAST, _ADDRESS_SET, next_address)


def if_clear_reply() -> bytes:
    """A broadcast IF_Clear comes back unchanged from the last camera of the chain."""
    return if_clear(BROADCAST)


def pan_tilt_position_reply(address: int, pan: int, tilt: int) -> bytes:
    """Answer to the pan-tilt position inquiry: ``z0 50 0w0w0w0w 0z0z0z0z FF``."""
    return completion(address, 0, encode_nibbles(pan) + encode_nibbles(tilt))


def zoom_position_reply(address: int, position: int) -> bytes:
    """Answer to the zoom position inquiry: ``z0 50 0p0q0r0s FF``."""
    return completion(address, 0, encode_nibbles(position))


# ----------------------------------------------------------------------------------------
# Framing
# ----------------------------------------------------------------------------------------


class ViscaParser:
    """Incremental VISCA framing: feed any chunks, get whole packets back.

    A packet starts at a header byte (:data:`HEADERS`) and ends at 0xFF. A header
    byte met inside a packet starts a new one (the unterminated one is dropped as
    garbage), so a valid packet is found whatever garbage precedes it; any other
    byte, 0x80 and above included, belongs to the packet (a camera answers such a
    packet with a syntax error, as a real one does). Bytes outside packets are
    counted in ``garbage_bytes``. A packet longer than :data:`MAX_PACKET` is
    reported once, at its terminator, as a :class:`Packet` with ``error="overlong"``;
    one of fewer than 3 bytes (``8x FF``) with ``error="short"``; both make a camera
    answer "message length error".
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._start = 0
        self._offset = 0
        self._overlong = False
        self.garbage_bytes = 0

    def feed(self, data: bytes) -> list[Packet]:
        """Consume ``data``; return the packets it completed, in order."""
        out: list[Packet] = []
        buf = self._buf
        for i, b in enumerate(data):
            pos = self._offset + i
            if b == TERMINATOR:
                if not buf:
                    self.garbage_bytes += 1
                    continue
                out.append(_packet(bytes(buf), self._start, pos + 1, self._overlong))
                buf.clear()
                self._overlong = False
            elif b in HEADERS:
                self.garbage_bytes += pos - self._start if buf else 0
                buf[:] = bytes((b,))
                self._start = pos
                self._overlong = False
            elif buf:
                if len(buf) < MAX_PACKET - 1:
                    buf.append(b)
                else:
                    self._overlong = True
            else:
                self.garbage_bytes += 1
        self._offset += len(data)
        return out


def _packet(head: bytes, start: int, end: int, overlong: bool) -> Packet:
    """A terminated packet whose bytes before the terminator are ``head`` (its first 15 if ``overlong``)."""
    if overlong:
        return Packet(head, start, end, "overlong")
    if len(head) < 2:
        return Packet(head + b"\xff", start, end, "short")
    return Packet(head + b"\xff", start, end)


def message(payload: bytes) -> Packet:
    """One VISCA-over-IP payload as one packet: a datagram is one message, never resynchronised.

    ``error`` is ``"unterminated"`` when it does not end at its only 0xFF, else as
    :class:`ViscaParser` reports (``"short"``, ``"overlong"``)."""
    if not payload or payload[-1] != TERMINATOR or TERMINATOR in payload[:-1]:
        return Packet(bytes(payload[:MAX_PACKET - 1]), 0, len(payload), "unterminated")
    head = bytes(payload[:-1])
    return _packet(head[:MAX_PACKET - 1], 0, len(payload), len(head) > MAX_PACKET - 1)


# ----------------------------------------------------------------------------------------
# Decoding
# ----------------------------------------------------------------------------------------

ReplyKind = Literal["ack", "completion", "error", "network_change", "address_set", "if_clear"]


@dataclass(frozen=True)
class Reply:
    """A packet from a camera. ``address`` is the camera's (0 for the broadcasts that come back)."""

    kind: ReplyKind
    address: int
    socket: int = 0
    payload: bytes = b""
    code: int = 0


def decode_reply(packet: bytes) -> Reply | None:
    """Classify a well-framed packet sent by a camera; ``None`` if it is not one (e.g. a command)."""
    if len(packet) < 3 or packet[-1] != TERMINATOR:
        return None
    header, body = packet[0], packet[1:-1]
    if header == 0x80 | BROADCAST:
        if len(body) == 2 and body[0] == _ADDRESS_SET:
            return Reply("address_set", 0, payload=bytes(body[1:]))
        if body == _IF_CLEAR:
            return Reply("if_clear", 0)
        return None
    sender, receiver = (header >> 4) & 0x07, header & 0x0F
    if receiver != 0 or sender == 0:
        return None
    kind, socket = body[0] & 0xF0, body[0] & 0x0F
    if kind == 0x40 and len(body) == 1:
        return Reply("ack", sender, socket)
    if kind == 0x50:
        return Reply("completion", sender, socket, payload=bytes(body[1:]))
    if kind == 0x60 and len(body) == 2:
        return Reply("error", sender, socket, code=body[1])
    if body == bytes((_NETWORK_CHANGE,)):
        return Reply("network_change", sender)
    return None


CommandKind = Literal["address_set", "if_clear", "cancel", "pan_tilt_absolute", "zoom_direct",
                      "pan_tilt_inquiry", "zoom_inquiry"]


@dataclass(frozen=True)
class Command:
    """A packet to a camera. ``args``: address_set (w,), cancel (socket,),
    pan_tilt_absolute (pan_speed, tilt_speed, pan, tilt), zoom_direct (position,)."""

    kind: CommandKind
    receiver: int
    args: tuple[int, ...] = ()


def decode_command(packet: bytes) -> Command:
    """Parse a well-framed packet sent to a camera; :class:`ViscaError` says which error to answer."""
    if len(packet) < 3:
        raise ViscaError(ErrorCode.MESSAGE_LENGTH, f"packet of {len(packet)} bytes")
    if len(packet) > MAX_PACKET:
        raise ViscaError(ErrorCode.MESSAGE_LENGTH, f"packet of {len(packet)} bytes, at most {MAX_PACKET}")
    header, body = packet[0], packet[1:-1]
    receiver = header & 0x0F
    if header >> 4 != 0x8 or not 1 <= receiver <= BROADCAST:
        raise ViscaError(ErrorCode.SYNTAX, f"header 0x{header:02x} is not from a controller")
    if len(body) == 2 and body[0] == _ADDRESS_SET and receiver == BROADCAST:
        return Command("address_set", receiver, (body[1],))
    if body == _IF_CLEAR:
        return Command("if_clear", receiver)
    if len(body) == 1 and body[0] & 0xF0 == 0x20:
        return Command("cancel", receiver, (body[0] & 0x0F,))
    if body[:3] == bytes((_COMMAND, _PAN_TILTER, _ABSOLUTE)) and len(body) == 13:
        pan = decode_nibbles(body[5:9], signed=True)
        tilt = decode_nibbles(body[9:13], signed=True)
        return Command("pan_tilt_absolute", receiver, (body[3], body[4], pan, tilt))
    if body[:3] == bytes((_COMMAND, _CAMERA, _ZOOM_DIRECT)) and len(body) == 7:
        return Command("zoom_direct", receiver, (decode_nibbles(body[3:7], signed=False),))
    if body == bytes((_INQUIRY, _PAN_TILTER, _PT_POSITION)):
        return Command("pan_tilt_inquiry", receiver)
    if body == bytes((_INQUIRY, _CAMERA, _ZOOM_DIRECT)):
        return Command("zoom_inquiry", receiver)
    raise ViscaError(ErrorCode.SYNTAX, f"unknown or malformed message {body.hex(' ')}")
