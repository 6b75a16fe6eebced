"""VISCA over IP (Sony's UDP framing, port 52381): the 8-byte header, the camera's side, the driver's port.

Every datagram is an 8-byte big-endian header, then 1-16 payload bytes::

    payload type (2) | payload length (2) | sequence number (4) | payload

Payload types: ``0x0100`` VISCA command, ``0x0110`` VISCA inquiry, ``0x0111`` VISCA
reply, ``0x0200`` control command, ``0x0201`` control reply. The control command
``01`` (RESET) resets the camera's sequence number and is answered ``01``; a
message whose sequence number goes backwards gets the control reply ``0F 01``
(sequence number error), a malformed one ``0F 02`` (message error). A reply
carries the sequence number of the message it answers (an ACK and the later
completion both carry the command's).

- :func:`frame` / :func:`unframe`: pure encoding and decoding.
- :class:`ViscaIpCamera`: the camera's side, datagram in, datagrams out, around a
  :class:`~runtime.ptz.emulator.ViscaCamera` (no socket, no clock: the emulator and the
  fuzz tests drive it).
- :class:`ViscaIpPort`: the driver's side, a port-like object (``write`` one VISCA packet,
  ``read`` the VISCA replies) over a connected UDP socket: RESET when it opens, a fresh
  sequence number per packet, retries of an unanswered packet (same sequence number, so
  the camera does not execute it twice), replies accepted only when their sequence number
  is one it sent, a RESET again after a sequence error (the unanswered packets are
  then sent again under new numbers), and a keep-alive inquiry after :data:`KEEPALIVE_S`
  of silence (its answer is kept by the port; none, after the retries, is a lost link).
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from urllib.parse import urlsplit

from .errors import PtzPortError
from .visca import ErrorCode, ViscaParser, error, message, pan_tilt_position_inquiry

DEFAULT_PORT = 52381
HEADER = struct.Struct(">HHI")
COMMAND, INQUIRY, REPLY, CONTROL, CONTROL_REPLY = 0x0100, 0x0110, 0x0111, 0x0200, 0x0201
PAYLOAD_TYPES = (COMMAND, INQUIRY, REPLY, CONTROL, CONTROL_REPLY)
MAX_PAYLOAD = 16
RESET = b"\x01"
SEQUENCE_ERROR = b"\x0f\x01"
MESSAGE_ERROR = b"\x0f\x02"
#: Sequence numbers are 32-bit; the driver starts again from 1 well before they wrap.
_SEQ_LIMIT = 0xFFFF_FFFF
#: How many sequence numbers a port remembers as its own (a completion may come seconds after its ACK).
_SEQS_KEPT = 256
#: Retries of an unanswered packet, and the wait before each, as a fraction of the link's ACK time-out.
RETRIES = 2
_RETRY_FRACTION = 0.3
#: After this long (s) without a datagram from the camera, the port asks its position itself (and keeps
#: the answer): UDP has no connection, so an idle driver would not notice a camera gone until its next
#: command. An unanswered keep-alive (after its retries) is a lost link.
KEEPALIVE_S = 1.0


@dataclass(frozen=True)
class Datagram:
    payload_type: int
    seq: int
    payload: bytes


def frame(payload_type: int, seq: int, payload: bytes) -> bytes:
    """One datagram; ``ValueError`` if the payload is empty or longer than 16 bytes."""
    if not 1 <= len(payload) <= MAX_PAYLOAD:
        raise ValueError(f"VISCA over IP payload of {len(payload)} bytes, expected 1-{MAX_PAYLOAD}")
    return HEADER.pack(payload_type, len(payload), seq & _SEQ_LIMIT) + payload


def unframe(data: bytes) -> Datagram | None:
    """The datagram's fields, or ``None`` if it is malformed (short, wrong length, unknown type)."""
    if len(data) < HEADER.size + 1:
        return None
    payload_type, length, seq = HEADER.unpack_from(data)
    payload = bytes(data[HEADER.size:])
    if payload_type not in PAYLOAD_TYPES or length != len(payload) or length > MAX_PAYLOAD:
        return None
    return Datagram(payload_type, seq, payload)


