"""What every PTZ driver shares, whatever its transport: the plumbing around one worker thread.

:class:`DriverBase` holds the latest target (``set_target`` stores it and returns at once: the latest
target wins, nothing queues up), starts and stops the worker (``connect``/``disconnect``, a context
manager), queues position requests for it, keeps the counters, the write time stamps and the
request-to-answer latencies, and says when the link is lost and back. A driver adds how it talks to
its camera: the worker (:meth:`DriverBase._run`), how to wake it (:meth:`DriverBase._wake`), and what
it reports beyond the shared counters. :class:`~runtime.ptz.driver.PtzDriver` (serial, VISCA over IP)
and :class:`~runtime.ptz.onvif.OnvifDriver` are the two.
"""

from __future__ import annotations

import abc
import logging
import threading
import time
from collections import deque
from concurrent.futures import Future

import numpy as np

from .errors import PtzError
from .profile import DeviceProfile, DeviceTarget, PtzPosition

log = logging.getLogger("omnijax.ptz")

#: Write time stamps and request-to-answer latencies kept for the statistics.
LATENCIES_KEPT = 10_000
_AXES = ("pan", "tilt", "zoom")


class DriverBase(abc.ABC):
    """Steers one PTZ camera from a worker thread; thread-safe, ``set_target`` never blocks on I/O.

    ``port`` is the camera's URL as messages show it (never a password). Subclasses name their
    extra counters (:attr:`COUNTERS`) and latency kinds (:attr:`LATENCIES`) and implement
    :meth:`_run`; ``_cond`` guards the shared state and wakes a worker that waits on it.
    """

    #: counters beyond ``commands``, ``errors``, ``reconnects``, ``clamped``, ``superseded``
    COUNTERS: tuple[str, ...] = ()
    #: kinds of request-to-answer latency kept (``stats()["latency_ms"]``)
    LATENCIES: tuple[str, ...] = ()
    #: the worker thread's name
    WORKER = "ptz-worker"

    def __init__(self, port: str, profile: DeviceProfile) -> None:
        self.port = port
        self.profile = profile
        self._link = profile.link
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._worker: threading.Thread | None = None
        self._target: DeviceTarget | None = None
        self._seq = 0
        self._sent_seq = 0
        self._queries: deque[Future] = deque()
        self._clamped: tuple[str, ...] = ()
        self._ever_connected = False
        self._outage_since: float | None = None
        self.last_error: str | None = None
        self._counts = dict.fromkeys(("commands", "errors", "reconnects", "clamped", "superseded", *self.COUNTERS), 0)
        self._latency = {k: deque(maxlen=LATENCIES_KEPT) for k in self.LATENCIES}
        self._writes: deque[tuple[int, float]] = deque(maxlen=LATENCIES_KEPT)

    # ------------------------------------------------------------------------------------
    # What a driver adds
    # ------------------------------------------------------------------------------------

    @abc.abstractmethod
    def _run(self) -> None:
        """The worker thread: connect, serve targets and queries, reconnect, until ``_stop`` is set."""

    @abc.abstractmethod
    def _check(self) -> None:
        """Refuse a malformed URL before any thread starts (:class:`~runtime.ptz.errors.PtzPortError`)."""

    def _wake(self) -> None:
        """Wake the worker for a new target, a query or a stop (called with ``_cond`` held)."""
        self._cond.notify_all()

    def _hopeless(self) -> bool:
        """Whether waiting longer for the first connection is pointless (e.g. refused credentials)."""
        return False

    def _connect_error(self, timeout: float) -> PtzError:
        """What :meth:`connect` raises when no camera was connected within ``timeout`` s."""
        return PtzError(f"{self.port}: no {self.profile.protocol} camera within {timeout:g} s "
                        f"({self.last_error or 'no answer'})")

    def _extra_stats(self) -> dict:
        """What :meth:`stats` adds for this transport (called with ``_cond`` held)."""
        return {}

    # ------------------------------------------------------------------------------------
    # Public API
    # ------------------------------------------------------------------------------------

    def connect(self, timeout: float | None = 5.0):
        """Start the worker; wait up to ``timeout`` s for the camera (``None``: do not wait).

        Raises :class:`~runtime.ptz.errors.PtzPortError` for a malformed URL (and whatever the driver
        finds hopeless), :class:`PtzError` if no camera was connected in time; the driver is then
        stopped again.
        """
        if self._worker is not None:
            return self
        self._check()
        self._stop.clear()
        self._worker = threading.Thread(target=self._run, name=self.WORKER, daemon=True)
        self._worker.start()
        if timeout is not None and not self._wait_connected(timeout):
            error = self._connect_error(timeout)
            self.disconnect()
            raise error
        return self

    def _wait_connected(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not self._connected.wait(min(0.05, max(0.0, deadline - time.monotonic()))):
            if self._hopeless() or time.monotonic() >= deadline:
                return False
        return True

    def disconnect(self) -> None:
        """Stop the worker and close the link; pending queries fail with :class:`PtzError`."""
        self._stop.set()
        with self._cond:
            self._wake()
        if self._worker is not None:
            self._worker.join()
            self._worker = None

    def __enter__(self):
        return self.connect()

    def __exit__(self, *exc) -> None:
        self.disconnect()

    @property
    def connected(self) -> bool:
        """Whether the link is up and the camera initialised."""
        return self._connected.is_set()

    def set_target(self, pan: float, tilt: float, zoom: float) -> DeviceTarget:
        """Aim at omnijax ``pan``, ``tilt`` (rad) with zoom factor ``zoom``; returns at once.

        Returns the target in device units as it will be sent (clamped to the limits; clamping is
        logged when it starts and stops). A non-finite value is a ``ValueError``.
        """
        t = self.profile.to_device(pan, tilt, zoom)
        if t.clamped != self._clamped:
            if t.clamped:
                log.warning("PTZ target clamped to the device's limits on %s (pan %.2f deg, tilt %.2f deg, "
                            "zoom %.2fx requested)", ", ".join(t.clamped), np.degrees(pan), np.degrees(tilt), zoom)
            else:
                log.info("PTZ target back within the device's limits")
            self._clamped = t.clamped
        with self._cond:
            if t.clamped:
                self._counts["clamped"] += 1
            if self._target is not None and self._sent_seq < self._seq:
                self._counts["superseded"] += 1
            self._target = t
            self._seq += 1
            self._wake()
        return t

    @property
    def target(self) -> DeviceTarget | None:
        """The latest target, in device units."""
        return self._target

    @property
    def sequence(self) -> int:
        """The number of :meth:`set_target` calls so far: the latest target's sequence number."""
        with self._cond:
            return self._seq

    def take_writes(self) -> list[tuple[int, float]]:
        """(sequence number, ``time.monotonic()``) of each target written since the last call: when its
        bytes left for the camera (for frame-to-wire latency)."""
        with self._cond:
            out = list(self._writes)
            self._writes.clear()
        return out

    def request_position(self) -> Future:
        """Ask the camera where it is; the future gives a :class:`PtzPosition` (or raises :class:`PtzError`)."""
        fut: Future = Future()
        with self._cond:
            if not self.connected:
                fut.set_exception(PtzError(f"{self.port}: not connected"))
            else:
                self._queries.append(fut)
                self._wake()
        return fut

    def query_position(self, timeout: float = 2.0) -> PtzPosition:
        """Blocking :meth:`request_position` (not for the real-time loop)."""
        return self.request_position().result(timeout)

    def reached(self, tolerance: int = 1) -> bool:
        """Whether the camera reports the latest target, within ``tolerance`` device units per axis."""
        t = self._target
        if t is None:
            return True
        try:
            pos = self.query_position()
        except (PtzError, TimeoutError):
            return False
        return all(self.profile.units_apart(axis, a, b) <= tolerance
                   for axis, a, b in zip(_AXES, pos.units, (t.pan, t.tilt, t.zoom)))

    def wait_reached(self, timeout: float, tolerance: int = 1, poll_s: float = 0.05,
                     cancel: threading.Event | None = None) -> bool:
        """Poll :meth:`reached` until it holds, ``timeout`` s pass or ``cancel`` is set."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not (cancel is not None and cancel.is_set()):
            if self.connected and self.reached(tolerance):
                return True
            time.sleep(poll_s)
        return False

    @property
    def counters(self) -> dict[str, int]:
        """``commands`` sent, ``errors`` (error replies, faults, time-outs, outages), ``reconnects``."""
        with self._cond:
            return {k: self._counts[k] for k in ("commands", "errors", "reconnects")}

    def stats(self) -> dict:
        """All counters, what the transport adds, and request-to-answer latencies (ms) by kind."""
        with self._cond:
            out: dict = dict(self._counts)
            lat = {k: 1e3 * np.asarray(v) for k, v in self._latency.items()}
            out.update(self._extra_stats())
        out["connected"] = self.connected
        out["latency_ms"] = {
            k: ({"p50": float(np.median(v)), "p99": float(np.percentile(v, 99)), "n": int(v.size)} if v.size
                else {"n": 0}) for k, v in lat.items()}
        return out

    # ------------------------------------------------------------------------------------
    # For the worker
    # ------------------------------------------------------------------------------------

    def _warn(self, message: str, *args) -> None:
        """A warning once the camera has been connected; before that, debug (:meth:`connect`'s one line says why)."""
        (log.warning if self._ever_connected else log.debug)(message, *args)

    def _count(self, *names: str) -> None:
        with self._cond:
            for n in names:
                self._counts[n] += 1

    def _fail_queries(self, reason: str) -> None:
        with self._cond:
            queries, self._queries = list(self._queries), deque()
        for fut in queries:
            if not fut.done():
                fut.set_exception(PtzError(reason))

    def _link_lost(self, reason: str) -> None:
        """The link failed: the first failure of an outage is an error and, once the camera was connected,
        a warning (before that, :meth:`connect` reports ``last_error`` in its one line); pending queries fail."""
        self.last_error = reason
        first = self._outage_since is None
        if first:
            self._outage_since = time.monotonic()
            self._count("errors")
        (self._warn if first else log.debug)("PTZ link lost on %s: %s; reconnecting", self.port, reason)
        self._fail_queries(f"{self.port}: {reason}")

    def _link_up(self) -> str:
        """The camera is connected (again): counts a reconnect, sets ``connected``; returns how long the outage
        was, for the log line (``""`` for the first connection)."""
        with self._cond:
            if self._ever_connected:
                self._counts["reconnects"] += 1
            self._ever_connected = True
            self._connected.set()
            self._cond.notify_all()
        outage, self._outage_since = self._outage_since, None
        return "" if outage is None else f" after {time.monotonic() - outage:.2f} s without"
