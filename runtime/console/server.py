"""The operator's console: a web page and its JSON API (``--serve HOST:PORT`` of ``run`` and ``demo``).

The server is aiohttp (docs/console.md says why) on an event loop of its own thread. It reads only what
the drawing thread leaves (:class:`~runtime.console.live.LiveView`) and the console's own state, and
asks things of the loop only through :class:`~runtime.realtime.operator.Operator`, which the control
thread reads once a frame without waiting. Anything that takes time (rebuilding the detector's mask for
new zones, the rig fit) runs off both the server's loop and the control thread.

Every request that changes something (POST) needs ``Authorization: Bearer TOKEN``, the token printed at
start; without it, 401. Bad requests (malformed JSON, unknown tracks, bad polygons) get a 4xx with a JSON
``{"error": "..."}`` of one line; the loop is never affected by them. The API is in docs/console.md.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import math
import os
import secrets
import socket
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
from aiohttp import web

from omnijax.config import ConfigError, parse_zones
from runtime.console.calibration import CalibrationAssistant
from runtime.console.live import LiveView
from runtime.errors import UsageError
from runtime.realtime.operator import POINT_S, Operator

#: How long a click on the floor, the home button or a jog keeps the PTZ under manual control (s).
MANUAL_S = POINT_S
#: Most seconds a manual pointing may be asked for.
MAX_MANUAL_S = 3600.0
#: JPEG quality of the live images.
JPEG_QUALITY = 80
#: Largest request body the API reads (bytes); a larger one is answered 413.
MAX_BODY = 2**20
#: The nice value of the console's threads (the server's and its workers'): a page never takes the CPU
#: from the control thread (Linux, where a thread has a nice value of its own; elsewhere the default).
NICE = 10


def _yield_cpu() -> None:
    """Give the calling thread the console's lower scheduling priority (:data:`NICE`; Linux only)."""
    if sys.platform.startswith("linux"):
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), NICE)
        except OSError:  # not allowed here: the page then shares the CPU as before
            pass