def parse_url(url: str) -> tuple[str, int]:
    """``visca-udp://HOST[:PORT]`` -> (host, port); :class:`PtzPortError` (one line) if malformed."""
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise PtzPortError(f"{url}: expected visca-udp://HOST[:PORT] ({exc})") from None
    if parts.scheme.lower() != "visca-udp" or not parts.hostname or parts.path not in ("", "/") or parts.query:
        raise PtzPortError(f"{url}: expected visca-udp://HOST[:PORT] (port {DEFAULT_PORT} by default)")
    return parts.hostname, port if port is not None else DEFAULT_PORT


# ----------------------------------------------------------------------------------------
# The camera's side
# ----------------------------------------------------------------------------------------


class ViscaIpCamera:
    """A VISCA camera behind the IP framing: :meth:`receive` a datagram, :meth:`tick` for completions.

    Both return datagrams to send back. A datagram is one VISCA message, never
    resynchronised: a payload that does not end at its only 0xFF gets a message error, one
    the camera cannot parse (an unknown command, a byte of 0x80 or above in its body, a
    header that is not a controller's) a syntax error ``90 60 02 FF`` in a reply with its
    sequence number. A repeated sequence number (the controller's retry) is answered with
    the replies already given, without executing again; one lower than the last is a
    sequence error; a malformed header gets a message error (or nothing, if not even its
    header can be read). ``errors`` counts the framing errors, the camera's own ``errors``
    the rest.
    """

    def __init__(self, camera) -> None:
        self.camera = camera
        self.last_seq: int | None = None
        self._last_replies: list[bytes] = []
        self._socket_seq: dict[int, int] = {}
        self.errors = 0
        self.resets = 0

    def receive(self, data: bytes, now: float) -> list[bytes]:
        d = unframe(data)
        if d is None:
            self.errors += 1
            if len(data) >= HEADER.size:
                return [frame(CONTROL_REPLY, HEADER.unpack_from(data)[2], MESSAGE_ERROR)]
            return []
        if d.payload_type == CONTROL:
            if d.payload != RESET:
                self.errors += 1
                return [frame(CONTROL_REPLY, d.seq, MESSAGE_ERROR)]
            self.last_seq, self._last_replies = None, []
            self.resets += 1
            return [frame(CONTROL_REPLY, d.seq, RESET)]
        if d.payload_type not in (COMMAND, INQUIRY):
            self.errors += 1
            return [frame(CONTROL_REPLY, d.seq, MESSAGE_ERROR)]
        if self.last_seq is not None:
            if d.seq == self.last_seq:
                return list(self._last_replies)
            if d.seq < self.last_seq:
                self.errors += 1
                return [frame(CONTROL_REPLY, d.seq, SEQUENCE_ERROR)]
        self.last_seq = d.seq
        packet = message(d.payload)
        if packet.error == "unterminated":
            self.errors += 1
            self._last_replies = [frame(CONTROL_REPLY, d.seq, MESSAGE_ERROR)]
        elif packet.data[0] >> 4 != 0x8:  # not a controller's header: a message the camera cannot parse
            self.camera.errors += 1
            self._last_replies = [frame(REPLY, d.seq, error(self.camera.address, 0, ErrorCode.SYNTAX))]
        else:
            self._last_replies = self._wrap(self.camera.receive(packet, now), d.seq)
        return list(self._last_replies)

    def tick(self, now: float) -> list[bytes]:
        return self._wrap(self.camera.tick(now), None)

    def _wrap(self, replies: list[bytes], seq: int | None) -> list[bytes]:
        """VISCA replies -> datagrams: an ACK takes the command's number and lends it to its socket's
        completion or error; replies without a socket take the current message's number."""
        out = []
        for reply in replies:
            socket_ = reply[1] & 0x0F if len(reply) > 2 and reply[0] & 0x80 else 0
            kind = reply[1] & 0xF0 if len(reply) > 2 else 0
            if kind == 0x40 and seq is not None:
                self._socket_seq[socket_] = seq
                n = seq
            elif socket_ and kind in (0x50, 0x60) and socket_ in self._socket_seq:
                n = self._socket_seq.pop(socket_) if kind == 0x50 or seq is None else seq
            else:
                n = seq if seq is not None else 0
            out.append(frame(REPLY, n, reply))
        return out

    def network_change(self) -> bytes:
        return frame(REPLY, 0, self.camera.network_change())


