"""The ONVIF PTZ driver: steer an IP camera over ONVIF (SOAP over HTTP) from the real-time loop.

Use::

    with OnvifDriver("onvif://admin:secret@192.168.1.20", load_profile("onvif_ptz")) as ptz:
        ptz.set_target(pan, tilt, zoom)      # every frame; returns at once
        print(ptz.counters)                  # {"commands", "errors", "reconnects"}

The same interface and rules as :class:`runtime.ptz.driver.PtzDriver`, from the same base
(:class:`runtime.ptz.base.DriverBase`: latest target wins, nothing queues up, one worker owns
the link, reconnect with exponential back-off, counters),
over the ONVIF client library ``onvif-zeep-async`` (docs/ptz.md says why that one). The
worker runs its own asyncio loop in a thread; ``set_target`` only stores the target.

On connect (and every reconnect) the worker discovers the camera: GetServices (else
GetCapabilities) for the service addresses, media GetProfiles for the first profile with a
PTZ configuration (its ``token``), PTZ GetConfigurationOptions for the move modes it offers,
and GetStatus for whether it reports its position and its move status. Then each new target
is sent with

- ``AbsoluteMove`` where the camera offers it;
- else ``RelativeMove``: the translation from the camera's position (a fresh GetStatus, or
  the driver's estimate where the camera reports none), corrected once the move has ended;
- else ``ContinuousMove``: a velocity proportional to the remaining error (time constant
  :data:`_CONTINUOUS_TAU_S`), polled and steered until within a unit, then ``Stop``;
  the time-out sent with each velocity stops the camera if this driver vanishes.

The move status comes from GetStatus' MoveStatus; where a camera reports none, or never
says IDLE, a timer from the profile's slew rates (plus ``link.retry_delay_s`` of margin, and
never beyond ``link.completion_timeout_s``) says when the move is over (counted as
``timer_fallbacks``). The generic spaces map to device units through the profile
(:meth:`DeviceProfile.to_normalised`): pan and tilt x in [-1, 1] span the limits, zoom
x in [0, 1] spans the lens table.

Failures never escape the worker: a SOAP fault to a move is counted (``faults``, ``errors``)
and the target is sent again only when it changes; a malformed reply is counted
(``malformed``); ``link.max_silent`` failed requests in a row, or a refused connection,
close the session and reconnect (discovering the camera again). A wrong user name or
password is reported by :meth:`connect` as :class:`PtzPortError` (bad input), and while
running is counted (``unauthorised``) and retried with back-off.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from concurrent.futures import Future
from dataclasses import dataclass
from urllib.parse import unquote, urlsplit

from .base import DriverBase
from .errors import PtzError, PtzPortError
from .profile import DeviceProfile, DeviceTarget

log = logging.getLogger("omnijax.ptz")

#: Default HTTP port of ``onvif://HOST``.
DEFAULT_PORT = 80
#: Continuous moves: velocity = error / (full slew rate * tau), so the error decays with this time constant (s);
#: tau grows to twice the measured control period where that is longer (a slow link or a busy machine).
_CONTINUOUS_TAU_S = 0.15
#: Continuous moves: the time-out sent with each velocity (s): the camera stops by itself if we vanish.
_CONTINUOUS_TIMEOUT_S = 1.0
#: A move's status is polled at this interval (s) at most (``link.retry_delay_s`` when larger).
_IDLE_S = 0.1
_AXES = ("pan", "tilt", "zoom")


class _LinkLost(Exception):
    """Internal: the camera cannot be reached or refused us; reconnect."""


class _Unauthorised(_LinkLost):
    """Internal: the camera refused the credentials."""


class _NotOnvif(_LinkLost):
    """Internal: what answered discovery is no ONVIF PTZ camera (no SOAP reply, no PTZ service)."""


class _BadReply(Exception):
    """Internal: what came back is no SOAP reply (the message says what it was)."""


#: Longest reply read (bytes): ONVIF replies are a few kB; the rest of a longer one is not read.
MAX_REPLY_BYTES = 1 << 20


def describe_reply(status: int, content_type: str, body: bytes) -> str | None:
    """Why an HTTP reply (``status``, its ``Content-Type``, its ``body``) is no SOAP reply, in a few words
    naming what came back (``None``: it may be one: XML, and a SOAP envelope where the status is an error)."""
    head = body.lstrip()[:60].decode("utf-8", "replace")
    what = f"HTTP {status} ({content_type or 'no content type'}, {len(body)} bytes: {head!r})"
    if not body.lstrip().startswith(b"<"):
        return f"{what}: not XML"
    if status >= 400 and b"Envelope" not in body:  # a SOAP fault comes with an error status: not this
        return what
    return None


def _capped(transport) -> None:
    """Make ``transport`` (onvif-zeep-async's aiohttp transport of one service) read at most
    :data:`MAX_REPLY_BYTES` of a reply and raise :class:`_BadReply` for one that is no SOAP reply, before
    zeep parses it (zeep's errors for those say nothing of what came back). Replaces the transport's
    ``_post_internal`` (onvif-zeep-async 4.3, pinned) on this instance."""
    session = transport.session

    async def post_internal(address, message, headers):
        headers = {"Content-Type": 'text/xml; charset="utf-8"', **(headers or {})}
        data = message.encode("utf-8") if isinstance(message, str) else message
        response = await session.post(address, data=data, headers=headers, proxy=transport.proxy)
        try:
            chunks, size = [], 0
            async for chunk in response.content.iter_any():
                size += len(chunk)
                if size > MAX_REPLY_BYTES:
                    raise _BadReply(f"HTTP {response.status} ({response.content_type}): a reply of more than "
                                    f"{MAX_REPLY_BYTES >> 10} KiB, not read further")
                chunks.append(chunk)
        finally:
            response.release()
        body = b"".join(chunks)
        why = describe_reply(response.status, response.content_type, body)
        if why is not None:
            raise _BadReply(why)
        return response, body

    transport._post_internal = post_internal


@dataclass
class OnvifUrl:
    """``onvif://[USER:PASSWORD@]HOST[:PORT]`` taken apart."""

    host: str
    port: int
    user: str | None
    password: str | None

    @classmethod
    def parse(cls, url: str) -> OnvifUrl:
        """One-line :class:`PtzPortError` for a malformed URL."""
        try:
            parts = urlsplit(url)
            port = parts.port
        except ValueError as exc:
            raise PtzPortError(f"{redact(url)}: not a usable ONVIF URL: {exc}") from None
        if parts.scheme.lower() != "onvif" or not parts.hostname or parts.netloc.endswith(":"):
            raise PtzPortError(f"{redact(url)}: expected onvif://[USER:PASSWORD@]HOST[:PORT]")
        if parts.path not in ("", "/") or parts.query or parts.fragment:
            raise PtzPortError(f"{redact(url)}: expected nothing after HOST[:PORT] (the services are discovered)")
        user = unquote(parts.username) if parts.username is not None else None
        password = unquote(parts.password) if parts.password is not None else None
        if password is not None and not user:
            raise PtzPortError(f"{redact(url)}: a password without a user name")
        return cls(parts.hostname, DEFAULT_PORT if port is None else port, user or None, password)


def redact(url: str) -> str:
    """``url`` with its password replaced by ``***`` (for messages and logs)."""
    try:
        parts = urlsplit(url)
        if parts.password is None:
            return url
        return url.replace(f":{parts.password}@", ":***@", 1)
    except ValueError:
        return url.split("@")[-1] if "@" in url else url


class _EgressClock:
    """A zeep plugin noting when each request leaves the SOAP layer for the HTTP transport."""

    def __init__(self) -> None:
        self.at = 0.0

    def egress(self, envelope, http_headers, operation, binding_options):
        self.at = time.monotonic()
        return envelope, http_headers

    def ingress(self, envelope, http_headers, operation):
        return envelope, http_headers


class OnvifDriver(DriverBase):
    """Steers one ONVIF PTZ camera; see the module docstring and :class:`DriverBase`."""

    COUNTERS = ("moves", "status_polls", "faults", "timeouts", "malformed", "unauthorised", "corrections",
                "timer_fallbacks")
    LATENCIES = ("move", "query")
    WORKER = "ptz-onvif"

    def __init__(self, port: str, profile: DeviceProfile) -> None:
        super().__init__(redact(port), profile)  # what messages show: never the password
        self._raw_url = port
        self._url: OnvifUrl | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wakeup: asyncio.Event | None = None
        self._unauthorised = False
        self._not_onvif = False
        #: what discovery found: profile token, move modes, whether position and move status are reported
        self.discovered: dict = {}
        # motion book-keeping (worker only): the goal in device units, the estimate, the move's deadline
        self._goal: tuple[float, float, float] | None = None
        self._estimate: list[float] = [0.0, 0.0, float(profile.zoom.position[0])]
        self._estimate_at = 0.0
        self._velocity = (0.0, 0.0, 0.0)  # continuous moves: units/s the camera was told
        self._eta = 0.0
        self._moving = False
        self._settled = True
        self._silent = 0
        self._steered_at = 0.0
        self._steer_period = 0.0
        self._egress = _EgressClock()

    # ------------------------------------------------------------------------------------
    # What DriverBase asks of a driver
    # ------------------------------------------------------------------------------------

    def _check(self) -> None:
        self._url = OnvifUrl.parse(self._raw_url)

    def _hopeless(self) -> bool:
        return self._unauthorised or self._not_onvif

    def _connect_error(self, timeout: float) -> PtzError:
        reason = self.last_error or "no answer"
        if self._unauthorised:
            return PtzPortError(f"{self.port}: the camera refused the user name or password ({reason})")
        if self._not_onvif:
            return PtzError(f"{self.port}: not an ONVIF PTZ camera: {reason}")
        return PtzError(f"{self.port}: no ONVIF PTZ camera within {timeout:g} s ({reason})")

    def _wake(self) -> None:
        loop, wakeup = self._loop, self._wakeup
        if loop is not None and wakeup is not None:
            try:
                loop.call_soon_threadsafe(wakeup.set)
            except RuntimeError:  # the loop has just closed
                pass

    def _extra_stats(self) -> dict:
        return {"onvif": dict(self.discovered), "moving": self._moving}

    def capabilities(self):
        """What this camera offers (a :class:`runtime.ptz.transports.Capabilities`), as discovered at the last
        connect: its move modes (best first), how the end of a move is known, position read-back."""
        from .transports import Capabilities

        p = self.profile
        with self._cond:
            d = dict(self.discovered)
            fallbacks = self._counts["timer_fallbacks"]
        notes = []
        if d and not d["position"]:
            notes.append("no position read-back: positions are the driver's estimate")
        if d and d["move_status"] == "timer":
            notes.append("no MoveStatus: the end of a move is timed from the profile's slew rates")
        if fallbacks:
            notes.append(f"MoveStatus stayed MOVING past the predicted arrival {fallbacks} times: timer used")
        if d and d["mode"] != "absolute":
            notes.append(f"no AbsoluteMove: driven by {d['mode']} moves")
        return Capabilities(
            protocol="onvif", transport="http", move_modes=tuple(d.get("modes", ())),
            move_status=d.get("move_status", "timer"), position=bool(d.get("position")),
            zoom=(float(p.zoom.magnification[0]), float(p.zoom.magnification[-1])),
            limits_deg={"pan": tuple(p.pan.limits_deg), "tilt": tuple(p.tilt.limits_deg)}, notes=tuple(notes))

    # ------------------------------------------------------------------------------------
    # Worker
    # ------------------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except Exception as exc:  # the worker never dies silently: say why, fail the queries
            log.error("PTZ ONVIF worker stopped: %s: %s", type(exc).__name__, exc)
            self.last_error = f"{type(exc).__name__}: {exc}"
        finally:
            self._connected.clear()
            self._fail_queries(f"{self.port}: driver stopped")

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._wakeup = asyncio.Event()
        backoff = self._link.reconnect_backoff_s[0]
        while not self._stop.is_set():
            cam = None
            try:
                cam = await self._open()
                backoff = self._link.reconnect_backoff_s[0]
                await self._serve(cam)
            except _LinkLost as exc:
                if not self._stop.is_set():
                    self._fail(exc)
            except Exception as exc:  # anything the library raised that _call did not classify
                if not self._stop.is_set():
                    self._fail(_LinkLost(f"{type(exc).__name__}: {exc}"))
            finally:
                self._connected.clear()
                if cam is not None:
                    await self._close(cam)
            if not self._stop.is_set() and not self.connected:
                await self._sleep(backoff)
                backoff = min(2 * backoff, self._link.reconnect_backoff_s[1])

    def _fail(self, exc: _LinkLost) -> None:
        """The session failed with ``exc``; before a first connection, refused credentials and an answer that
        is no ONVIF PTZ camera's end :meth:`connect`'s wait (the worker goes on trying meanwhile)."""
        unauthorised = isinstance(exc, _Unauthorised)
        self._unauthorised = unauthorised or (self._unauthorised and not self._ever_connected)
        self._not_onvif = isinstance(exc, _NotOnvif) and not self._ever_connected
        if unauthorised:
            self._count("unauthorised")
        self._link_lost(str(exc))

    async def _sleep(self, seconds: float) -> None:
        """Sleep up to ``seconds``, waking early for a new target, a query or a stop."""
        wake = self._wakeup
        wake.clear()
        try:
            await asyncio.wait_for(wake.wait(), max(0.0, seconds))
        except TimeoutError:
            pass

    async def _close(self, cam) -> None:
        try:
            await asyncio.wait_for(cam.close(), 2.0)
        except Exception as exc:  # closing a session of a vanished camera may fail in many ways
            log.debug("PTZ ONVIF: closing the session: %s", exc)

    # -- requests --------------------------------------------------------------------------

    async def _call(self, service, operation: str, params: dict | None = None, *, kind: str = "",
                    fatal: bool = False):
        """One SOAP request; the reply object (``True`` for an empty one), or ``None`` after a fault, a
        time-out or a malformed reply (each counted). Raises :class:`_LinkLost` after ``link.max_silent``
        failures in a row, for refused credentials, for a refused connection, or at once when ``fatal``."""
        import aiohttp
        import zeep.exceptions

        name = operation if self._url.user else f"authless_{operation}"
        self._count("commands")
        t0 = time.perf_counter()
        why = ""
        malformed = False
        try:
            reply = await asyncio.wait_for(getattr(service, name)(params or {}), self._link.ack_timeout_s)
        except zeep.exceptions.Fault as exc:
            subcode = str(getattr(exc, "subcodes", "") or "")
            text = f"{exc.message or 'SOAP fault'}"
            if "NotAuthorized" in subcode or "NotAuthorized" in text or "not authori" in text.lower():
                raise _Unauthorised(f"{operation}: {text}") from None
            self._count("faults", "errors")
            self._warn("PTZ ONVIF: %s refused: %s", operation, text)
            if fatal:
                raise _LinkLost(f"{operation} refused: {text}") from None
            self._silent = 0  # the camera answered
            return None
        except TimeoutError:
            self._count("timeouts", "errors")
            why = f"no answer to {operation} within {self._link.ack_timeout_s:g} s"
        except (aiohttp.ClientConnectionError, ConnectionError) as exc:
            raise _LinkLost(f"{operation}: {exc or type(exc).__name__}") from None
        except _BadReply as exc:
            self._count("malformed", "errors")
            why, malformed = f"{operation} got {exc}", True
        except Exception as exc:  # malformed replies surface as many types from zeep, lxml and the library
            if self._is_http_auth_failure(exc):
                raise _Unauthorised(f"{operation}: HTTP 401") from None
            if isinstance(exc, aiohttp.ClientError) or "Cannot connect" in str(exc):
                raise _LinkLost(f"{operation}: {exc}") from None
            self._count("malformed", "errors")
            why, malformed = f"malformed reply to {operation}: {type(exc).__name__}: {str(exc)[:120]}", True
        else:
            self._silent = 0
            if kind:
                with self._cond:
                    self._latency[kind].append(time.perf_counter() - t0)
            return True if reply is None else reply  # an empty response (AbsoluteMoveResponse) is a success
        self._silent += 1
        self._warn("PTZ ONVIF: %s", why)
        if fatal:
            raise (_NotOnvif if malformed else _LinkLost)(why)
        if self._silent >= self._link.max_silent:
            raise _LinkLost(f"{self._silent} requests in a row failed ({why})")
        return None

    @staticmethod
    def _is_http_auth_failure(exc: Exception) -> bool:
        status = getattr(exc, "status_code", None) or getattr(exc, "status", None)
        return status == 401

    # -- discovery -------------------------------------------------------------------------

    async def _open(self):
        from onvif import ONVIFCamera

        u = self._url
        cam = ONVIFCamera(u.host, u.port, u.user or "", u.password or "", no_cache=True)
        try:
            await self._discover(cam)
        except BaseException:
            await self._close(cam)
            raise
        with self._cond:
            self._sent_seq = 0  # the latest target is sent again
        self._unauthorised = self._not_onvif = False
        after = self._link_up()
        d = self.discovered
        log.info("PTZ connected on %s (ONVIF, profile %s, %s moves, status: %s)%s", self.port,
                 d["profile_token"], d["mode"], d["move_status"], after)
        return cam

    async def _discover(self, cam) -> None:
        self._silent = 0
        device = await cam.create_devicemgmt_service()
        _capped(device.transport)
        services = await self._call(device, "GetServices", {"IncludeCapability": False}, fatal=True)
        xaddrs = {}
        for s in services or []:
            ns, xaddr = getattr(s, "Namespace", None), getattr(s, "XAddr", None)
            if isinstance(ns, str) and isinstance(xaddr, str):
                xaddrs[ns] = xaddr
        if not xaddrs:
            caps = await self._call(device, "GetCapabilities", {"Category": "All"}, fatal=True)
            for name, ns in (("Media", "http://www.onvif.org/ver10/media/wsdl"),
                             ("PTZ", "http://www.onvif.org/ver20/ptz/wsdl")):
                xaddr = getattr(getattr(caps, name, None), "XAddr", None)
                if isinstance(xaddr, str):
                    xaddrs[ns] = xaddr
        cam.xaddrs = xaddrs
        for ns, what in (("http://www.onvif.org/ver10/media/wsdl", "media"),
                         ("http://www.onvif.org/ver20/ptz/wsdl", "PTZ")):
            if ns not in xaddrs:
                raise _NotOnvif(f"the camera offers no {what} service")
        media = await cam.create_media_service()
        ptz = await cam.create_ptz_service()
        for svc in (media, ptz):
            _capped(svc.transport)
        for svc in (device, media, ptz):
            for client in (svc.zeep_client, svc.zeep_client_authless):
                client.plugins.append(self._egress)
        profiles = await self._call(media, "GetProfiles", fatal=True) or []
        chosen = next((p for p in profiles if getattr(p, "PTZConfiguration", None) is not None), None)
        if chosen is None or not isinstance(getattr(chosen, "token", None), str):
            raise _NotOnvif("no media profile with a PTZ configuration")
        config_token = getattr(chosen.PTZConfiguration, "token", None)
        options = await self._call(ptz, "GetConfigurationOptions", {"ConfigurationToken": config_token}, fatal=True)
        spaces = getattr(options, "Spaces", None)

        def offered(name: str) -> bool:
            return bool(getattr(spaces, name, None))

        modes = [m for m, space in (("absolute", "AbsolutePanTiltPositionSpace"),
                                    ("relative", "RelativePanTiltTranslationSpace"),
                                    ("continuous", "ContinuousPanTiltVelocitySpace")) if offered(space)]
        if not modes:
            raise _NotOnvif("the camera offers no pan/tilt move (no absolute, relative or continuous space)")
        zoom_modes = [m for m, space in (("absolute", "AbsoluteZoomPositionSpace"),
                                         ("relative", "RelativeZoomTranslationSpace"),
                                         ("continuous", "ContinuousZoomVelocitySpace")) if offered(space)]
        self._ptz, self._token = ptz, chosen.token
        status = await self._call(ptz, "GetStatus", {"ProfileToken": chosen.token}, fatal=True)
        pos = self._position_of(status)
        move_status = getattr(getattr(status, "MoveStatus", None), "PanTilt", None)
        with self._cond:
            self.discovered = {
                "host": self._url.host, "port": self._url.port, "profile_token": chosen.token,
                "configuration_token": config_token, "modes": modes, "zoom_modes": zoom_modes, "mode": modes[0],
                "position": pos is not None, "move_status": "status" if move_status is not None else "timer",
                "services": sorted(xaddrs),
            }
        now = time.monotonic()
        if pos is not None:
            self._estimate, self._estimate_at = list(pos), now
        self._goal, self._moving, self._settled, self._velocity = None, False, True, (0.0, 0.0, 0.0)

    def _position_of(self, status) -> tuple[float, float, float] | None:
        """GetStatus' position in device units (floats), or ``None`` where the camera reports none or
        nonsense."""
        p = getattr(status, "Position", None)
        pt, z = getattr(p, "PanTilt", None), getattr(p, "Zoom", None)
        try:
            xs = (float(pt.x), float(pt.y), float(z.x))
        except (AttributeError, TypeError, ValueError):
            return None
        if not all(math.isfinite(v) for v in xs) or not (-1.5 <= xs[0] <= 1.5 and -1.5 <= xs[1] <= 1.5
                                                         and -0.5 <= xs[2] <= 1.5):
            self._count("malformed")
            return None
        return tuple(self.profile.from_normalised(a, x) for a, x in zip(_AXES, xs))

    def _reported_moving(self, status) -> bool | None:
        ms = getattr(status, "MoveStatus", None)
        if ms is None:
            return None
        words = [str(getattr(ms, g, "") or "").upper() for g in ("PanTilt", "Zoom")]
        if not any(words):
            return None
        return any(w == "MOVING" for w in words)

    # -- serving ---------------------------------------------------------------------------

    async def _serve(self, cam) -> None:
        poll = max(self._link.retry_delay_s, 0.01)
        next_send = 0.0
        while not self._stop.is_set():
            with self._cond:
                query = self._queries.popleft() if self._queries else None
            if query is not None:
                await self._answer_query(query)
                continue
            now = time.monotonic()
            with self._cond:
                target, seq = self._target, self._seq
                fresh = target is not None and self._sent_seq < seq
            if fresh and now >= next_send:
                with self._cond:
                    self._sent_seq = seq
                await self._move(target, seq)
                next_send = time.monotonic() + self._link.min_interval_s
                continue
            if not self._settled:
                await self._follow()
                await self._sleep(poll)
                continue
            await self._sleep(next_send - now if fresh else _IDLE_S)
        if any(self._velocity):  # leaving mid continuous move: stop the camera now, not at the move's time-out
            self._count("moves")
            await self._call(self._ptz, "Stop", {"ProfileToken": self._token, "PanTilt": True, "Zoom": True})
            self._velocity = (0.0, 0.0, 0.0)

    def _estimate_now(self, now: float) -> list[float]:
        """Where the camera should be by now: the last known position moved toward the goal at the
        slew rates (absolute and relative moves), or by the commanded velocity (continuous)."""
        dt = max(0.0, now - self._estimate_at)
        est = list(self._estimate)
        for i, axis in enumerate(_AXES):
            if any(self._velocity):
                est[i] += self._velocity[i] * dt
            elif self._goal is not None:
                d = self._goal[i] - est[i]
                step = self._rate(axis) * dt
                est[i] = self._goal[i] if abs(d) <= step else est[i] + math.copysign(step, d)
            lo, hi = self._limits(axis)
            est[i] = min(max(est[i], lo), hi)
        return est

    def _set_estimate(self, est, now: float) -> None:
        self._estimate, self._estimate_at = list(est), now

    def _rate(self, axis: str) -> float:
        z = self.profile.zoom
        return ((z.position[-1] - z.position[0]) / z.seconds_full_range if axis == "zoom"
                else self.profile.move_units_s(axis))

    def _limits(self, axis: str) -> tuple[float, float]:
        if axis == "zoom":
            return float(self.profile.zoom.position[0]), float(self.profile.zoom.position[-1])
        return tuple(map(float, self.profile.limits_units(axis)))

    def _travel_s(self, frm, to) -> float:
        return max(abs(b - a) / self._rate(axis) for axis, a, b in zip(_AXES, frm, to))

    async def _status(self):
        self._count("status_polls")
        return await self._call(self._ptz, "GetStatus", {"ProfileToken": self._token}, kind="query")

    async def _move(self, t: DeviceTarget, seq: int) -> None:
        goal = (float(t.pan), float(t.tilt), float(t.zoom))
        mode = self.discovered["mode"]
        now = time.monotonic()
        here = self._estimate_now(now)
        if mode == "relative" and self.discovered["position"]:
            status = await self._status()
            pos = self._position_of(status)
            if pos is not None:
                here = list(pos)
                now = time.monotonic()
        self._goal, self._velocity = goal, (0.0, 0.0, 0.0)
        if mode == "continuous":
            self._set_estimate(here, now)
            self._settled = False
            await self._steer(here)
            return
        p = self.profile
        if mode == "absolute":
            vec = {axis: p.to_normalised(axis, g) for axis, g in zip(_AXES, goal)}
            params = {"ProfileToken": self._token,
                      "Position": {"PanTilt": {"x": vec["pan"], "y": vec["tilt"]}, "Zoom": {"x": vec["zoom"]}}}
            op = "AbsoluteMove"
        else:
            d = {axis: (g - h) / p.normalised_scale(axis) for axis, g, h in zip(_AXES, goal, here)}
            params = {"ProfileToken": self._token,
                      "Translation": {"PanTilt": {"x": d["pan"], "y": d["tilt"]}, "Zoom": {"x": d["zoom"]}}}
            op = "RelativeMove"
        self._count("moves")
        reply = await self._call(self._ptz, op, params, kind="move")
        if reply is None:
            if self._silent:  # unanswered or garbled (counted): it may not have moved, send the latest again
                with self._cond:
                    self._sent_seq = 0
            return  # a fault (counted): sent again when the target changes
        with self._cond:
            self._writes.append((seq, self._egress.at))
        self._set_estimate(here, now)
        self._eta = now + self._travel_s(here, goal) + self._link.retry_delay_s
        self._moving, self._settled = True, False

    async def _steer(self, here) -> None:
        """Continuous mode: a velocity toward the goal, or Stop once within half a unit on every axis. The
        camera coasts on for the Stop's round trip (longer on a slow link or a loaded machine): where it
        reports its position, the next status poll looks where it stopped and steers back if it is off."""
        err = [g - h for g, h in zip(self._goal, here)]
        if all(abs(e) <= 0.5 for e in err):
            stopped = any(self._velocity)
            if stopped:
                self._count("moves")
                await self._call(self._ptz, "Stop", {"ProfileToken": self._token, "PanTilt": True, "Zoom": True})
            self._velocity = (0.0, 0.0, 0.0)
            verify = stopped and self.discovered["position"]
            self._moving, self._settled = bool(verify), not verify
            return
        # the camera keeps the velocity until the next command: cover at most half the error per control period
        # (measured), so that the loop stays stable however slow the link or the machine is
        now = time.monotonic()
        if 0 < now - self._steered_at < 2.0:
            self._steer_period = 0.7 * self._steer_period + 0.3 * (now - self._steered_at)
        self._steered_at = now
        tau = max(_CONTINUOUS_TAU_S, 2.0 * self._steer_period)
        v = [max(-1.0, min(1.0, e / (self._rate(a) * tau))) for a, e in zip(_AXES, err)]
        params = {"ProfileToken": self._token, "Velocity": {"PanTilt": {"x": v[0], "y": v[1]}, "Zoom": {"x": v[2]}},
                  "Timeout": f"PT{_CONTINUOUS_TIMEOUT_S:g}S"}
        self._count("moves")
        reply = await self._call(self._ptz, "ContinuousMove", params, kind="move")
        if reply is not None:
            with self._cond:
                self._writes.append((self._seq, self._egress.at))
            self._velocity = tuple(vi * self._rate(a) for vi, a in zip(v, _AXES))
            self._moving = True

    async def _follow(self) -> None:
        """While a move runs: poll the status; say when it is over; correct relative moves, steer continuous."""
        mode = self.discovered["mode"]
        now = time.monotonic()
        status = await self._status() if self.discovered["position"] or self.discovered["move_status"] == "status" \
            else None
        pos = self._position_of(status) if status is not None else None
        est = list(pos) if pos is not None else self._estimate_now(now)
        self._set_estimate(est, now)
        if mode == "continuous":
            if pos is None:  # dead reckoning: the velocity holds until the next command
                self._estimate_at = now
            await self._steer(est)
            return
        reported = self._reported_moving(status) if status is not None else None
        deadline = min(self._eta, now + self._link.completion_timeout_s)
        if reported is False or now >= deadline:
            if reported is True:
                self._count("timer_fallbacks")  # the camera still says MOVING: believe the timer
            self._moving, self._settled = False, True
            if mode == "relative" and pos is not None and self._goal is not None and \
                    max(abs(g - p) for g, p in zip(self._goal, pos)) > 1:
                self._count("corrections")
                with self._cond:
                    self._sent_seq = 0  # send the latest target again, as a translation from where it is
        elif reported is None and now >= self._eta:
            self._count("timer_fallbacks")

    async def _answer_query(self, fut: Future) -> None:
        if not self.discovered.get("position"):
            est = self._estimate_now(time.monotonic())
            fut.set_result(self.profile.from_device(*(round(v) for v in est)))
            return
        try:
            status = await self._status()
        except _LinkLost as exc:
            fut.set_exception(PtzError(f"{self.port}: position inquiry failed ({exc})"))
            raise
        pos = self._position_of(status) if status is not None else None
        if pos is None:
            fut.set_exception(PtzError(f"{self.port}: position inquiry failed (no usable GetStatus)"))
            return
        self._set_estimate(pos, time.monotonic())
        fut.set_result(self.profile.from_device(*(round(v) for v in pos)))