class ApiError(Exception):
    """A request the console refuses: HTTP ``status`` and one line."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status


def parse_serve(spec: str) -> tuple[str, int]:
    """``--serve HOST:PORT`` (``[V6]:PORT``; ``:PORT`` is 127.0.0.1); one-line :class:`UsageError` otherwise."""
    expected = "expected HOST:PORT, e.g. 127.0.0.1:8080 (port 0: any free port)"
    host, sep, port = spec.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UsageError(f"--serve: {expected}, got {spec!r}")
    if host.startswith("[") or host.endswith("]"):
        if not (host.startswith("[") and host.endswith("]")):
            raise UsageError(f"--serve: {expected}, got {spec!r}")
        host = host[1:-1]
    if not host:
        host = "127.0.0.1"
    if any(c in host for c in "/ ?#@[]"):
        raise UsageError(f"--serve: {expected}, got {spec!r}")
    return host, int(port)


def bind(spec: str) -> socket.socket:
    """A listening socket for ``--serve`` (bound before any work, so that a port in use or an address
    this machine does not have is one line and exit code 2)."""
    host, port = parse_serve(spec)
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise UsageError(f"--serve: cannot resolve {host!r} ({exc.strerror})") from None
    family, _, _, _, address = infos[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(64)
    except OSError as exc:
        sock.close()
        why = "the port is in use" if exc.errno == 98 else exc.strerror or str(exc)
        raise UsageError(f"--serve: cannot listen on {spec} ({why})") from None
    sock.setblocking(False)
    return sock


def _url_host(host: str) -> str:
    try:
        return f"[{host}]" if ipaddress.ip_address(host).version == 6 else host
    except ValueError:
        return host


class Console:
    """The console's server and state; ``with Console(spec) as console:`` serves until the block ends.

    The session attaches the running loop (:meth:`attach`); until then the page says the system is
    starting. ``rig_path``: the rig file ``POST /api/zones`` writes the zones into (``None``: kept in
    memory only); ``profile_spec``: the PTZ device profile the calibration assistant's fit uses.
    """

    def __init__(self, spec: str, rig_path: Path | None = None, profile_spec: str | None = None):
        self.sock = bind(spec)
        self.host, self.port = self.sock.getsockname()[:2]
        self.token = secrets.token_urlsafe(18)
        self.url = f"http://{_url_host(self.host)}:{self.port}/"
        self.rig_path, self.profile_spec = rig_path, profile_spec
        self.operator = Operator()
        self.live: LiveView | None = None
        self.events = None  # the session's EventLog (its latest faces)
        self.loop = self.rig = None
        self.zones: tuple = ()
        self.zones_version = 0
        self.zones_error: str | None = None
        self.calibration: CalibrationAssistant | None = None
        self._jpeg_cache: dict[str, tuple[int, bytes]] = {}
        self._thread = threading.Thread(target=self._serve, name="omnijax-console", daemon=True)
        self._ready = threading.Event()
        self._aio: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self.error: BaseException | None = None

    # -- lifecycle ------------------------------------------------------------------------

    def __enter__(self) -> Console:
        self._thread.start()
        self._ready.wait(10)
        if self.error is not None:
            raise RuntimeError(f"the console's server did not start: {self.error!r}")
        print(f"serving {self.url}?token={self.token}", file=sys.stderr, flush=True)
        return self

    def __exit__(self, *exc) -> None:
        if self._aio is not None and self._stop is not None:
            self._aio.call_soon_threadsafe(self._stop.set)
        self._thread.join(10)
        self.sock.close()

    def attach(self, loop, rig, annotator, stage: Path, driver=None, profile=None) -> LiveView:
        """Connect the running session: the loop (its operator is this console's), the rig, the
        annotator; ``stage`` is where the calibration assistant writes. Returns the drawing thread's hook."""
        self.rig, self.loop = rig, loop
        self.zones, self.zones_version = tuple(rig.zones), 0
        self.live = LiveView(rig, annotator, loop)
        self.calibration = CalibrationAssistant(rig, self.rig_path, stage / "calibration", driver, profile,
                                                self.profile_spec, self._pointing_sent)
        cx, cy = (float(v) for v in rig.omni.center)  # compile the floor click's aim now, not on the first click
        threading.Thread(target=_aim_at_pixel, args=(rig, loop.cfg.zoom_rule, cx + 0.3 * float(rig.omni.r_m), cy),
                         name="omnijax-console-warm-up", daemon=True).start()
        return self.live

    def _pointing_sent(self) -> bool:
        """Whether the latest frame the drawing thread saw had the operator's manual pointing sent."""
        st = self.operator.state
        point = st.pointing(time.monotonic())
        snap = self.live.snapshot if self.live is not None else None
        if point is None or snap is None:
            return point is None
        sent = _sent(snap, st.point_camera)
        return sent is not None and all(abs(a - b) < 1e-4 for a, b in zip(sent[:2], point[:2])) \
            and abs(sent[2] - point[2]) < 1e-3

    def _serve(self) -> None:
        try:
            _yield_cpu()
            self._aio = asyncio.new_event_loop()
            asyncio.set_event_loop(self._aio)
            self._aio.set_default_executor(ThreadPoolExecutor(2, "omnijax-console-work", initializer=_yield_cpu))
            self._stop = asyncio.Event()
            runner = web.AppRunner(self.app(), access_log=None, handle_signals=False, shutdown_timeout=1.0)
            self._aio.run_until_complete(runner.setup())
            self._aio.run_until_complete(web.SockSite(runner, self.sock).start())
        except BaseException as exc:
            self.error = exc
            self._ready.set()
            return
        self._ready.set()
        self._aio.run_until_complete(self._stop.wait())
        self._aio.run_until_complete(runner.cleanup())
        left = asyncio.all_tasks(self._aio)  # a connection still open (a page polling at the end)
        for task in left:
            task.cancel()
        self._aio.run_until_complete(asyncio.gather(*left, return_exceptions=True))
        self._aio.run_until_complete(self._aio.shutdown_default_executor())
        self._aio.close()

    # -- the app --------------------------------------------------------------------------

    def app(self) -> web.Application:
        app = web.Application(middlewares=[self._errors, self._auth], client_max_size=MAX_BODY)
        get = [("/", self._page), ("/static/{name}", self._static), ("/api/status", self._status),
               ("/api/zones", self._get_zones), ("/api/view/{which}.jpg", self._view), ("/api/events", self._events),
               ("/api/faces", self._faces), ("/api/faces/{k}.jpg", self._face), ("/api/calibration", self._get_cal)]
        post = [("/api/target", self._target), ("/api/zones", self._post_zones), ("/api/point", self._point),
                ("/api/ptz", self._ptz), ("/api/release", self._release), ("/api/pause", self._pause),
                ("/api/home", self._home), ("/api/calibration/mark", self._cal_mark),
                ("/api/calibration/clear", self._cal_clear), ("/api/calibration/fit", self._cal_fit)]
        app.add_routes([web.get(p, h) for p, h in get] + [web.post(p, h) for p, h in post])
        return app

    @web.middleware
    async def _errors(self, request, handler):
        try:
            return await handler(request)
        except ApiError as exc:
            return web.json_response({"error": str(exc)}, status=exc.status)
        except web.HTTPException as exc:
            if exc.status < 400:
                raise
            if exc.status == 413:
                return web.json_response({"error": f"request body too large: at most {MAX_BODY // 1024} KiB "
                                                   f"({request.method} {request.path})"}, status=413)
            return web.json_response({"error": f"{exc.reason}: {request.method} {request.path}"}, status=exc.status)
        except Exception as exc:  # a bug in a handler: the loop goes on, the page is told
            return web.json_response({"error": f"internal error: {exc!r}"}, status=500)

    @web.middleware
    async def _auth(self, request, handler):
        if request.method not in ("GET", "HEAD"):
            given = request.headers.get("Authorization", "")
            if not hmac.compare_digest(given.encode(), f"Bearer {self.token}".encode()):
                return web.json_response({"error": "this needs Authorization: Bearer TOKEN (the token printed "
                                                   "at start, also in the page's address)"},
                                         status=401, headers={"WWW-Authenticate": "Bearer"})
        return await handler(request)

    async def _body(self, request) -> dict:
        try:
            body = await request.json()
        except (ValueError, UnicodeDecodeError) as exc:
            raise ApiError(400, f"malformed JSON: {exc}") from None
        if not isinstance(body, dict):
            raise ApiError(400, f"expected a JSON object, got {type(body).__name__}")
        return body

    def _running(self):
        if self.loop is None or self.live is None or self.live.snapshot is None:
            raise ApiError(503, "the system is still starting (learning the background, compiling); try again")
        return self.live.snapshot

    # -- pages and views ------------------------------------------------------------------

    async def _page(self, request):
        return web.Response(text=_static_text("index.html"), content_type="text/html")

    async def _static(self, request):
        name = request.match_info["name"]
        types = {"console.js": "application/javascript", "console.css": "text/css"}
        if name not in types:
            raise ApiError(404, f"no such file: /static/{name}")
        return web.Response(text=_static_text(name), content_type=types[name])

    async def _status(self, request):
        snap = self.live.snapshot if self.live is not None else None
        if snap is None:
            return web.json_response({"starting": True, "frames": 0, "fps": 0.0,
                                      "latency_ms": {"p50": None, "p99": None}, "tracks": [], "target": None,
                                      "ptz": None})
        return web.json_response({"starting": False, **snap.status, "zones_pending": self._zones_pending(snap),
                                  "ptz_view": snap.ptz_label})

    def _zones_pending(self, snap) -> bool:
        return snap.status["zones_version"] != self.zones_version

    async def _view(self, request):
        which = request.match_info["which"]
        count = self.rig.ptz_count if self.rig is not None else 1
        views = ("omni", "ptz", *(f"ptz{k}" for k in range(count)))
        if which not in views:
            raise ApiError(404, f"no such view: {which} ({', '.join(views)})")
        snap = self.live.snapshot if self.live is not None else None
        k = 0 if which == "ptz" else int(which[3:]) if which != "omni" else None
        image = None if snap is None else snap.omni if k is None else snap.views[k][0]
        if image is None:
            raise ApiError(404, f"no {which} image yet")
        cached = self._jpeg_cache.get(which)
        if cached is None or cached[0] != snap.index:
            jpeg = await asyncio.get_running_loop().run_in_executor(None, _jpeg, image)
            cached = self._jpeg_cache[which] = (snap.index, jpeg)
        return web.Response(body=cached[1], content_type="image/jpeg", headers={"Cache-Control": "no-store"})

    async def _events(self, request):
        return web.json_response({"events": self.live.recent_events() if self.live is not None else []})

    def _recent_faces(self) -> list:
        return list(self.events.faces) if self.events is not None else []

    async def _faces(self, request):
        return web.json_response({"faces": [{**event, "image": f"/api/faces/{k}.jpg"}
                                            for k, (event, _) in enumerate(self._recent_faces())]})

    async def _face(self, request):
        faces = self._recent_faces()
        try:
            k = int(request.match_info["k"])
            return web.Response(body=faces[k][1], content_type="image/jpeg")
        except (ValueError, IndexError):
            raise ApiError(404, f"no face {request.match_info['k']}") from None

    # -- controls -------------------------------------------------------------------------

    async def _target(self, request):
        body = await self._body(request)
        if "track" not in body:
            raise ApiError(400, 'expected {"track": ID} (null: back to the automatic choice)')
        track = body["track"]
        if track is not None and (not isinstance(track, int) or isinstance(track, bool)):
            raise ApiError(400, f"track: expected a track id (integer) or null, got {track!r}")
        snap = self._running()
        if track is not None and track not in {tr["id"] for tr in snap.status["tracks"]}:
            raise ApiError(404, f"no track {track} now (tracks: {[tr['id'] for tr in snap.status['tracks']]})")
        st = self.operator.choose(track)
        return web.json_response({"target": st.target, "version": st.version})

    def _seconds(self, body) -> float:
        seconds = body.get("seconds", MANUAL_S)
        if not isinstance(seconds, (int, float)) or isinstance(seconds, bool) or not 0 < seconds <= MAX_MANUAL_S:
            raise ApiError(400, f"seconds: expected a number in (0, {MAX_MANUAL_S:g}], got {seconds!r}")
        return float(seconds)

    def _camera(self, body) -> int:
        """The PTZ a request is for (``camera``, the rig's order; default the first)."""
        k = body.get("camera", 0)
        count = self.rig.ptz_count
        if not isinstance(k, int) or isinstance(k, bool) or not 0 <= k < count:
            raise ApiError(400, f"camera: expected a PTZ number 0 to {count - 1}, got {k!r}")
        return k

    def _number(self, body, key, default=None) -> float:
        v = body.get(key, default)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise ApiError(400, f"{key}: expected a finite number, got {v!r}")
        return float(v)

    async def _point(self, request):
        body = await self._body(request)
        self._running()
        x, y = self._number(body, "x"), self._number(body, "y")
        seconds, camera = self._seconds(body), self._camera(body)
        W, H = self.rig.omni.image_size
        if not (0 <= x <= W and 0 <= y <= H):
            raise ApiError(400, f"x, y: ({x:g}, {y:g}) lies outside the {W}x{H} omni image")
        aim = await asyncio.get_running_loop().run_in_executor(None, _aim_at_pixel, self.rig.ptz(camera),
                                                               self.loop.cfg.zoom_rule, x, y)
        if aim is None:
            raise ApiError(422, f"({x:g}, {y:g}) is not a floor point the PTZ can aim at (beyond the floor's "
                                "horizon, or at the PTZ's foot)")
        st = self.operator.point(*aim, seconds=seconds, camera=camera)
        return web.json_response(self._pointing(st))

    @staticmethod
    def _pointing(st) -> dict:
        pan, tilt, zoom = st.point
        return {"pan_deg": round(math.degrees(pan), 3), "tilt_deg": round(math.degrees(tilt), 3),
                "zoom": round(zoom, 3), "until": st.point_until, "camera": st.point_camera, "version": st.version}

    async def _ptz(self, request):
        """Absolute (``pan_deg``, ``tilt_deg``, ``zoom``) or relative (``dpan_deg``, ``dtilt_deg``, ``zoom_factor``)
        to where the PTZ was sent last: the calibration assistant's keys."""
        body = await self._body(request)
        snap = self._running()
        known = {"pan_deg", "tilt_deg", "zoom", "dpan_deg", "dtilt_deg", "zoom_factor", "seconds", "camera"}
        if not body or set(body) - known:
            raise ApiError(400, f"expected some of {sorted(known)}, got {sorted(body)}")
        camera = self._camera(body)
        st = self.operator.state
        held = st.pointing(time.monotonic()) if st.point_camera == camera else None
        cur = held or _sent(snap, camera) or self.loop.cfg.home
        pan = math.radians(self._number(body, "pan_deg")) if "pan_deg" in body else cur[0]
        tilt = math.radians(self._number(body, "tilt_deg")) if "tilt_deg" in body else cur[1]
        zoom = self._number(body, "zoom") if "zoom" in body else cur[2]
        pan += math.radians(self._number(body, "dpan_deg", 0.0))
        tilt += math.radians(self._number(body, "dtilt_deg", 0.0))
        zoom *= self._number(body, "zoom_factor", 1.0)
        foveal = self.rig.ptz(camera).foveal
        zoom = min(max(zoom, float(foveal.lens.zoom_range[0])), float(foveal.lens.zoom_range[1]))
        lo, hi = np.asarray(foveal.tilt_limits)
        tilt = min(max(tilt, float(lo)), float(hi))
        pan = math.remainder(pan, 2 * math.pi)
        try:
            st = self.operator.point(pan, tilt, zoom, seconds=self._seconds(body), camera=camera)
        except ValueError as exc:
            raise ApiError(400, str(exc)) from None
        return web.json_response(self._pointing(st))

    async def _release(self, request):
        st = self.operator.release()
        return web.json_response({"version": st.version})

    async def _pause(self, request):
        body = await self._body(request)
        paused = body.get("paused")
        if not isinstance(paused, bool):
            raise ApiError(400, f'expected {{"paused": true | false}}, got {body!r}')
        st = self.operator.pause(paused)
        return web.json_response({"paused": st.paused, "version": st.version})

    async def _home(self, request):
        self._running()
        body = await self._body(request) if request.can_read_body else {}
        st = self.operator.point(*self.loop.cfg.home, seconds=self._seconds(body), camera=self._camera(body))
        return web.json_response(self._pointing(st))

    # -- zones ----------------------------------------------------------------------------

    async def _get_zones(self, request):
        W, H = (self.rig.omni.image_size if self.rig is not None else (None, None))
        snap = self.live.snapshot if self.live is not None else None
        return web.json_response({
            "zones": [z.as_dict() for z in self.zones], "version": self.zones_version,
            "applied": snap is not None and not self._zones_pending(snap), "error": self.zones_error,
            "image_size": [W, H], "file": str(self.rig_path) if self.rig_path else None})

    async def _post_zones(self, request):
        body = await self._body(request)
        self._running()
        if set(body) != {"zones"}:
            raise ApiError(400, f'expected {{"zones": [{{"kind", "points", "name"}}, ...]}}, got keys {sorted(body)}')
        try:
            zones = parse_zones(body["zones"], self.rig.omni.image_size, "POST /api/zones")
        except ConfigError as exc:
            raise ApiError(422, str(exc)) from None
        saved = None
        if self.rig_path is not None:
            from runtime.files import write_zones

            try:
                await asyncio.get_running_loop().run_in_executor(None, write_zones, self.rig_path, zones)
            except (ConfigError, OSError) as exc:
                raise ApiError(500, f"could not save the zones in {self.rig_path}: {exc}") from None
            saved = str(self.rig_path)
        self.zones_version += 1
        self.zones, version = zones, self.zones_version
        threading.Thread(target=self._rebuild, args=(zones, version), name="omnijax-zones", daemon=True).start()
        return web.json_response({"zones": [z.as_dict() for z in zones], "version": version, "saved": saved})

    def _rebuild(self, zones, version: int) -> None:
        """The detector's mask and the priority test for ``zones`` (seconds; this thread), handed to the loop."""
        from runtime.realtime.zones import zone_swap

        try:
            swap = zone_swap(self.rig, self.loop.detector, zones, version)
        except Exception as exc:  # shown on the page; the loop keeps the zones it has
            self.zones_error = f"zones {version}: {exc!r}"
            return
        if version == self.zones_version:  # a newer set supersedes this one
            self.zones_error = None
            self.operator.offer_zones(swap)

    # -- the calibration assistant --------------------------------------------------------

    async def _get_cal(self, request):
        if self.calibration is None:
            return web.json_response({"observations": [], "result": None, "running": False})
        return web.json_response(self.calibration.report())

    async def _cal_mark(self, request):
        body = await self._body(request)
        self._running()
        x, y = self._number(body, "x"), self._number(body, "y")
        height = self._number(body, "height_m", 0.0)
        try:
            obs = await asyncio.get_running_loop().run_in_executor(None, self.calibration.mark, x, y, height)
        except ValueError as exc:
            raise ApiError(422, str(exc)) from None
        return web.json_response(obs)

    async def _cal_clear(self, request):
        self._running()
        self.calibration.clear()
        return web.json_response(self.calibration.report())

    async def _cal_fit(self, request):
        self._running()
        try:
            await self.calibration.fit()
        except ValueError as exc:
            raise ApiError(422, str(exc)) from None
        return web.json_response(self.calibration.report())


def _sent(snap, camera: int = 0) -> tuple[float, float, float] | None:
    """Where PTZ ``camera`` was sent last, as the latest snapshot has it."""
    p = snap.status["cameras"][camera]
    if p is None or p["pan_deg"] is None:
        return None
    return math.radians(p["pan_deg"]), math.radians(p["tilt_deg"]), p["zoom"]


def _jpeg(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ApiError(500, "could not encode the image")
    return buf.tobytes()


def _aim_at_pixel(rig, rule: str, x: float, y: float) -> tuple[float, float, float] | None:
    """Pan, tilt (rad) and zoom at the head of someone standing on the floor point seen at pixel (x, y)."""
    from omnijax import aim_at_floor, image_to_floor
    from omnijax.zoom import ZOOM_RULES

    X, Y, valid = image_to_floor(rig.omni, x, y)
    if not bool(valid):
        return None
    aimed = aim_at_floor(rig, np.array([float(X), float(Y)]), 0.01 * np.eye(2), ZOOM_RULES)
    if not bool(aimed.pointing.valid):
        return None
    return float(aimed.pointing.pan), float(aimed.pointing.tilt), float(aimed.zooms[rule].zoom)


def _static_text(name: str) -> str:
    return resources.files("runtime.console").joinpath("static", name).read_text()


