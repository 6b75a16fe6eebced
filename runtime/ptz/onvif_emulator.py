"""An ONVIF PTZ camera on localhost HTTP: what ``omnijax ptz-emulator --protocol onvif`` serves.

Three layers, each testable alone:

- :class:`OnvifCamera`: the device. The same slew-rate-limited axes as the serial
  emulator's cameras (:class:`runtime.ptz.emulator.Axis`, in the profile's units:
  hundredths of a degree and ten-thousandths of the generic zoom), driven by absolute,
  relative and continuous moves in ONVIF's generic spaces; time is passed in.
- :class:`OnvifService`: SOAP 1.2 bytes in, (HTTP status, bytes) out: parsing
  (:mod:`runtime.ptz.onvif_soap`, hardened), WS-Security when a user is set, dispatch to
  the device (GetCapabilities, GetServices, GetSystemDateAndTime), media (GetProfiles)
  and PTZ (GetConfigurationOptions, GetConfigurations, GetNodes, AbsoluteMove,
  RelativeMove, ContinuousMove, Stop, GetStatus, GotoHomePosition, SetHomePosition)
  operations; anything else is a SOAP fault, never an exception.
- :class:`OnvifEmulator`: a threading ``http.server`` on ``HOST:PORT`` serving the
  three services at ``/onvif/device_service``, ``/onvif/media_service`` and
  ``/onvif/ptz_service``, with the state file of the serial emulator.

``quirks`` imitate firmware faults seen in the field: ``no-move-status`` (GetStatus has
no MoveStatus), ``always-moving`` (MoveStatus stays MOVING), ``relative-only`` and
``continuous-only`` (the other move modes are not offered and answer a fault),
``no-position`` (GetStatus has no Position).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import math
import socket
import threading
import time
from collections import deque
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from lxml import etree

from .emulator import Axis, Faults, _Camera, _Emulator
from .onvif_soap import SPACES, TDS, TPTZ, TRT, TT, SoapError, check_username_token, envelope, fault, parse_request
from .profile import DeviceProfile

QUIRKS = ("no-move-status", "always-moving", "relative-only", "continuous-only", "no-position")
PROFILE_TOKEN = "profile_1"
PTZ_CONFIG_TOKEN = "ptz_config_1"
NODE_TOKEN = "ptz_node_1"
#: How many nonces the camera remembers to refuse replays.
_NONCES_KEPT = 4096
#: The emulator's state-file tick (s).
_TICK_S = 0.02
#: Longest and default ContinuousMove time-out (s).
_MAX_TIMEOUT_S = 60.0
_DEFAULT_TIMEOUT_S = 5.0


def parse_quirks(text: str) -> tuple[str, ...]:
    """``"no-move-status,relative-only"`` -> a tuple; one-line ``ValueError`` for an unknown one."""
    out = tuple(filter(None, (s.strip() for s in text.split(","))))
    for q in out:
        if q not in QUIRKS:
            raise ValueError(f"unknown quirk {q!r}, expected some of {', '.join(QUIRKS)}")
    if "relative-only" in out and "continuous-only" in out:
        raise ValueError("relative-only and continuous-only exclude each other")
    return out


def _duration_s(text: str) -> float:
    """An xs:duration such as ``PT5S`` or ``PT0.5S`` or ``PT1M`` -> seconds (``ValueError`` otherwise)."""
    t = text.strip().upper()
    if not t.startswith("PT") or len(t) > 32:
        raise ValueError(text)
    total, num = 0.0, ""
    for ch in t[2:]:
        if ch.isdigit() or ch == ".":
            num += ch
            continue
        if not num or ch not in "HMS":
            raise ValueError(text)
        total += float(num) * {"H": 3600, "M": 60, "S": 1}[ch]
        num = ""
    if num:
        raise ValueError(text)
    return total


class OnvifCamera(_Camera):
    """The device behind the PTZ service: moves in generic spaces, status, home position."""

    def __init__(self, profile: DeviceProfile, now: float = 0.0, quirks: tuple[str, ...] = ()) -> None:
        super().__init__(profile, profile.address, now)
        self.quirks = quirks
        self.home = (0.0, 0.0, float(profile.zoom.position[0]))
        self._continuous_until: float | None = None

    # -- what it offers ----------------------------------------------------------------

    @property
    def modes(self) -> tuple[str, ...]:
        if "relative-only" in self.quirks:
            return ("relative",)
        if "continuous-only" in self.quirks:
            return ("continuous",)
        return ("absolute", "relative", "continuous")

    def advance(self, now: float) -> None:
        if self._continuous_until is not None and now >= self._continuous_until:
            super().advance(self._continuous_until)
            for axis in (self.pan, self.tilt, self.zoom):
                axis.stop()
            self._continuous_until = None
        super().advance(now)

    # -- moves (x values in the generic spaces; ``None``: that axis is not moved) ------------

    def _limits(self, axis: str) -> tuple[float, float]:
        if axis == "zoom":
            return float(self.profile.zoom.position[0]), float(self.profile.zoom.position[-1])
        return tuple(map(float, self.profile.limits_units(axis)))

    def _rate(self, axis: str, speed: float | None) -> float:
        full = self._zoom_rate() if axis == "zoom" else self.profile.slew_units_s(axis)
        return full * (1.0 if speed is None else speed)

    def _axis(self, name: str) -> Axis:
        return getattr(self, name)

    def absolute(self, now: float, values: dict[str, float], speeds: dict[str, float | None]) -> None:
        self.advance(now)
        self._continuous_until = None
        for name, x in values.items():
            lo, hi = self._limits(name)
            units = min(max(self.profile.from_normalised(name, x), lo), hi)
            self._axis(name).move_to(units, self._rate(name, speeds.get(name)))

    def relative(self, now: float, values: dict[str, float], speeds: dict[str, float | None]) -> None:
        """Move by a translation from where the camera is now (mid-move: from there)."""
        self.advance(now)
        self._continuous_until = None
        for name, dx in values.items():
            lo, hi = self._limits(name)
            axis = self._axis(name)
            units = min(max(axis.position + dx * self.profile.normalised_scale(name), lo), hi)
            axis.move_to(units, self._rate(name, speeds.get(name)))

    def continuous(self, now: float, velocity: dict[str, float], timeout_s: float) -> None:
        """Move at ``velocity`` (generic, [-1, 1], fraction of full speed) until a limit, a Stop or the time-out."""
        self.advance(now)
        for name, v in velocity.items():
            lo, hi = self._limits(name)
            axis = self._axis(name)
            if v == 0:
                axis.stop()
            else:
                axis.move_to(hi if v > 0 else lo, self._rate(name, abs(v)))
        self._continuous_until = now + timeout_s

    def stop(self, now: float, pan_tilt: bool, zoom: bool) -> None:
        self.advance(now)
        for axis in ((self.pan, self.tilt) if pan_tilt else ()) + ((self.zoom,) if zoom else ()):
            axis.stop()
        if pan_tilt and zoom:
            self._continuous_until = None

    def status(self, now: float) -> dict:
        """Generic position (pan, tilt in [-1, 1], zoom in [0, 1]) and move status of each group."""
        self.advance(now)
        p = self.profile
        return {"pan": p.to_normalised("pan", self.pan.position), "tilt": p.to_normalised("tilt", self.tilt.position),
                "zoom": p.to_normalised("zoom", self.zoom.position),
                "pan_tilt_moving": self.pan.moving or self.tilt.moving, "zoom_moving": self.zoom.moving}


def _float(el: etree._Element | None, attr: str, lo: float, hi: float, what: str) -> float | None:
    """Attribute ``attr`` of ``el`` as a finite float in [lo, hi]; ``None`` if the element is absent."""
    if el is None:
        return None
    text = el.get(attr)
    if text is None:
        raise SoapError(f"{what}: attribute {attr} missing", "Sender", "ter:InvalidArgVal")
    try:
        v = float(text)
    except ValueError:
        raise SoapError(f"{what}.{attr}: expected a number, got {text[:40]!r}", "Sender", "ter:InvalidArgVal") from None
    if not math.isfinite(v) or not lo <= v <= hi:
        raise SoapError(f"{what}.{attr}: expected a number in [{lo:g}, {hi:g}], got {text[:40]!r}",
                        "Sender", "ter:InvalidArgVal")
    return v


def _vector(el: etree._Element | None, what: str, pan_tilt: tuple[float, float], zoom: tuple[float, float],
            space_pt: str, space_z: str) -> dict[str, float]:
    """A PTZVector/PTZSpeed element -> {pan, tilt, zoom}: only the groups it holds."""
    if el is None:
        return {}
    out: dict[str, float] = {}
    pt, z = el.find(f"{{{TT}}}PanTilt"), el.find(f"{{{TT}}}Zoom")
    for sub, space in ((pt, space_pt), (z, space_z)):
        if sub is not None and sub.get("space") not in (None, space):
            raise SoapError(f"{what}: space {sub.get('space')[:120]!r} not supported, expected {space}",
                            "Sender", "ter:InvalidArgVal")
    if pt is not None:
        out["pan"] = _float(pt, "x", *pan_tilt, f"{what}.PanTilt")
        out["tilt"] = _float(pt, "y", *pan_tilt, f"{what}.PanTilt")
    if z is not None:
        out["zoom"] = _float(z, "x", *zoom, f"{what}.Zoom")
    return out


def _speeds(el: etree._Element | None) -> dict[str, float | None]:
    s = _vector(el, "Speed", (0.0, 1.0), (0.0, 1.0), SPACES["pan_tilt_speed"], SPACES["zoom_speed"])
    # a zero speed means "the default" in practice; ours is full speed
    return {k: (v if v else None) for k, v in s.items()}


def _range(lo: float, hi: float) -> str:
    return f"<tt:Min>{lo:g}</tt:Min><tt:Max>{hi:g}</tt:Max>"


class OnvifService:
    """SOAP requests to an :class:`OnvifCamera`; thread-safe; every request gets a reply, never an exception.

    ``base_url`` is what GetServices and GetCapabilities advertise (``http://HOST:PORT``);
    ``user``/``password``: WS-Security UsernameToken required on every operation but
    GetSystemDateAndTime when a user is set; ``lock`` (the emulator's) guards the camera.
    Counters: ``requests``, ``faults``, ``unauthorised``, ``malformed``.
    """

    def __init__(self, camera: OnvifCamera, base_url: str, user: str | None = None, password: str | None = None,
                 clock=time.monotonic, wall_clock=lambda: dt.datetime.now(dt.UTC),
                 lock: threading.Lock | None = None) -> None:
        self.camera, self.base_url = camera, base_url.rstrip("/")
        self.user, self.password = user, password or ""
        self.clock, self.wall_clock = clock, wall_clock
        self.lock = lock or threading.Lock()
        self._nonces: set[bytes] = set()
        self._nonce_order: deque[bytes] = deque()
        self.counts = dict.fromkeys(("requests", "faults", "unauthorised", "malformed"), 0)
        self._ops = {
            (TDS, "GetCapabilities"): self._get_capabilities, (TDS, "GetServices"): self._get_services,
            (TDS, "GetSystemDateAndTime"): self._get_date_time,
            (TRT, "GetProfiles"): self._get_profiles,
            (TPTZ, "GetConfigurationOptions"): self._get_configuration_options,
            (TPTZ, "GetConfigurations"): self._get_configurations, (TPTZ, "GetNodes"): self._get_nodes,
            (TPTZ, "AbsoluteMove"): self._absolute_move, (TPTZ, "RelativeMove"): self._relative_move,
            (TPTZ, "ContinuousMove"): self._continuous_move, (TPTZ, "Stop"): self._stop,
            (TPTZ, "GetStatus"): self._get_status, (TPTZ, "GotoHomePosition"): self._goto_home,
            (TPTZ, "SetHomePosition"): self._set_home,
        }

    def handle(self, data: bytes) -> tuple[int, bytes]:
        """One request body -> (HTTP status, SOAP reply). Faults: 400 for the sender's, 500 for ours."""
        with self.lock:
            self.counts["requests"] += 1
            try:
                req = parse_request(data)
                op = self._ops.get((req.namespace, req.operation))
                if op is None:
                    raise SoapError(f"operation {req.operation[:80]!r} in {req.namespace[:120]!r} is not supported",
                                    "Receiver", "ter:ActionNotSupported")
                if self.user is not None and req.operation != "GetSystemDateAndTime":
                    check_username_token(req.header, self.user, self.password, self.wall_clock(), self._nonces)
                    self._forget_old_nonces()
                return 200, envelope(op(req.body))
            except SoapError as exc:
                self.counts["faults"] += 1
                if exc.subcode == "ter:NotAuthorized":
                    self.counts["unauthorised"] += 1
                elif exc.subcode != "ter:ActionNotSupported":
                    self.counts["malformed"] += 1
                self.camera.errors += 1
                return (400 if exc.code in ("Sender", "VersionMismatch") else 500), fault(exc.code, exc.subcode,
                                                                                            str(exc))

    def _forget_old_nonces(self) -> None:
        for n in self._nonces.difference(self._nonce_order):
            self._nonce_order.append(n)
        while len(self._nonce_order) > _NONCES_KEPT:
            self._nonces.discard(self._nonce_order.popleft())

    # -- device --------------------------------------------------------------------------

    def _get_capabilities(self, body) -> str:
        b = self.base_url
        return (f"<tds:GetCapabilitiesResponse><tds:Capabilities>"
                f"<tt:Device><tt:XAddr>{b}/onvif/device_service</tt:XAddr></tt:Device>"
                f"<tt:Media><tt:XAddr>{b}/onvif/media_service</tt:XAddr><tt:StreamingCapabilities>"
                f"<tt:RTPMulticast>false</tt:RTPMulticast><tt:RTP_TCP>true</tt:RTP_TCP>"
                f"<tt:RTP_RTSP_TCP>true</tt:RTP_RTSP_TCP></tt:StreamingCapabilities></tt:Media>"
                f"<tt:PTZ><tt:XAddr>{b}/onvif/ptz_service</tt:XAddr></tt:PTZ>"
                f"</tds:Capabilities></tds:GetCapabilitiesResponse>")

    def _get_services(self, body) -> str:
        b = self.base_url
        services = ((TDS, "device_service", 2), (TRT, "media_service", 2), (TPTZ, "ptz_service", 2))
        return ("<tds:GetServicesResponse>" + "".join(
            f"<tds:Service><tds:Namespace>{ns}</tds:Namespace><tds:XAddr>{b}/onvif/{path}</tds:XAddr>"
            f"<tds:Version><tt:Major>{major}</tt:Major><tt:Minor>0</tt:Minor></tds:Version></tds:Service>"
            for ns, path, major in services) + "</tds:GetServicesResponse>")

    def _get_date_time(self, body) -> str:
        t = self.wall_clock()
        return (f"<tds:GetSystemDateAndTimeResponse><tds:SystemDateAndTime><tt:DateTimeType>Manual</tt:DateTimeType>"
                f"<tt:DaylightSavings>false</tt:DaylightSavings><tt:UTCDateTime>"
                f"<tt:Time><tt:Hour>{t.hour}</tt:Hour><tt:Minute>{t.minute}</tt:Minute>"
                f"<tt:Second>{t.second}</tt:Second></tt:Time>"
                f"<tt:Date><tt:Year>{t.year}</tt:Year><tt:Month>{t.month}</tt:Month><tt:Day>{t.day}</tt:Day></tt:Date>"
                f"</tt:UTCDateTime></tds:SystemDateAndTime></tds:GetSystemDateAndTimeResponse>")

    # -- media ---------------------------------------------------------------------------

    def _ptz_configuration(self, tag: str) -> str:
        modes = self.camera.modes
        defaults = ""
        if "absolute" in modes:
            defaults += (f"<tt:DefaultAbsolutePantTiltPositionSpace>{SPACES['pan_tilt_position']}"
                         f"</tt:DefaultAbsolutePantTiltPositionSpace><tt:DefaultAbsoluteZoomPositionSpace>"
                         f"{SPACES['zoom_position']}</tt:DefaultAbsoluteZoomPositionSpace>")
        if "relative" in modes:
            defaults += (f"<tt:DefaultRelativePanTiltTranslationSpace>{SPACES['pan_tilt_translation']}"
                         f"</tt:DefaultRelativePanTiltTranslationSpace><tt:DefaultRelativeZoomTranslationSpace>"
                         f"{SPACES['zoom_translation']}</tt:DefaultRelativeZoomTranslationSpace>")
        if "continuous" in modes:
            defaults += (f"<tt:DefaultContinuousPanTiltVelocitySpace>{SPACES['pan_tilt_velocity']}"
                         f"</tt:DefaultContinuousPanTiltVelocitySpace><tt:DefaultContinuousZoomVelocitySpace>"
                         f"{SPACES['zoom_velocity']}</tt:DefaultContinuousZoomVelocitySpace>")
        return (f'<{tag} token="{PTZ_CONFIG_TOKEN}"><tt:Name>PTZ</tt:Name><tt:UseCount>1</tt:UseCount>'
                f"<tt:NodeToken>{NODE_TOKEN}</tt:NodeToken>{defaults}"
                f'<tt:DefaultPTZSpeed><tt:PanTilt x="1" y="1" space="{SPACES["pan_tilt_speed"]}"/>'
                f'<tt:Zoom x="1" space="{SPACES["zoom_speed"]}"/></tt:DefaultPTZSpeed>'
                f"<tt:DefaultPTZTimeout>PT{_DEFAULT_TIMEOUT_S:g}S</tt:DefaultPTZTimeout>"
                f"<tt:PanTiltLimits><tt:Range><tt:URI>{SPACES['pan_tilt_position']}</tt:URI>"
                f"<tt:XRange>{_range(-1, 1)}</tt:XRange><tt:YRange>{_range(-1, 1)}</tt:YRange></tt:Range>"
                f"</tt:PanTiltLimits><tt:ZoomLimits><tt:Range><tt:URI>{SPACES['zoom_position']}</tt:URI>"
                f"<tt:XRange>{_range(0, 1)}</tt:XRange></tt:Range></tt:ZoomLimits></{tag}>")

    def _get_profiles(self, body) -> str:
        return (f'<trt:GetProfilesResponse><trt:Profiles token="{PROFILE_TOKEN}" fixed="true">'
                f"<tt:Name>mainStream</tt:Name>{self._ptz_configuration('tt:PTZConfiguration')}"
                f"</trt:Profiles></trt:GetProfilesResponse>")

    # -- PTZ -----------------------------------------------------------------------------

    def _token(self, body, name: str = "ProfileToken", expected: str = PROFILE_TOKEN) -> None:
        token = body.findtext(f"{{{TPTZ}}}{name}")
        if token is None:
            raise SoapError(f"{name} missing", "Sender", "ter:InvalidArgVal")
        if token.strip() != expected:
            raise SoapError(f"no profile or configuration {token.strip()[:80]!r}", "Sender",
                            "ter:NoProfile" if name == "ProfileToken" else "ter:NoEntity")

    def _get_configuration_options(self, body) -> str:
        self._token(body, "ConfigurationToken", PTZ_CONFIG_TOKEN)
        modes = self.camera.modes
        spaces = ""

        def space(tag: str, uri: str, x: tuple[float, float], y: tuple[float, float] | None = None) -> str:
            yr = f"<tt:YRange>{_range(*y)}</tt:YRange>" if y else ""
            return f"<tt:{tag}><tt:URI>{uri}</tt:URI><tt:XRange>{_range(*x)}</tt:XRange>{yr}</tt:{tag}>"

        if "absolute" in modes:
            spaces += space("AbsolutePanTiltPositionSpace", SPACES["pan_tilt_position"], (-1, 1), (-1, 1))
            spaces += space("AbsoluteZoomPositionSpace", SPACES["zoom_position"], (0, 1))
        if "relative" in modes:
            spaces += space("RelativePanTiltTranslationSpace", SPACES["pan_tilt_translation"], (-1, 1), (-1, 1))
            spaces += space("RelativeZoomTranslationSpace", SPACES["zoom_translation"], (-1, 1))
        if "continuous" in modes:
            spaces += space("ContinuousPanTiltVelocitySpace", SPACES["pan_tilt_velocity"], (-1, 1), (-1, 1))
            spaces += space("ContinuousZoomVelocitySpace", SPACES["zoom_velocity"], (-1, 1))
        spaces += f"<tt:PanTiltSpeedSpace><tt:URI>{SPACES['pan_tilt_speed']}</tt:URI>" \
                  f"<tt:XRange>{_range(0, 1)}</tt:XRange></tt:PanTiltSpeedSpace>"
        spaces += f"<tt:ZoomSpeedSpace><tt:URI>{SPACES['zoom_speed']}</tt:URI>" \
                  f"<tt:XRange>{_range(0, 1)}</tt:XRange></tt:ZoomSpeedSpace>"
        return (f"<tptz:GetConfigurationOptionsResponse><tptz:PTZConfigurationOptions><tt:Spaces>{spaces}</tt:Spaces>"
                f"<tt:PTZTimeout><tt:Min>PT0S</tt:Min><tt:Max>PT{_MAX_TIMEOUT_S:g}S</tt:Max></tt:PTZTimeout>"
                f"</tptz:PTZConfigurationOptions></tptz:GetConfigurationOptionsResponse>")

    def _get_configurations(self, body) -> str:
        return (f"<tptz:GetConfigurationsResponse>{self._ptz_configuration('tptz:PTZConfiguration')}"
                f"</tptz:GetConfigurationsResponse>")

    def _get_nodes(self, body) -> str:
        return (f'<tptz:GetNodesResponse><tptz:PTZNode token="{NODE_TOKEN}" FixedHomePosition="false">'
                f"<tt:Name>PTZ</tt:Name><tt:SupportedPTZSpaces/><tt:MaximumNumberOfPresets>0"
                f"</tt:MaximumNumberOfPresets><tt:HomeSupported>true</tt:HomeSupported>"
                f"</tptz:PTZNode></tptz:GetNodesResponse>")

    def _require(self, mode: str, operation: str) -> None:
        if mode not in self.camera.modes:
            raise SoapError(f"{operation} is not supported by this camera", "Receiver", "ter:ActionNotSupported")

    def _absolute_move(self, body) -> str:
        self._require("absolute", "AbsoluteMove")
        self._token(body)
        pos = _vector(body.find(f"{{{TPTZ}}}Position"), "Position", (-1, 1), (0, 1),
                      SPACES["pan_tilt_position"], SPACES["zoom_position"])
        if not pos:
            raise SoapError("Position missing or empty", "Sender", "ter:InvalidArgVal")
        self.camera.absolute(self.clock(), pos, _speeds(body.find(f"{{{TPTZ}}}Speed")))
        return "<tptz:AbsoluteMoveResponse/>"

    def _relative_move(self, body) -> str:
        self._require("relative", "RelativeMove")
        self._token(body)
        tr = _vector(body.find(f"{{{TPTZ}}}Translation"), "Translation", (-2, 2), (-1, 1),
                     SPACES["pan_tilt_translation"], SPACES["zoom_translation"])
        if not tr:
            raise SoapError("Translation missing or empty", "Sender", "ter:InvalidArgVal")
        self.camera.relative(self.clock(), tr, _speeds(body.find(f"{{{TPTZ}}}Speed")))
        return "<tptz:RelativeMoveResponse/>"

    def _continuous_move(self, body) -> str:
        self._require("continuous", "ContinuousMove")
        self._token(body)
        vel = _vector(body.find(f"{{{TPTZ}}}Velocity"), "Velocity", (-1, 1), (-1, 1),
                      SPACES["pan_tilt_velocity"], SPACES["zoom_velocity"])
        if not vel:
            raise SoapError("Velocity missing or empty", "Sender", "ter:InvalidArgVal")
        timeout = _DEFAULT_TIMEOUT_S
        text = body.findtext(f"{{{TPTZ}}}Timeout")
        if text is not None:
            try:
                timeout = _duration_s(text)
            except ValueError:
                raise SoapError(f"Timeout: expected a duration such as PT5S, got {text[:40]!r}", "Sender",
                                "ter:InvalidArgVal") from None
            if timeout > _MAX_TIMEOUT_S:
                raise SoapError(f"Timeout: at most PT{_MAX_TIMEOUT_S:g}S", "Sender", "ter:TimeoutNotSupported")
        self.camera.continuous(self.clock(), vel, timeout)
        return "<tptz:ContinuousMoveResponse/>"

    def _stop(self, body) -> str:
        self._token(body)

        def flag(name: str) -> bool:
            text = body.findtext(f"{{{TPTZ}}}{name}")
            if text is None:
                return True
            if text.strip() not in ("true", "false", "1", "0"):
                raise SoapError(f"{name}: expected true or false, got {text[:20]!r}", "Sender", "ter:InvalidArgVal")
            return text.strip() in ("true", "1")

        self.camera.stop(self.clock(), flag("PanTilt"), flag("Zoom"))
        return "<tptz:StopResponse/>"

    def _get_status(self, body) -> str:
        self._token(body)
        s = self.camera.status(self.clock())
        q = self.camera.quirks
        out = "<tptz:GetStatusResponse><tptz:PTZStatus>"
        if "no-position" not in q:
            out += (f'<tt:Position><tt:PanTilt x="{s["pan"]:.6f}" y="{s["tilt"]:.6f}" '
                    f'space="{SPACES["pan_tilt_position"]}"/>'
                    f'<tt:Zoom x="{s["zoom"]:.6f}" space="{SPACES["zoom_position"]}"/></tt:Position>')
        if "no-move-status" not in q:
            always = "always-moving" in q

            def word(moving: bool) -> str:
                return "MOVING" if moving or always else "IDLE"

            out += (f"<tt:MoveStatus><tt:PanTilt>{word(s['pan_tilt_moving'])}</tt:PanTilt>"
                    f"<tt:Zoom>{word(s['zoom_moving'])}</tt:Zoom></tt:MoveStatus>")
        t = self.wall_clock().strftime("%Y-%m-%dT%H:%M:%SZ")
        return out + f"<tt:UtcTime>{t}</tt:UtcTime></tptz:PTZStatus></tptz:GetStatusResponse>"

    def _goto_home(self, body) -> str:
        self._token(body)
        cam = self.camera
        pan, tilt, zoom = cam.home
        p = cam.profile
        home = {"pan": p.to_normalised("pan", pan), "tilt": p.to_normalised("tilt", tilt),
                "zoom": p.to_normalised("zoom", zoom)}
        # home works whichever move modes the camera offers to clients
        cam.absolute(self.clock(), home, _speeds(body.find(f"{{{TPTZ}}}Speed")))
        return "<tptz:GotoHomePositionResponse/>"

    def _set_home(self, body) -> str:
        self._token(body)
        cam = self.camera
        cam.advance(self.clock())
        cam.home = (cam.pan.position, cam.tilt.position, cam.zoom.position)
        return "<tptz:SetHomePositionResponse/>"


class _Handler(BaseHTTPRequestHandler):
    server_version = "omnijax-onvif-emulator"
    protocol_version = "HTTP/1.1"
    timeout = 5.0  # a client that stalls mid-request loses its connection, not the server

    def setup(self) -> None:
        super().setup()
        with self.server.lock:
            self.server.connections.add(self.connection)

    def finish(self) -> None:
        try:
            super().finish()
        finally:
            with self.server.lock:
                self.server.connections.discard(self.connection)

    def do_POST(self) -> None:
        emulator: OnvifEmulator = self.server.emulator
        if self.path.split("?")[0] not in ("/onvif/device_service", "/onvif/media_service", "/onvif/ptz_service"):
            self._reply(404, b"not found\n", "text/plain")
            return
        try:
            length = int(self.headers.get("Content-Length", ""))
        except ValueError:
            self._reply(411, b"Content-Length required\n", "text/plain")
            return
        if not 0 <= length <= 4 * 1024 * 1024:
            self._reply(413, b"request too large\n", "text/plain")
            self.close_connection = True
            return
        data = self.rfile.read(length)
        if emulator.latency_s:
            time.sleep(emulator.latency_s)
        status, body = emulator.service.handle(data)
        self._reply(status, body, "application/soap+xml; charset=utf-8")

    def do_GET(self) -> None:
        self._reply(405, b"ONVIF services take SOAP over POST\n", "text/plain")

    def _reply(self, status: int, body: bytes, content_type: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format, *args) -> None:  # quiet: the counters say what happened
        return


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True
    request_queue_size = 64

    def __init__(self, *args, **kwargs) -> None:
        self.lock = threading.Lock()
        self.connections: set[socket.socket] = set()
        super().__init__(*args, **kwargs)

    def drop_connections(self) -> None:
        """Close every open (keep-alive) connection: a camera that goes away answers nobody."""
        with self.lock:
            conns = list(self.connections)
        for conn in conns:
            with contextlib.suppress(OSError):
                conn.shutdown(socket.SHUT_RDWR)

    def handle_error(self, request, client_address) -> None:
        # a client that vanished mid-reply (reset, broken pipe) is not the emulator's problem; count it
        self.emulator.dropped_connections += 1


class OnvifEmulator(_Emulator):
    """An :class:`OnvifCamera` served over HTTP on ``host:port`` (port 0: one the system picks).

    ``url`` is the device service address to print; ``state_file`` as the serial emulator's
    (pan_deg, tilt_deg, zoom, commands, errors, and ``onvif``: the service's counters);
    ``latency_s`` delays every request before the camera sees it (a camera's command latency).
    :meth:`serve` in the calling thread until :meth:`stop`, or :meth:`start`/:meth:`close`
    (a context manager) in a thread.
    """

    def __init__(self, profile: DeviceProfile, host: str = "127.0.0.1", port: int = 0, *,
                 user: str | None = None, password: str | None = None, quirks: tuple[str, ...] = (),
                 state_file: str | Path | None = None, latency_s: float = 0.0) -> None:
        self._quirks = quirks
        super().__init__(profile, None, state_file=state_file, faults=Faults(), seed=0, latency_s=latency_s)
        self._server = _Server((host, port), _Handler)
        self._server.emulator = self
        h, p = self._server.server_address[:2]
        self.address = (h, p)
        self.url = f"http://{h}:{p}/onvif/device_service"
        self.service = OnvifService(self.camera, f"http://{h}:{p}", user, password, lock=self._lock)
        self.dropped_connections = 0

    def _make_camera(self, profile: DeviceProfile, address: int | None, now: float) -> OnvifCamera:
        return OnvifCamera(profile, now, self._quirks)

    def state(self) -> dict:
        with self._lock:
            self.camera.advance(time.monotonic())
            out = self.camera.state()
            out["commands"] = self.service.counts["requests"]
            out["onvif"] = dict(self.service.counts, quirks=list(self.camera.quirks))
            return out

    def serve(self) -> None:
        """Serve until :meth:`stop` (safe from a signal handler)."""
        http = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05},
                                name="onvif-http", daemon=True)
        http.start()
        try:
            self._write_state(force=True)
            while not self._stop.wait(_TICK_S):
                self._write_state()
        finally:
            self._server.shutdown()
            http.join()
            self._server.server_close()
            self._server.drop_connections()
            self._write_state(force=True)

    def close(self) -> None:
        """Stop serving: the port closes and open connections are dropped (the camera vanishes)."""
        if self._thread is not None:
            self._join()
        else:
            self.stop()
            with contextlib.suppress(OSError):
                self._server.server_close()
