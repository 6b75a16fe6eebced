"""Which driver and which transport a ``--ptz`` URL selects: the one place PTZ URLs are dispatched.

- ``visca-udp://HOST[:PORT]`` (port 52381 by default): VISCA over IP
  (:class:`runtime.ptz.visca_ip.ViscaIpPort`) under :class:`~runtime.ptz.driver.PtzDriver`;
- ``onvif://[USER:PASSWORD@]HOST[:PORT]`` (port 80 by default): :class:`runtime.ptz.onvif.OnvifDriver`
  (SOAP over HTTP through ``onvif-zeep-async``);
- anything else: a pyserial URL or device path (``/dev/ttyUSB0``, ``socket://host:port``,
  ``loop://``, a pseudo-terminal from ``omnijax ptz-emulator``) under the same driver.

A new kind of camera adds a row to :data:`SCHEMES` (its driver class, the profile protocol it
needs) and, if it runs in the emulator, a row to :data:`EMULATED`. Every driver answers the
same questions: :class:`Capabilities` (what ``omnijax ptz probe`` reports and ``ptz
calibrate`` relies on), ``set_target``, ``query_position``, ``counters``, ``stats()``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any
from urllib.parse import urlsplit

from .errors import PtzPortError


@dataclass(frozen=True)
class Scheme:
    """One URL scheme: the dotted path of its driver class, and the device-profile protocol it carries."""

    driver: str
    protocol: str | None  # None: whatever the profile says
    port_factory: str | None = None  # a byte-stream transport under PtzDriver (None: pyserial)


#: URL scheme -> driver. Serial URLs (no scheme, or a pyserial one) fall through to :data:`SERIAL`.
SCHEMES: dict[str, Scheme] = {
    "visca-udp": Scheme("runtime.ptz.driver:PtzDriver", "visca", "runtime.ptz.visca_ip:ViscaIpPort"),
    "onvif": Scheme("runtime.ptz.onvif:OnvifDriver", "onvif"),
}
SERIAL = Scheme("runtime.ptz.driver:PtzDriver", None)

#: ``--protocol`` of ``ptz-emulator`` and ``demo`` -> the device-profile protocol of the emulated camera.
#: The emulator prints a pty path, ``udp://HOST:PORT`` or ``http://HOST:PORT/onvif/device_service``; the
#: driver's URL for it is :func:`emulator_url`.
EMULATED: dict[str, str] = {"visca": "visca", "pelco-d": "pelco-d", "visca-ip": "visca", "onvif": "onvif"}
#: The emulated cameras reached over the network (``--listen``), not on a pty.
NETWORK_EMULATED = ("visca-ip", "onvif")


@dataclass(frozen=True)
class Capabilities:
    """What a camera offers, as a driver knows it (static: from the protocol and the profile;
    ``omnijax ptz probe`` checks the live ones against the camera).

    ``move_modes``: of ``absolute``, ``relative``, ``continuous`` (omnijax needs ``absolute``, or
    another with a position estimate); ``move_status``: how the end of a move is known
    (``completion`` replies, ``status`` polling, ``timer`` from the slew rates); ``position``:
    whether the camera reports where it is; ``zoom``: magnification range; ``limits_deg``:
    pan and tilt ranges in the device's degrees; ``transport``: ``serial``, ``udp``, ``http``.
    """

    protocol: str
    transport: str
    move_modes: tuple[str, ...]
    move_status: str
    position: bool
    zoom: tuple[float, float]
    limits_deg: dict[str, tuple[float, float]] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def scheme_of(url: str) -> str:
    """The URL's scheme, lower case (``""`` for a device path)."""
    return urlsplit(url).scheme.lower() if "://" in url else ""


def scheme_for(url: str) -> Scheme:
    return SCHEMES.get(scheme_of(url), SERIAL)


def required_protocol(url: str) -> str | None:
    """The device-profile protocol the URL carries (``visca`` for ``visca-udp://``), or ``None`` (any)."""
    return scheme_for(url).protocol


def _load(dotted: str):
    import importlib

    module, _, name = dotted.partition(":")
    return getattr(importlib.import_module(module), name)


def make_driver(url: str, profile):
    """The driver for ``url`` with device profile ``profile`` (not connected yet).

    :class:`PtzPortError` (one line) if the profile's protocol is not what the URL carries.
    """
    scheme = scheme_for(url)
    if scheme.protocol is not None and profile.protocol != scheme.protocol:
        raise PtzPortError(f"{url}: {scheme_of(url)}:// carries {scheme.protocol}, but the device profile "
                           f"{profile.name!r} is {profile.protocol}")
    return _load(scheme.driver)(url, profile)


def check_port(url: str) -> None:
    """Refuse a malformed byte-stream URL before any thread starts (:class:`PtzPortError`, one line)."""
    scheme = scheme_for(url)
    if scheme.port_factory is not None:
        _load(scheme.port_factory).check_url(url)
        return
    import os

    import serial

    try:
        port = serial.serial_for_url(url, do_not_open=True)
        if "://" in url and hasattr(port, "from_url"):
            port.from_url(url)  # URL handlers parse their host, port and options only when opening
    except (ValueError, TypeError, serial.SerialException) as exc:
        reason = "expected HOST:PORT after the scheme" if isinstance(exc, TypeError) else exc  # pyserial's
        raise PtzPortError(f"{url}: not a usable serial port URL: {reason}") from None
    if "://" not in url and not os.path.exists(url):
        raise PtzPortError(f"{url}: no such serial device")


def open_port(url: str, *, baudrate: int, timeout: float, write_timeout: float, link, counters: dict,
              address: int = 1):
    """Open the byte stream behind ``url``: a pyserial port, or a port-like transport (``read``,
    ``write``, ``in_waiting``, ``reset_input_buffer``, ``close``) that counts its events in ``counters``.
    ``address`` is the camera's (a transport that asks the camera itself, e.g. a keep-alive, uses it).
    Raises ``OSError``/``ValueError``/``serial.SerialException`` when it cannot be opened."""
    scheme = scheme_for(url)
    if scheme.port_factory is not None:
        return _load(scheme.port_factory).open(url, timeout=timeout, link=link, counters=counters, address=address)
    import serial

    return serial.serial_for_url(url, baudrate=baudrate, timeout=timeout, write_timeout=write_timeout)


def transport_of(url: str) -> str:
    scheme = scheme_of(url)
    return {"visca-udp": "udp", "onvif": "http"}.get(scheme, "serial")


def emulator_url(protocol: str, printed: str) -> str:
    """The ``--ptz`` URL for an emulator of ``protocol`` that printed ``printed`` as its address."""
    if protocol == "visca-ip":
        return "visca-udp://" + printed.removeprefix("udp://")
    if protocol == "onvif":
        return "onvif://" + urlsplit(printed).netloc
    return printed
