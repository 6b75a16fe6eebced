"""The PTZ driver: steer a VISCA or Pelco-D camera over any pyserial URL, from a real-time loop.

Use::

    with PtzDriver("/dev/ttyUSB0", load_profile("sony_evi_d70")) as ptz:
        ptz.set_target(pan, tilt, zoom)      # every frame; returns at once
        print(ptz.counters)                  # {"commands", "errors", "reconnects"}

``set_target(pan, tilt, zoom)`` takes omnijax's pan and tilt (radians; pan
measured at the PTZ from the direction of the omni camera's axis, tilt up
positive: :func:`omnijax.pointing`) and a zoom factor. The device profile maps
them to device units and clamps them to the device's limits
(:meth:`DeviceProfile.to_device`); the call only stores the target, so the
latest target wins and nothing queues up. A worker thread sends what changed,
at most once per ``link.min_interval_s``, waits for each ACK
(``link.ack_timeout_s``), retries after "buffer full", and tracks VISCA
completions (``link.completion_timeout_s``; a command that never completes is
an error, and its target is sent again). One reader thread reads the port and
routes every reply. When the port fails (unplugged, the emulator killed, a
socket closed) or ``link.max_silent`` commands in a row go unanswered, the
port is closed and reopened with exponential back-off
(``link.reconnect_backoff_s``), re-initialised (VISCA: AddressSet and
IF_Clear, also after a Network Change message), and the latest target is sent.

Ports are pyserial URLs: ``/dev/ttyUSB0``, ``socket://host:port``, ``loop://``,
or a pseudo-terminal from ``omnijax ptz-emulator`` (and ``visca-udp://``, through
:class:`~runtime.ptz.visca_ip.ViscaIpPort`). What every driver shares (the target,
connect/disconnect, queries, counters) is :class:`~runtime.ptz.base.DriverBase`'s.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import Future
from dataclasses import dataclass, field

import serial

from . import transports
from .base import DriverBase
from .dialect import Event, Exchange, dialect_for
from .errors import PtzError as PtzError, PtzPortError as PtzPortError
from .profile import DeviceProfile

log = logging.getLogger("omnijax.ptz")

#: Reader's read time-out (s): how quickly it notices a stop where the port cannot cancel a read.
_READ_TIMEOUT_S = 0.05
#: A write that takes longer than this (s) means the line is stuck: the port is reopened.
_WRITE_TIMEOUT_S = 1.0
#: The worker's longest sleep when idle (s).
_IDLE_S = 0.1


class _LinkLost(Exception):
    """Internal: the port failed or the camera went silent; reconnect."""


@dataclass
class _Waiter:
    exchange: Exchange
    seq: int
    event: threading.Event = field(default_factory=threading.Event)
    result: Event | None = None
    at: float = 0.0


@dataclass
class _Pending:
    group: str
    seq: int
    deadline: float


class _Connection:
    """One open port and its reader thread."""

    def __init__(self, port) -> None:  # a serial.SerialBase, or a port-like transport (runtime.ptz.transports)
        self.port = port
        self.reader: threading.Thread | None = None
        self.closing = threading.Event()


class PtzDriver(DriverBase):
    """Steers one PTZ camera over a byte stream; see the module docstring and :class:`DriverBase`."""

    COUNTERS = ("acks", "completions", "timeouts", "buffer_full", "unsolicited", "garbage_bytes")
    LATENCIES = ("ack", "query")

    def __init__(self, port: str, profile: DeviceProfile) -> None:
        super().__init__(port, profile)
        self._dialect = dialect_for(profile)
        self._conn: _Connection | None = None
        self._lost_reason: str | None = None
        self._sent: dict[str, tuple[int, ...]] = {}
        self._pending: dict[int, _Pending] = {}
        self._waiting: _Waiter | None = None
        self._reinit = False
        self._silent = 0
        self._next_send = 0.0
        #: what the transport counts (VISCA over IP: retries, sequence errors, stale and malformed datagrams)
        self._transport: dict[str, int] = {}

    def _check(self) -> None:
        transports.check_port(self.port)

    def _wake(self) -> None:
        if self._stop.is_set() and self._waiting is not None:  # a stop: end the exchange waiting for its answer
            self._waiting.event.set()
        self._cond.notify_all()

    def _extra_stats(self) -> dict:
        return {"transport": dict(self._transport)}

    def capabilities(self) -> transports.Capabilities:
        """What this camera offers, from its protocol and profile (``omnijax ptz probe`` checks them live)."""
        p = self.profile
        visca = p.protocol == "visca"
        return transports.Capabilities(
            protocol="visca-ip" if transports.transport_of(self.port) == "udp" else p.protocol,
            transport=transports.transport_of(self.port),
            move_modes=("absolute",),
            move_status="completion" if visca else "timer",
            position=True,
            zoom=(float(p.zoom.magnification[0]), float(p.zoom.magnification[-1])),
            limits_deg={"pan": tuple(p.pan.limits_deg), "tilt": tuple(p.tilt.limits_deg)},
            notes=() if visca or p.pelco_d.general_response else ("no general response: writes are not acknowledged",),
        )

    # ------------------------------------------------------------------------------------
    # Worker: connection life cycle
    # ------------------------------------------------------------------------------------

    def _run(self) -> None:
        backoff = self._link.reconnect_backoff_s[0]
        try:
            while not self._stop.is_set():
                if self._conn is None:
                    if self._open():
                        backoff = self._link.reconnect_backoff_s[0]
                    else:
                        self._stop.wait(backoff)
                        backoff = min(2 * backoff, self._link.reconnect_backoff_s[1])
                    continue
                try:
                    self._serve()
                except _LinkLost as exc:
                    if not self._stop.is_set():
                        self._fail(str(exc))
        finally:
            self._close()
            self._fail_queries(f"{self.port}: driver stopped")

    def _fail(self, reason: str) -> None:
        """Close a failed link (counted and said once per outage: :meth:`DriverBase._link_lost`)."""
        self._close()
        self._link_lost(reason)

    def _open(self) -> bool:
        try:
            port = transports.open_port(self.port, baudrate=self.profile.baudrate, timeout=_READ_TIMEOUT_S,
                                        write_timeout=_WRITE_TIMEOUT_S, link=self._link, counters=self._transport,
                                        address=self.profile.address)
            port.reset_input_buffer()
        except (serial.SerialException, OSError, ValueError) as exc:
            self.last_error = f"cannot open: {exc}"
            log.debug("PTZ: cannot open %s: %s", self.port, exc)
            return False
        self._lost_reason = None
        conn = _Connection(port)
        conn.reader = threading.Thread(target=self._read_loop, args=(conn,), name="ptz-reader", daemon=True)
        self._conn = conn
        conn.reader.start()
        try:
            self._initialise()
        except _LinkLost as exc:
            if not self._stop.is_set():
                self._fail(f"initialisation failed: {exc}")
            return False
        with self._cond:
            self._sent.clear()
            self._pending.clear()
            self._silent = 0
        after = self._link_up()
        log.info("PTZ connected on %s (%s, address %d)%s", self.port, self.profile.protocol, self.profile.address,
                 after)
        return True

    def _initialise(self) -> None:
        for exchange in self._dialect.init():
            if self._exchange(exchange) is None:
                raise _LinkLost(f"no answer to {exchange.packet.hex(' ')}")

    def _close(self) -> None:
        conn, self._conn = self._conn, None
        self._connected.clear()
        if conn is None:
            return
        conn.closing.set()
        if hasattr(conn.port, "cancel_read"):
            try:
                conn.port.cancel_read()
            except (OSError, serial.SerialException):
                pass
        conn.reader.join()
        try:
            conn.port.close()
        except (OSError, serial.SerialException):
            pass
        with self._cond:
            self._pending.clear()

    # ------------------------------------------------------------------------------------
    # Worker: sending
    # ------------------------------------------------------------------------------------

    def _serve(self) -> None:
        """Send targets and answer queries until the link is lost or the driver stops."""
        while not self._stop.is_set():
            with self._cond:
                if self._lost_reason:
                    raise _LinkLost(self._lost_reason)
                reinit, self._reinit = self._reinit, False
            if reinit:
                log.info("PTZ: Network Change from the camera; re-initialising")
                self._initialise()
                with self._cond:
                    self._sent.clear()
            self._expire_completions()
            with self._cond:
                query = self._queries.popleft() if self._queries else None
            if query is not None:
                self._answer_query(query)
                continue
            now = time.monotonic()
            with self._cond:
                todo = self._todo()
                seq = self._seq
                if not todo:
                    self._sent_seq = seq
                if not todo or now < self._next_send:
                    wake = self._next_send - now if todo else _IDLE_S
                    deadlines = [p.deadline - now for p in self._pending.values()]
                    self._cond.wait(max(0.0, min([wake, _IDLE_S, *deadlines])))
                    continue
                self._sent_seq = seq
            self._next_send = time.monotonic() + self._send_target(todo, seq)

    def _todo(self) -> list[tuple[str, tuple[int, ...], Exchange]]:
        if self._target is None:
            return []
        return [c for c in self._dialect.commands(self._target) if self._sent.get(c[0]) != c[1]]

    def _send_target(self, todo, seq: int) -> float:
        """Send one target's changed groups; returns how long to wait before the next send (s)."""
        for group, key, exchange in todo:
            reply = self._exchange(exchange, seq)
            if reply is None:
                continue
            if reply.kind == "error":
                if reply.code == self._dialect.buffer_full:
                    with self._cond:
                        self._counts["buffer_full"] += 1
                    return self._link.retry_delay_s
                with self._cond:
                    self._counts["errors"] += 1
                    self._sent[group] = key
                log.warning("PTZ: %s command refused (error 0x%02x)", group, reply.code)
                continue
            with self._cond:
                self._sent[group] = key
        return self._link.min_interval_s

    def _exchange(self, exchange: Exchange, seq: int = 0) -> Event | None:
        """Write one packet and wait for its answer; ``None`` after the ACK time-out (counted)."""
        conn = self._conn
        if conn is None:
            raise _LinkLost("port closed")
        waiter = _Waiter(exchange, seq)
        with self._cond:
            self._waiting = waiter
        t0 = time.perf_counter()
        try:
            conn.port.write(exchange.packet)
            t_write = time.monotonic()
        except (serial.SerialException, OSError) as exc:
            with self._cond:
                self._waiting = None
            raise _LinkLost(f"write failed: {exc}") from None
        with self._cond:
            self._counts["commands"] += 1
            if seq and exchange.group not in ("init", "query"):
                self._writes.append((seq, t_write))
        if not exchange.answered:
            with self._cond:
                self._waiting = None
            return Event("general")
        answered = waiter.event.wait(self._link.ack_timeout_s)
        with self._cond:
            self._waiting = None
            if self._lost_reason or self._stop.is_set():
                raise _LinkLost(self._lost_reason or "driver stopped")
            if not answered:
                self._counts["timeouts"] += 1
                if exchange.group == "init":  # a camera that does not answer: its outage counts once, in _fail
                    return None
                self._counts["errors"] += 1
                self._silent += 1
                silent = self._silent
            else:
                self._silent = 0
                if exchange.group != "init":
                    kind = "query" if exchange.group == "query" else "ack"
                    self._latency[kind].append(waiter.at - t0)
                return waiter.result
        log.warning("PTZ: no answer to %s within %g s", exchange.packet.hex(" "), self._link.ack_timeout_s)
        if silent >= self._link.max_silent:
            raise _LinkLost(f"{silent} commands in a row unanswered")
        return None

    def _answer_query(self, fut: Future) -> None:
        answers = []
        for exchange in self._dialect.queries():
            try:
                reply = self._exchange(exchange)
            except _LinkLost as exc:
                fut.set_exception(PtzError(f"{self.port}: position inquiry failed ({exc})"))
                raise
            if reply is None or reply.kind == "error":
                what = "no answer" if reply is None else f"error 0x{reply.code:02x}"
                fut.set_exception(PtzError(f"{self.port}: position inquiry failed ({what})"))
                return
            answers.append(reply)
        fut.set_result(self.profile.from_device(*self._dialect.position(answers)))

    def _expire_completions(self) -> None:
        now = time.monotonic()
        with self._cond:
            expired = [s for s, p in self._pending.items() if p.deadline <= now]
            for socket in expired:
                p = self._pending.pop(socket)
                newer = any(q.group == p.group and q.seq > p.seq for q in self._pending.values())
                if not newer:
                    self._counts["timeouts"] += 1
                    self._counts["errors"] += 1
                    self._sent.pop(p.group, None)
                    log.warning("PTZ: %s command not completed within %g s; sending it again",
                                p.group, self._link.completion_timeout_s)

    # ------------------------------------------------------------------------------------
    # Reader
    # ------------------------------------------------------------------------------------

    def _read_loop(self, conn: _Connection) -> None:
        parser = self._dialect.parser()
        garbage = 0
        while not conn.closing.is_set():
            try:
                data = conn.port.read(conn.port.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                if not conn.closing.is_set():
                    self._lost(f"read failed: {exc}")
                return
            if not data:
                continue
            at = time.perf_counter()
            events = list(map(self._dialect.event, parser.feed(data)))
            with self._cond:
                self._counts["garbage_bytes"] += parser.garbage_bytes - garbage
                garbage = parser.garbage_bytes
                for event in events:
                    self._route(event, at)

    def _lost(self, reason: str) -> None:
        with self._cond:
            self._lost_reason = reason
            self._connected.clear()
            if self._waiting is not None:
                self._waiting.event.set()
            self._cond.notify_all()

    def _route(self, event: Event | None, at: float) -> None:
        """Hand one reply to whoever waits for it (called with the lock held)."""
        if event is None:
            self._counts["unsolicited"] += 1
            return
        if event.kind == "network_change":
            self._reinit = True
            self._cond.notify_all()
            return
        if event.kind == "completion" and event.socket:
            if self._pending.pop(event.socket, None) is not None:
                self._counts["completions"] += 1
            else:
                self._counts["unsolicited"] += 1
            return
        if event.kind == "error" and event.socket in self._pending:
            pending = self._pending.pop(event.socket)
            if event.code != self._dialect.cancelled:
                self._counts["errors"] += 1
                self._sent.pop(pending.group, None)
            return
        w = self._waiting
        if w is None or w.event.is_set() or not w.exchange.answers(event):
            self._counts["unsolicited"] += 1
            return
        w.result, w.at = event, at
        if event.kind == "ack":
            self._counts["acks"] += 1
            if self._dialect.completions:
                self._pending[event.socket] = _Pending(w.exchange.group, w.seq,
                                                       time.monotonic() + self._link.completion_timeout_s)
        elif event.kind == "general":
            self._counts["acks"] += 1
        w.event.set()