# ----------------------------------------------------------------------------------------
# The driver's side
# ----------------------------------------------------------------------------------------


@dataclass
class _Outstanding:
    datagram: bytes
    sent_at: float
    tries: int = 1


class ViscaIpPort:
    """A connected UDP socket that looks like a serial port to :class:`~runtime.ptz.driver.PtzDriver`.

    ``write`` takes VISCA packets, ``read`` returns the VISCA bytes of the replies whose
    sequence number this port sent. ``counters`` (shared with the driver, kept across
    reconnects) counts ``retries``, ``sequence_errors``, ``message_errors``, ``resets``,
    ``stale_replies`` (a number it did not send, or no longer remembers) and
    ``malformed_datagrams``. Opening sends RESET and waits for its answer: a camera that
    does not answer is an ``OSError``, so the driver backs off and tries again.
    """

    def __init__(self, host: str, port: int, *, timeout: float, ack_timeout_s: float,
                 counters: dict | None = None, camera: int = 1) -> None:
        self.address = (host, port)
        self.camera = camera
        self.timeout = timeout
        self._retry_s = max(0.02, _RETRY_FRACTION * ack_timeout_s)
        self.counters = counters if counters is not None else {}
        for key in ("retries", "sequence_errors", "message_errors", "resets", "stale_replies", "malformed_datagrams",
                    "keepalives"):
            self.counters.setdefault(key, 0)
        self._lock = threading.Lock()
        self._buffer = bytearray()
        self._outstanding: OrderedDict[int, _Outstanding] = OrderedDict()
        self._mine: OrderedDict[int, None] = OrderedDict()
        self._seq = 0
        self._closed = False
        self._keepalive: int | None = None
        self._dead: str | None = None
        self._heard = time.monotonic()
        self._sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.connect(self.address)
            self._sock.settimeout(timeout)
            self._reset_handshake(ack_timeout_s)
        except BaseException:
            self._sock.close()
            raise

    # -- what the driver and transports call --------------------------------------------------

    @staticmethod
    def check_url(url: str) -> None:
        parse_url(url)

    @classmethod
    def open(cls, url: str, *, timeout: float, link, counters: dict, address: int = 1) -> ViscaIpPort:
        host, port = parse_url(url)
        return cls(host, port, timeout=timeout, ack_timeout_s=link.ack_timeout_s, counters=counters, camera=address)

    @property
    def in_waiting(self) -> int:
        return len(self._buffer)

    def reset_input_buffer(self) -> None:
        with self._lock:
            self._buffer.clear()

    def write(self, data: bytes) -> int:
        """Send each VISCA packet in ``data`` in its own datagram, under a fresh sequence number."""
        for packet in ViscaParser().feed(bytes(data)):
            kind = INQUIRY if len(packet.data) > 1 and packet.data[1] == 0x09 else COMMAND
            with self._lock:
                seq = self._next_seq()
                datagram = frame(kind, seq, packet.data[:MAX_PAYLOAD])
                self._outstanding[seq] = _Outstanding(datagram, time.monotonic())
                self._remember(seq)
                self._sock.send(datagram)
        return len(data)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes of VISCA replies; waits at most ``timeout`` s for a datagram."""
        if not self._buffer:
            self._retry_due()
            if self._dead:
                raise OSError(self._dead)
            try:
                data = self._sock.recv(2048)
            except TimeoutError:
                return b""
            except OSError:
                if self._closed:
                    return b""
                raise
            self._take(data)
        with self._lock:
            out = bytes(self._buffer[:size])
            del self._buffer[:size]
        return out

    def cancel_read(self) -> None:
        """Nothing to cancel: a read waits at most ``timeout`` s."""

    def close(self) -> None:
        self._closed = True
        self._sock.close()

    # -- inside ---------------------------------------------------------------------------

    def _next_seq(self) -> int:
        self._seq = self._seq + 1 if self._seq < _SEQ_LIMIT else 1
        return self._seq

    def _remember(self, seq: int) -> None:
        self._mine[seq] = None
        while len(self._mine) > _SEQS_KEPT:
            self._mine.popitem(last=False)

    def _reset_handshake(self, ack_timeout_s: float) -> None:
        deadline = time.monotonic() + ack_timeout_s
        while True:
            self._sock.send(frame(CONTROL, 0, RESET))
            wait_until = min(deadline, time.monotonic() + self._retry_s)
            while (left := wait_until - time.monotonic()) > 0:
                self._sock.settimeout(left)
                try:
                    d = unframe(self._sock.recv(2048))
                except TimeoutError:
                    break
                if d is not None and d.payload_type == CONTROL_REPLY and d.payload == RESET:
                    self._sock.settimeout(self.timeout)
                    self._seq = 0
                    self.counters["resets"] += 1
                    return
            if time.monotonic() >= deadline:
                raise OSError(f"no answer to VISCA over IP RESET from {self.address[0]}:{self.address[1]} "
                              f"within {ack_timeout_s:g} s")

    def _take(self, data: bytes) -> None:
        d = unframe(data)
        with self._lock:
            self._heard = time.monotonic()
            if d is None or d.payload_type not in (REPLY, CONTROL_REPLY):
                self.counters["malformed_datagrams"] += 1
                return
            if d.payload_type == CONTROL_REPLY:
                if d.payload == SEQUENCE_ERROR:
                    self.counters["sequence_errors"] += 1
                    self._resequence()
                elif d.payload == MESSAGE_ERROR:
                    self.counters["message_errors"] += 1
                    self._outstanding.pop(d.seq, None)
                elif d.payload != RESET:
                    self.counters["malformed_datagrams"] += 1
                return
            if message(d.payload).error == "unterminated":  # one datagram, one message: nothing to resynchronise
                self.counters["malformed_datagrams"] += 1
                return
            if d.seq not in self._mine:
                self.counters["stale_replies"] += 1
                return
            self._outstanding.pop(d.seq, None)
            if d.seq == self._keepalive:
                self._keepalive = None
                return
            self._buffer += d.payload

    def _resequence(self) -> None:
        """After a sequence error: RESET, and send what is unanswered again under new numbers (lock held)."""
        self._sock.send(frame(CONTROL, 0, RESET))
        self.counters["resets"] += 1
        self._seq = 0
        self._outstanding.pop(self._keepalive, None)
        self._keepalive = None
        pending, self._outstanding = list(self._outstanding.values()), OrderedDict()
        now = time.monotonic()
        for o in pending:
            seq = self._next_seq()
            kind, _, _ = HEADER.unpack_from(o.datagram)
            datagram = frame(kind, seq, o.datagram[HEADER.size:])
            self._outstanding[seq] = _Outstanding(datagram, now)
            self._remember(seq)
            self._sock.send(datagram)

    def _retry_due(self) -> None:
        """Send again (same number) the newest packet if unanswered after the retry interval; give up after
        :data:`RETRIES` (the driver's ACK time-out then counts it). An older unanswered packet is not sent
        again: a number below one already sent is a sequence error to the camera."""
        now = time.monotonic()
        with self._lock:
            if self._keepalive is None and now - self._heard > KEEPALIVE_S and not self._outstanding:
                self._keepalive = self._next_seq()
                datagram = frame(INQUIRY, self._keepalive, pan_tilt_position_inquiry(self.camera))
                self._outstanding[self._keepalive] = _Outstanding(datagram, now)
                self._remember(self._keepalive)
                self.counters["keepalives"] += 1
                self._sock.send(datagram)
            newest = next(reversed(self._outstanding), None)
            for seq, o in list(self._outstanding.items()):
                if now - o.sent_at < self._retry_s:
                    continue
                if seq != newest:  # a later number went out: the camera would take a retry for a sequence error
                    del self._outstanding[seq]
                    if seq == self._keepalive:
                        self._keepalive = None
                    continue
                if o.tries > RETRIES:
                    del self._outstanding[seq]
                    if seq == self._keepalive:
                        self._dead = (f"no answer from {self.address[0]}:{self.address[1]} to a keep-alive inquiry "
                                      f"after {1 + RETRIES} tries")
                    continue
                o.tries += 1
                o.sent_at = now
                self.counters["retries"] += 1
                self._sock.send(o.datagram)


__all__ = ["DEFAULT_PORT", "Datagram", "ViscaIpCamera", "ViscaIpPort", "frame", "parse_url", "unframe"]
