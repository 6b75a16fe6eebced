"""A PTZ camera on a pseudo-terminal: what ``omnijax ptz-emulator`` runs, and what the tests drive.

:class:`ViscaCamera` and :class:`PelcoDCamera` are the devices: bytes in, reply
bytes out, with slew-rate-limited motion from the device profile (time is
passed in, so they are testable without a clock). :class:`PtyEmulator` puts one
on a pseudo-terminal (``os.openpty``): a client opens the slave path with
pyserial exactly as it would open ``/dev/ttyUSB0``.

VISCA behaviour: two sockets; a motion command is ACKed and completed when the
motion ends; a new pan-tilt (or zoom) command replaces a running one, whose
socket completes at once (so "buffer full" comes only from injected faults);
out-of-range speeds are syntax errors, positions beyond the limits "not
executable", over-long or short packets "message length", unknown messages
"syntax"; Cancel answers "cancelled" or "no socket"; AddressSet and IF_Clear
work as on a daisy chain whose ``chain_position``-th camera this is. Pelco-D
behaviour: absolute pan/tilt/zoom at the profile's top speed (pan the short way
round when it turns fully), position queries, presets, a general response to
each accepted command when the profile says so; packets with a bad checksum,
unsupported commands and out-of-range values are ignored and counted as errors.
Motion is at constant speed (no acceleration ramps).

Faults can be injected (:class:`Faults`): garbled, dropped or noisy replies,
and (VISCA) "buffer full" answers.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import select
import socket as _socket
import threading
import time
import tty
from dataclasses import dataclass
from pathlib import Path

from . import pelco_d, visca
from .packets import Packet
from .pelco_d import PelcoDParser
from .profile import DeviceProfile
from .visca import ErrorCode, ViscaError, ViscaParser

#: Emulator loop period while something moves, and when idle (s).
_TICK_MOVING_S = 0.005
_TICK_IDLE_S = 0.05
#: Shortest interval between two state-file writes (s).
_STATE_INTERVAL_S = 0.05


@dataclass(frozen=True)
class Faults:
    """Probabilities of injected faults, per reply (``buffer_full``: per VISCA motion command)."""

    garble: float = 0.0
    drop: float = 0.0
    noise: float = 0.0
    buffer_full: float = 0.0

    @classmethod
    def parse(cls, text: str) -> Faults:
        """From ``"garble=0.05,drop=0.01"``; a bad entry is a one-line ``ValueError``."""
        values = {}
        for item in filter(None, (s.strip() for s in text.split(","))):
            name, _, value = item.partition("=")
            if name not in cls.__dataclass_fields__:
                raise ValueError(f"unknown fault {name!r}, expected one of {', '.join(cls.__dataclass_fields__)}")
            try:
                p = float(value)
            except ValueError:
                raise ValueError(f"fault {name}: expected a probability, got {value!r}") from None
            if not 0 <= p <= 1:
                raise ValueError(f"fault {name}: expected a probability in [0, 1], got {p}")
            values[name] = p
        return cls(**values)


class Axis:
    """One slew-rate-limited axis in device units; ``turn`` > 0 makes it wrap (shortest way round)."""

    def __init__(self, position: float, turn: int = 0) -> None:
        self.position = float(position)
        self.target = float(position)
        self.rate = 0.0
        self.turn = turn

    @property
    def moving(self) -> bool:
        return self.position != self.target

    def _delta(self) -> float:
        d = self.target - self.position
        if self.turn:
            d = (d + self.turn / 2) % self.turn - self.turn / 2
        return d

    def move_to(self, target: float, rate: float) -> None:
        self.target, self.rate = float(target), rate

    def stop(self) -> None:
        self.target = self.position

    def advance(self, dt: float) -> None:
        d = self._delta()
        step = self.rate * dt
        if abs(d) <= step:
            self.position = self.target
        else:
            self.position += step if d > 0 else -step
            if self.turn:
                self.position = (self.position + self.turn / 2) % self.turn - self.turn / 2


class _Camera:
    """What both devices share: three axes from the profile, counters, and the clock."""

    def __init__(self, profile: DeviceProfile, address: int, now: float) -> None:
        self.profile = profile
        self.address = address
        turn = round(360 * profile.pan.units_per_deg) if profile.pan_continuous else 0
        self.pan = Axis(0.0, turn)
        self.tilt = Axis(0.0)
        self.zoom = Axis(profile.zoom.position[0])
        self.commands = 0
        self.errors = 0
        self._now = now

    @property
    def moving(self) -> bool:
        return self.pan.moving or self.tilt.moving or self.zoom.moving

    def advance(self, now: float) -> None:
        dt = max(0.0, now - self._now)
        self._now = now
        for axis in (self.pan, self.tilt, self.zoom):
            axis.advance(dt)

    def _zoom_rate(self) -> float:
        z = self.profile.zoom
        return (z.position[-1] - z.position[0]) / z.seconds_full_range

    def _in_limits(self, axis: str, units: int) -> bool:
        lo, hi = self.profile.limits_units(axis)
        return lo <= units <= hi

    def state(self) -> dict:
        """The ``--state-file`` object: device angles (deg), zoom factor, counters, and more."""
        p = self.profile
        pan, tilt, zoom = round(self.pan.position), round(self.tilt.position), round(self.zoom.position)
        geo = p.from_device(pan, tilt, zoom)
        return {
            "pan_deg": pan / p.pan.units_per_deg,
            "tilt_deg": tilt / p.tilt.units_per_deg,
            "zoom": geo.zoom,
            "commands": self.commands,
            "errors": self.errors,
            "protocol": p.protocol,
            "address": self.address,
            "units": {"pan": pan, "tilt": tilt, "zoom": zoom},
            "moving": self.moving,
            "geometry": {"pan_deg": geo.pan_deg, "tilt_deg": geo.tilt_deg},
        }


class ViscaCamera(_Camera):
    """A VISCA camera: :meth:`receive` a framed packet, :meth:`tick` for completions; both return replies.

    ``chain_position`` is the camera's place on the daisy chain (the profile's
    address by default): AddressSet ``w`` gives it address ``w + chain_position - 1``.
    """

    def __init__(self, profile: DeviceProfile, chain_position: int | None = None, now: float = 0.0,
                 rng: random.Random | None = None, buffer_full: float = 0.0) -> None:
        chain_position = profile.address if chain_position is None else chain_position
        super().__init__(profile, chain_position, now)
        self.chain_position = chain_position
        self.sockets: dict[int, str] = {}
        self._rng = rng or random.Random(0)
        self._buffer_full = buffer_full

    def _axes(self, kind: str) -> tuple[Axis, ...]:
        return (self.pan, self.tilt) if kind == "pan_tilt" else (self.zoom,)

    def _free(self, socket: int, stop: bool) -> None:
        kind = self.sockets.pop(socket)
        if stop:
            for axis in self._axes(kind):
                axis.stop()

    def _error(self, socket: int, code: ErrorCode) -> list[bytes]:
        self.errors += 1
        return [visca.error(self.address, socket, code)]

    def receive(self, packet: Packet, now: float) -> list[bytes]:
        """Replies to one framed packet (none if it is not addressed to this camera)."""
        self.advance(now)
        header = packet.data[0]
        receiver = header & 0x0F
        if header >> 4 != 0x8 or receiver not in (self.address, visca.BROADCAST):
            return []
        self.commands += 1
        if packet.error:
            return self._error(0, ErrorCode.MESSAGE_LENGTH)
        try:
            cmd = visca.decode_command(packet.data)
        except ViscaError as exc:
            return self._error(0, exc.code)
        return self._execute(cmd)

    def _execute(self, cmd: visca.Command) -> list[bytes]:
        if cmd.kind == "address_set":
            self.address = min(cmd.args[0] + self.chain_position - 1, 7)
            return [visca.address_set_reply(self.address + 1)]
        if cmd.kind == "if_clear":
            for socket in list(self.sockets):
                self._free(socket, stop=True)
            return [visca.if_clear_reply()] if cmd.receiver == visca.BROADCAST else [visca.completion(self.address, 0)]
        if cmd.receiver == visca.BROADCAST:
            return self._error(0, ErrorCode.SYNTAX)
        if cmd.kind == "cancel":
            socket = cmd.args[0]
            if socket not in self.sockets:
                return self._error(socket, ErrorCode.NO_SOCKET)
            self._free(socket, stop=True)
            return [visca.error(self.address, socket, ErrorCode.CANCELLED)]
        if cmd.kind == "pan_tilt_inquiry":
            return [visca.pan_tilt_position_reply(self.address, round(self.pan.position), round(self.tilt.position))]
        if cmd.kind == "zoom_inquiry":
            return [visca.zoom_position_reply(self.address, round(self.zoom.position))]
        return self._motion(cmd)

    def _motion(self, cmd: visca.Command) -> list[bytes]:
        p = self.profile
        kind = "pan_tilt" if cmd.kind == "pan_tilt_absolute" else "zoom"
        if kind == "pan_tilt":
            vv, ww, pan, tilt = cmd.args
            if not (1 <= vv <= p.pan.max_speed and 1 <= ww <= p.tilt.max_speed):
                return self._error(0, ErrorCode.SYNTAX)
            executable = self._in_limits("pan", pan) and self._in_limits("tilt", tilt)
        else:
            (position,) = cmd.args
            executable = p.zoom.position[0] <= position <= p.zoom.position[-1]
        if self._rng.random() < self._buffer_full:
            return self._error(0, ErrorCode.BUFFER_FULL)
        replies = []
        for socket, running in list(self.sockets.items()):
            if running == kind:
                self._free(socket, stop=False)
                replies.append(visca.completion(self.address, socket))
        # the running command of this kind (if any) was just freed, so one of the two sockets is free
        socket = min(s for s in (1, 2) if s not in self.sockets)
        if not executable:
            return replies + self._error(socket, ErrorCode.NOT_EXECUTABLE)
        self.sockets[socket] = kind
        if kind == "pan_tilt":
            self.pan.move_to(pan, p.slew_units_s("pan", vv))
            self.tilt.move_to(tilt, p.slew_units_s("tilt", ww))
        else:
            self.zoom.move_to(position, self._zoom_rate())
        return replies + [visca.ack(self.address, socket)]

    def tick(self, now: float) -> list[bytes]:
        """Completions of the motions that ended by ``now``."""
        self.advance(now)
        done = [s for s, kind in self.sockets.items() if not any(a.moving for a in self._axes(kind))]
        for socket in done:
            self._free(socket, stop=False)
        return [visca.completion(self.address, s) for s in done]

    def network_change(self) -> bytes:
        """The Network Change message a camera sends when it joins the chain."""
        return visca.network_change(self.address)


class PelcoDCamera(_Camera):
    """A Pelco-D device: :meth:`receive` a framed packet and get its replies (Pelco-D has no completions)."""

    def __init__(self, profile: DeviceProfile, address: int | None = None, now: float = 0.0) -> None:
        super().__init__(profile, profile.address if address is None else address, now)
        self.presets: dict[int, tuple[float, float, float]] = {}

    def receive(self, packet: Packet, now: float) -> list[bytes]:
        """Replies to one framed packet (none if it is for another address, unsupported or out of range)."""
        self.advance(now)
        msg = pelco_d.decode(packet.data)
        if not isinstance(msg, pelco_d.Message) or msg.address != self.address:
            return []
        self.commands += 1
        accepted = self._execute(msg)
        if accepted is None:
            self.errors += 1
            return []
        if accepted:
            return [accepted]
        return [pelco_d.general_response(self.address)] if self.profile.pelco_d.general_response else []

    def _execute(self, msg: pelco_d.Message) -> bytes | None:
        """The query answer; ``b""`` for an accepted command; ``None`` for a rejected one."""
        p, a = self.profile, self.address
        if msg.cmd1:
            return None
        if msg.cmd2 in pelco_d.QUERY_REPLY:
            value = {pelco_d.QUERY_PAN: pelco_d.wrap_angle(round(self.pan.position)),
                     pelco_d.QUERY_TILT: pelco_d.wrap_angle(round(self.tilt.position)),
                     pelco_d.QUERY_ZOOM: round(self.zoom.position)}[msg.cmd2]
            return pelco_d.position_reply(a, pelco_d.QUERY_REPLY[msg.cmd2], value)
        if msg.cmd2 in (pelco_d.SET_PAN, pelco_d.SET_TILT):
            axis = "pan" if msg.cmd2 == pelco_d.SET_PAN else "tilt"
            units = pelco_d.unwrap_angle(msg.value)
            if msg.value >= pelco_d.FULL_TURN or not self._in_limits(axis, units):
                return None
            getattr(self, axis).move_to(units, p.slew_units_s(axis))
            return b""
        if msg.cmd2 == pelco_d.SET_ZOOM:
            if not p.zoom.position[0] <= msg.value <= p.zoom.position[-1]:
                return None
            self.zoom.move_to(msg.value, self._zoom_rate())
            return b""
        if msg.cmd2 in (pelco_d.SET_PRESET, pelco_d.CLEAR_PRESET, pelco_d.GO_TO_PRESET) and msg.data1 == 0:
            return self._preset(msg.cmd2, msg.data2)
        if msg.cmd2 == 0 and msg.value == 0:
            for axis in (self.pan, self.tilt, self.zoom):
                axis.stop()
            return b""
        return None

    def _preset(self, opcode: int, number: int) -> bytes | None:
        if number == 0:
            return None
        if opcode == pelco_d.SET_PRESET:
            self.presets[number] = (self.pan.position, self.tilt.position, self.zoom.position)
        elif opcode == pelco_d.CLEAR_PRESET:
            self.presets.pop(number, None)
        elif number in self.presets:
            pan, tilt, zoom = self.presets[number]
            self.pan.move_to(pan, self.profile.slew_units_s("pan"))
            self.tilt.move_to(tilt, self.profile.slew_units_s("tilt"))
            self.zoom.move_to(zoom, self._zoom_rate())
        else:
            return None
        return b""

    def tick(self, now: float) -> list[bytes]:
        self.advance(now)
        return []


class _Emulator:
    """What the pty, UDP and ONVIF emulators share: the camera, injected faults, the state file, the lifetime.

    ``latency_s`` delays every packet received before the camera sees it (a camera's
    command latency, for ``omnijax ptz calibrate`` to measure).
    """

    def __init__(self, profile: DeviceProfile, address: int | None, *, state_file: str | Path | None,
                 faults: Faults, seed: int, latency_s: float = 0.0) -> None:
        self.profile = profile
        self._rng = random.Random(seed)
        self.faults = faults
        self.latency_s = latency_s
        self.camera = self._make_camera(profile, address, time.monotonic())
        self.state_file = Path(state_file) if state_file else None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._last_state: dict | None = None
        self._state_due = 0.0
        self._delayed: list[tuple[float, object]] = []

    def _make_camera(self, profile: DeviceProfile, address: int | None, now: float) -> _Camera:
        if profile.protocol == "visca":
            return ViscaCamera(profile, address, now, self._rng, self.faults.buffer_full)
        return PelcoDCamera(profile, address, now)

    def _due(self, items, now: float) -> list:
        """The received items whose latency has passed, oldest first (``items``, received at ``now``,
        join the queue first)."""
        self._delayed += [(now + self.latency_s, it) for it in items]
        ready = [it for t, it in self._delayed if t <= now]
        self._delayed = [(t, it) for t, it in self._delayed if t > now]
        return ready

    def _timeout(self) -> float:
        timeout = _TICK_MOVING_S if self.camera.moving else _TICK_IDLE_S
        if self._delayed:
            timeout = min(timeout, max(0.0, min(t for t, _ in self._delayed) - time.monotonic()))
        return timeout

    def _mangle(self, reply: bytes, header: int = 0) -> bytes | None:
        """The reply after the injected faults (``None``: dropped); the first ``header`` bytes are kept."""
        f, rng = self.faults, self._rng
        if f.drop and rng.random() < f.drop:
            return None
        if f.garble and rng.random() < f.garble and len(reply) > header:
            i = rng.randrange(header, len(reply))
            reply = reply[:i] + bytes((reply[i] ^ (1 << rng.randrange(8)),)) + reply[i + 1:]
        if f.noise and rng.random() < f.noise:
            reply = reply[:header] + rng.randbytes(rng.randint(1, 8)) + reply[header:]
        return reply

    def state(self) -> dict:
        with self._lock:
            return self.camera.state()

    def _write_state(self, force: bool = False) -> None:
        if self.state_file is None:
            return
        now = time.monotonic()
        state = self.state()
        # the moment motion ends is written at once: a client that saw the camera arrive (a position reply)
        # and then reads the file must find it there, not a position 50 ms old
        settled = not state["moving"] and bool(self._last_state and self._last_state["moving"])
        if not force and (state == self._last_state or (now < self._state_due and not settled)):
            return
        tmp = self.state_file.with_name(f".{self.state_file.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(state))
        os.replace(tmp, self.state_file)
        self._last_state = state
        self._state_due = now + _STATE_INTERVAL_S

    def stop(self) -> None:
        """Ask :meth:`serve` to return (safe from a signal handler)."""
        self._stop.set()

    @property
    def stopped(self) -> bool:
        """Whether :meth:`stop` was called."""
        return self._stop.is_set()

    def start(self):
        """Serve in a daemon thread."""
        self._thread = threading.Thread(target=self.serve, name="ptz-emulator", daemon=True)
        self._thread.start()
        return self

    def _join(self) -> None:
        self.stop()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()


class PtyEmulator(_Emulator):
    """A camera served on a pseudo-terminal; ``path`` is what a client opens with pyserial.

    ``link`` (optional) is a symlink kept pointing at the pty, so that a client
    can reopen one path after the emulator was restarted (a new pty). The
    ``state_file`` (optional) is rewritten atomically (temporary file and
    rename) at most every 50 ms while something changes, and at once when a motion ends. Use :meth:`serve`
    in the calling thread, or :meth:`start` / :meth:`close` (a context manager)
    for a background thread.
    """

    def __init__(self, profile: DeviceProfile, address: int | None = None, *, state_file: str | Path | None = None,
                 link: str | Path | None = None, faults: Faults = Faults(), seed: int = 0,
                 latency_s: float = 0.0) -> None:
        super().__init__(profile, address, state_file=state_file, faults=faults, seed=seed, latency_s=latency_s)
        self._parser: ViscaParser | PelcoDParser = (ViscaParser() if profile.protocol == "visca"
                                                    else PelcoDParser(replies=False))
        self.link = Path(link) if link else None
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        if self.link:
            tmp = self.link.with_name(f".{self.link.name}.{os.getpid()}.tmp")
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
            os.symlink(self.path, tmp)
            os.replace(tmp, self.link)
        self._write_state(force=True)

    # -- the loop -------------------------------------------------------------------------

    def serve(self) -> None:
        """Serve until :meth:`stop` is called (from another thread or a signal handler)."""
        try:
            while not self._stop.is_set():
                ready, _, _ = select.select([self._master], [], [], self._timeout())
                now = time.monotonic()
                replies: list[bytes] = []
                with self._lock:
                    packets = self._parser.feed(self._read()) if ready else []
                    if isinstance(self._parser, PelcoDParser):
                        self.camera.errors += self._parser.rejected
                        self._parser.rejected = 0
                    for packet in self._due(packets, now):
                        replies += self.camera.receive(packet, now)
                    replies += self.camera.tick(now)
                for reply in replies:
                    self._send(reply)
                self._write_state()
        finally:
            self._write_state(force=True)

    def _read(self) -> bytes:
        try:
            return os.read(self._master, 4096)
        except BlockingIOError:
            return b""

    def _send(self, reply: bytes) -> None:
        reply = self._mangle(reply)
        if reply is not None:
            self.write(reply)

    def write(self, data: bytes) -> None:
        """Write to the client without blocking; what does not fit in the pty is dropped."""
        while data:
            try:
                n = os.write(self._master, data)
            except (BlockingIOError, OSError):
                return
            data = data[n:]

    def send_network_change(self) -> None:
        """VISCA: announce a Network Change (as a camera does when it is power-cycled on the chain)."""
        with self._lock:
            self.write(self.camera.network_change())

    # -- lifetime -------------------------------------------------------------------------

    def close(self) -> None:
        """Stop serving, close the pty (the client sees the port vanish) and remove the link."""
        self._join()
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)
        if self.link is not None:
            with contextlib.suppress(OSError):
                if os.readlink(self.link) == self.path:
                    self.link.unlink()


class UdpEmulator(_Emulator):
    """A VISCA camera served over IP (:mod:`runtime.ptz.visca_ip`) on a UDP socket bound to ``listen``.

    ``address`` is ``(host, port)`` as bound (port 0 picks a free one); ``url`` is what
    ``omnijax ptz-emulator --protocol visca-ip`` prints (``udp://HOST:PORT``). It answers the
    last peer that spoke to it. Malformed datagrams are answered with a message error (or
    ignored, if shorter than a header) and counted; none stops it.
    """

    def __init__(self, profile: DeviceProfile, listen: tuple[str, int] = ("127.0.0.1", 0), *,
                 state_file: str | Path | None = None, faults: Faults = Faults(), seed: int = 0,
                 latency_s: float = 0.0) -> None:
        from .visca_ip import ViscaIpCamera

        if profile.protocol != "visca":
            raise ValueError(f"VISCA over IP needs a visca profile, got {profile.protocol}")
        super().__init__(profile, None, state_file=state_file, faults=faults, seed=seed, latency_s=latency_s)
        self.ip = ViscaIpCamera(self.camera)
        self._sock = _socket.socket(_socket.AF_INET6 if ":" in listen[0] else _socket.AF_INET, _socket.SOCK_DGRAM)
        try:
            self._sock.bind(listen)
        except OSError:
            self._sock.close()
            raise
        self._sock.setblocking(False)
        self.address = self._sock.getsockname()[:2]
        host = f"[{self.address[0]}]" if ":" in self.address[0] else self.address[0]
        self.url = f"udp://{host}:{self.address[1]}"
        self._peer = None
        self.datagrams = 0
        self._write_state(force=True)

    def serve(self) -> None:
        """Serve until :meth:`stop` is called."""
        try:
            while not self._stop.is_set():
                ready, _, _ = select.select([self._sock], [], [], self._timeout())
                now = time.monotonic()
                out: list[tuple[bytes, object]] = []
                with self._lock:
                    received = self._drain() if ready else []
                    self.datagrams += len(received)
                    for data, peer in self._due(received, now):
                        self._peer = peer
                        out += [(r, peer) for r in self.ip.receive(data, now)]
                    if self._peer is not None:
                        out += [(r, self._peer) for r in self.ip.tick(now)]
                    else:
                        self.ip.tick(now)
                for reply, peer in out:
                    self._send(reply, peer)
                self._write_state()
        finally:
            self._write_state(force=True)

    def _drain(self) -> list[tuple[bytes, object]]:
        got = []
        while len(got) < 256:
            try:
                got.append(self._sock.recvfrom(2048))
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # an ICMP error from a peer that went away: nothing to read
                break
        return got

    def _send(self, reply: bytes, peer) -> None:
        reply = self._mangle(reply, header=8)
        if reply is None:
            return
        with contextlib.suppress(OSError):
            self._sock.sendto(reply, peer)

    def state(self) -> dict:
        with self._lock:
            return {**self.camera.state(), "errors": self.camera.errors + self.ip.errors,
                    "datagrams": self.datagrams, "resets": self.ip.resets}

    def close(self) -> None:
        self._join()
        with contextlib.suppress(OSError):
            self._sock.close()
