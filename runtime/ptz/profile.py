"""PTZ device profiles: what a camera model accepts, and how it is mounted (``configs/devices/*.toml``).

A profile holds the protocol and line settings, the pan/tilt ranges in the
device's own degrees and its units per degree, the speeds, the zoom lens's
position for each magnification, the link's timing, and the *mounting*: how
omnijax's pan/tilt (geometry frame: pan measured at the PTZ from the direction
of the omni camera's axis, tilt up positive, radians; docs/design.md section 4.2) map to
the device's angles. :meth:`DeviceProfile.to_device` and
:meth:`DeviceProfile.from_device` are the only places where angles and zoom
factors become device units and back; every target is clamped to the limits.

Profiles are validated by a strict pydantic schema (unknown keys are errors);
every failure is a one-line :class:`ProfileError` naming the file and key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, get_args

import numpy as np
from annotated_types import Len
from pydantic import Field, model_validator

from omnijax.config import Degrees, Section, validate, within

#: Where the shipped profiles live (``configs/devices`` of the checkout).
DEVICES_DIR = Path(__file__).resolve().parents[2] / "configs" / "devices"
#: The protocols a profile can name (``--protocol``).
Protocol = Literal["visca", "pelco-d", "onvif"]
PROTOCOLS: tuple[str, ...] = get_args(Protocol)
#: The profile each protocol uses when none is given.
DEFAULT_PROFILES = {"visca": "sony_evi_d70", "pelco-d": "pelco_d_dome", "onvif": "onvif_ptz"}
#: Largest magnitude of a VISCA pan/tilt position (signed 16-bit nibbles) and of any zoom position.
_VISCA_MAX_ANGLE_UNITS = 0x7FFF
_MAX_ZOOM_POSITION = 0xFFFF
_PELCO_UNITS_PER_DEG = 100.0
#: ONVIF profiles count pan and tilt in hundredths of a degree, and the zoom in ten-thousandths of
#: the generic zoom space [0, 1] (so the emulator's slew model works in integers as for the others).
_ONVIF_UNITS_PER_DEG = 100.0
ONVIF_ZOOM_UNITS = 10_000


class ProfileError(ValueError):
    """A device profile that cannot be used (one line: file, key, what was expected)."""


Range = Annotated[list[Degrees], Len(2, 2)]
Direction = Literal[-1, 1]
#: Times of the link and the lens (s): longer than any camera takes.
Seconds = Annotated[float, within(0.0, 3600.0, "seconds", open_low=True, why="an hour")]


class AxisSection(Section):
    """One rotation axis in the device's own degrees."""

    limits_deg: Range = Field(description="lowest and highest reachable angle, device degrees")
    units_per_deg: Annotated[float, within(0.0, 1e4, "units per degree", open_low=True)] = Field(
        description="device position units per degree")
    speed: int = Field(0, ge=0, description="VISCA speed code sent with absolute moves (unused by Pelco-D)")
    max_speed: int = Field(0, ge=0, description="VISCA: highest speed code the device accepts")
    max_speed_deg_s: Annotated[float, within(0.0, 1e4, "degrees per second", open_low=True,
                                             why="no PTZ turns faster")] = Field(
        description="slew rate at the highest speed code, deg/s")

    @model_validator(mode="after")
    def _check(self):
        lo, hi = self.limits_deg
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"expected [low, high] with low < high, got {self.limits_deg}")
        if hi - lo > 360:
            raise ValueError(f"range spans {hi - lo} deg, at most 360")
        if self.speed > self.max_speed:
            raise ValueError(f"speed {self.speed} is above max_speed {self.max_speed}")
        return self

    def slew_deg_s(self, speed: int | None = None) -> float:
        """Slew rate (deg/s) at VISCA speed code ``speed`` (linear in the code), or the fastest."""
        if speed is None or self.max_speed == 0:
            return self.max_speed_deg_s
        return self.max_speed_deg_s * speed / self.max_speed

    def move_deg_s(self) -> float:
        """Slew rate (deg/s) of the moves omnijax commands: at ``speed``, the code every absolute move carries
        (VISCA), or the top speed where the protocol sends none (``speed`` 0). The one figure the driver's
        moves and the loop's arrival prediction share."""
        return self.slew_deg_s(self.speed or None)


class ZoomSection(Section):
    """The lens: device zoom position at each magnification (interpolated linearly between rows)."""

    magnification: Annotated[list[Annotated[float, Field(ge=1)]], Len(2)]
    position: Annotated[list[Annotated[int, Field(ge=0, le=_MAX_ZOOM_POSITION)]], Len(2)]
    seconds_full_range: Seconds = Field(description="time to drive from wide to tele, s")

    @model_validator(mode="after")
    def _check(self):
        if len(self.magnification) != len(self.position):
            raise ValueError(f"magnification has {len(self.magnification)} rows, position {len(self.position)}")
        if any(b <= a for a, b in zip(self.magnification, self.magnification[1:])):
            raise ValueError("magnification must increase strictly")
        if any(b <= a for a, b in zip(self.position, self.position[1:])):
            raise ValueError("position must increase strictly")
        return self


class MountingSection(Section):
    """How the geometry's pan/tilt map to the device's: ``device = direction * geometry + zero``."""

    pan_zero_deg: Degrees = Field(0.0, description="device pan when the PTZ looks toward the omni camera's axis")
    pan_direction: Direction = Field(1, description="+1: device pan grows with omnijax pan; -1: opposite")
    tilt_zero_deg: Degrees = Field(0.0, description="device tilt when the PTZ looks level")
    tilt_direction: Direction = Field(1, description="+1: device tilt grows upward; -1: downward")


class LinkSection(Section):
    """Timing of the serial link (seconds)."""

    ack_timeout_s: Seconds = 0.5
    completion_timeout_s: Seconds = 10.0
    min_interval_s: Annotated[float, Field(ge=0, le=3600)] = 0.05
    retry_delay_s: Seconds = 0.05
    reconnect_backoff_s: Annotated[list[Seconds], Len(2, 2)] = [0.05, 0.5]
    max_silent: Annotated[int, Field(ge=1)] = 3
    command_latency_s: Annotated[float, Field(ge=0, le=60)] = Field(
        0.0, description="from a command's bytes on the wire to the motion starting (omnijax ptz calibrate)")

    @model_validator(mode="after")
    def _check(self):
        if self.reconnect_backoff_s[0] > self.reconnect_backoff_s[1]:
            raise ValueError(f"reconnect_backoff_s: expected [first, longest], got {self.reconnect_backoff_s}")
        return self


class PelcoDSection(Section):
    """Pelco-D options."""

    general_response: bool = Field(True, description="the device answers each command with a general response")


@dataclass(frozen=True)
class DeviceTarget:
    """A target in device units (what goes on the wire) and which axes had to be clamped."""

    pan: int
    tilt: int
    zoom: int
    clamped: tuple[str, ...] = ()


@dataclass(frozen=True)
class PtzPosition:
    """A pan/tilt/zoom in omnijax's frame: radians (pan from the omni axis, tilt up) and a zoom factor.

    ``units`` are the device's (pan, tilt, zoom) it was converted from, where it was.
    """

    pan: float
    tilt: float
    zoom: float
    units: tuple[int, int, int] | None = None

    @property
    def pan_deg(self) -> float:
        return math.degrees(self.pan)

    @property
    def tilt_deg(self) -> float:
        return math.degrees(self.tilt)


class DeviceProfile(Section):
    """A validated device profile; see ``configs/devices/sony_evi_d70.toml`` for every key."""

    name: str
    protocol: Protocol
    address: Annotated[int, Field(ge=1, le=255)]
    baudrate: Annotated[int, Field(gt=0)] = 9600
    pan: AxisSection
    tilt: AxisSection
    zoom: ZoomSection
    mounting: MountingSection = MountingSection()
    link: LinkSection = LinkSection()
    pelco_d: PelcoDSection = PelcoDSection()

    @model_validator(mode="after")
    def _protocol_ranges(self):
        if self.protocol == "visca":
            if self.address > 7:
                raise ValueError(f"address: VISCA cameras are 1-7, got {self.address}")
            for axis in ("pan", "tilt"):
                sec = getattr(self, axis)
                if not 1 <= sec.speed <= sec.max_speed <= 0x7F:
                    raise ValueError(f"{axis}.speed, {axis}.max_speed: VISCA needs 1 <= speed <= max_speed "
                                     f"<= 127, got {sec.speed}, {sec.max_speed}")
                if max(abs(v) for v in sec.limits_deg) * sec.units_per_deg > _VISCA_MAX_ANGLE_UNITS:
                    raise ValueError(f"{axis}.limits_deg: beyond VISCA's signed 16-bit position")
        elif self.protocol == "onvif":
            for axis in ("pan", "tilt"):
                if getattr(self, axis).units_per_deg != _ONVIF_UNITS_PER_DEG:
                    raise ValueError(f"{axis}.units_per_deg: ONVIF profiles count hundredths of a degree, "
                                     f"expected 100, got {getattr(self, axis).units_per_deg}")
            if self.zoom.position[-1] > ONVIF_ZOOM_UNITS:
                raise ValueError(f"zoom.position: ONVIF positions are the generic zoom space [0, 1] times "
                                 f"{ONVIF_ZOOM_UNITS}, got {self.zoom.position[-1]}")
        else:
            for axis in ("pan", "tilt"):
                if getattr(self, axis).units_per_deg != _PELCO_UNITS_PER_DEG:
                    raise ValueError(f"{axis}.units_per_deg: Pelco-D positions are hundredths of a degree, "
                                     f"expected 100, got {getattr(self, axis).units_per_deg}")
        return self

    # ------------------------------------------------------------------------------------
    # The conversions (the only place angles and zoom factors become device units)
    # ------------------------------------------------------------------------------------

    @property
    def pan_continuous(self) -> bool:
        """Whether pan turns all the way round (its range spans 360 deg)."""
        lo, hi = self.pan.limits_deg
        return hi - lo >= 360

    def device_pan_deg(self, pan: float) -> float:
        """Device pan (deg, unclamped) for omnijax pan ``pan`` (rad): taken modulo 360 into the
        360-degree window centred on the device's range."""
        m = self.mounting
        deg = m.pan_direction * math.degrees(pan) + m.pan_zero_deg
        centre = 0.5 * sum(self.pan.limits_deg)
        return centre + (deg - centre + 180.0) % 360.0 - 180.0

    def device_tilt_deg(self, tilt: float) -> float:
        """Device tilt (deg, unclamped) for omnijax tilt ``tilt`` (rad)."""
        m = self.mounting
        return m.tilt_direction * math.degrees(tilt) + m.tilt_zero_deg

    def zoom_position(self, zoom: float) -> float:
        """Device zoom position for magnification ``zoom`` (unclamped within the table's ends)."""
        return float(np.interp(zoom, self.zoom.magnification, self.zoom.position))

    def to_device(self, pan: float, tilt: float, zoom: float) -> DeviceTarget:
        """omnijax pan, tilt (rad) and zoom factor -> device units, clamped to the device's limits.

        ``clamped`` names the axes that were outside the limits (and moved onto them).
        """
        if not all(math.isfinite(v) for v in (pan, tilt, zoom)):
            raise ValueError(f"PTZ target must be finite, got pan={pan}, tilt={tilt}, zoom={zoom}")
        clamped = []
        pan_deg = self.device_pan_deg(pan)
        tilt_deg = self.device_tilt_deg(tilt)
        values = {}
        for axis, deg in (("pan", pan_deg), ("tilt", tilt_deg)):
            lo, hi = getattr(self, axis).limits_deg
            if not lo <= deg <= hi:
                clamped.append(axis)
            values[axis] = round(min(max(deg, lo), hi) * getattr(self, axis).units_per_deg)
        z_lo, z_hi = self.zoom.magnification[0], self.zoom.magnification[-1]
        if not z_lo <= zoom <= z_hi:
            clamped.append("zoom")
        return DeviceTarget(values["pan"], values["tilt"], round(self.zoom_position(zoom)), tuple(clamped))

    def from_device(self, pan: int, tilt: int, zoom: int) -> PtzPosition:
        """Device units -> omnijax pan (rad, in (-pi, pi]), tilt (rad) and zoom factor."""
        m = self.mounting
        pan_deg = (pan / self.pan.units_per_deg - m.pan_zero_deg) * m.pan_direction
        pan_deg = -((180.0 - pan_deg) % 360.0) + 180.0
        tilt_deg = (tilt / self.tilt.units_per_deg - m.tilt_zero_deg) * m.tilt_direction + 0.0  # no -0.0
        mag = float(np.interp(zoom, self.zoom.position, self.zoom.magnification))
        return PtzPosition(math.radians(pan_deg), math.radians(tilt_deg), mag, (pan, tilt, zoom))

    def units_apart(self, axis: Literal["pan", "tilt", "zoom"], a: int, b: int) -> int:
        """How far apart two device positions of ``axis`` are, in units (pan the short way round
        when it turns fully)."""
        d = abs(a - b)
        if axis == "pan" and self.pan_continuous:
            turn = round(360 * self.pan.units_per_deg)
            d %= turn
            d = min(d, turn - d)
        return d

    def limits_units(self, axis: Literal["pan", "tilt"]) -> tuple[int, int]:
        """The device's range of ``axis`` in its units."""
        sec = getattr(self, axis)
        return round(sec.limits_deg[0] * sec.units_per_deg), round(sec.limits_deg[1] * sec.units_per_deg)

    def at_limit(self, axis: Literal["pan", "tilt"], units: float) -> float | None:
        """The limit (device deg) that a position of ``axis`` (device units) stands at, within a unit: where a
        device stops when sent beyond its range; ``None`` inside it (and for a pan that turns all the way)."""
        if axis == "pan" and self.pan_continuous:
            return None
        sec = getattr(self, axis)
        return next((lim for lim in sec.limits_deg if abs(units - lim * sec.units_per_deg) <= 1.0), None)

    # ONVIF's generic spaces: pan and tilt x in [-1, 1] span the device's range linearly, zoom x in [0, 1]
    # spans the lens (ONVIF_ZOOM_UNITS units). Relative moves use the same scale (a full sweep is 2).

    def to_normalised(self, axis: Literal["pan", "tilt", "zoom"], units: float) -> float:
        """Device units of ``axis`` -> ONVIF generic position space (pan/tilt [-1, 1], zoom [0, 1])."""
        if axis == "zoom":
            return units / ONVIF_ZOOM_UNITS
        sec = getattr(self, axis)
        lo, hi = sec.limits_deg
        return (units / sec.units_per_deg - 0.5 * (lo + hi)) / (0.5 * (hi - lo))

    def from_normalised(self, axis: Literal["pan", "tilt", "zoom"], x: float) -> float:
        """ONVIF generic position ``x`` of ``axis`` -> device units (not rounded, not clamped)."""
        if axis == "zoom":
            return x * ONVIF_ZOOM_UNITS
        sec = getattr(self, axis)
        lo, hi = sec.limits_deg
        return (0.5 * (lo + hi) + x * 0.5 * (hi - lo)) * sec.units_per_deg

    def normalised_scale(self, axis: Literal["pan", "tilt", "zoom"]) -> float:
        """Device units per unit of ONVIF generic translation (and of full-speed velocity per second
        divided by the slew rate): the half range of pan/tilt, the whole lens for zoom."""
        if axis == "zoom":
            return float(ONVIF_ZOOM_UNITS)
        sec = getattr(self, axis)
        return 0.5 * (sec.limits_deg[1] - sec.limits_deg[0]) * sec.units_per_deg

    def slew_units_s(self, axis: Literal["pan", "tilt"], speed: int | None = None) -> float:
        """Slew rate of ``axis`` in device units per second (at VISCA speed code ``speed``)."""
        sec = getattr(self, axis)
        return sec.slew_deg_s(speed) * sec.units_per_deg

    def move_units_s(self, axis: Literal["pan", "tilt"]) -> float:
        """Slew rate of ``axis`` in device units per second of the moves omnijax commands
        (:meth:`AxisSection.move_deg_s`)."""
        sec = getattr(self, axis)
        return sec.move_deg_s() * sec.units_per_deg

    def move_rates_deg_s(self) -> tuple[float, float]:
        """(pan, tilt) slew rates of the moves omnijax commands, deg/s: what the real-time loop predicts the
        PTZ's arrival with."""
        return self.pan.move_deg_s(), self.tilt.move_deg_s()


def parse_profile(mapping: dict, source: str = "<profile>") -> DeviceProfile:
    """Validate a profile mapping (as read from TOML); one-line :class:`ProfileError` if it is wrong."""
    return validate(DeviceProfile, mapping, source, ProfileError)


def resolve_profile_path(name_or_path: str | Path) -> Path:
    """A profile file: a path as given, or a bare name of a shipped profile (``sony_evi_d70``)."""
    path = Path(name_or_path)
    if path.suffix != ".toml" and path.parent == Path(".") and not path.exists():
        return DEVICES_DIR / f"{path}.toml"
    return path


def load_profile(name_or_path: str | Path) -> DeviceProfile:
    """Read and validate a profile (see :func:`resolve_profile_path`)."""
    path = resolve_profile_path(name_or_path)
    from runtime.files import read_toml  # here: runtime.files imports the rig, hence JAX, which the emulator needs not

    return parse_profile(read_toml(path, "device profile", ProfileError), source=str(path))


def default_profile(protocol: str) -> DeviceProfile:
    """The shipped profile for ``protocol`` (``visca``, ``pelco-d`` or ``onvif``)."""
    return load_profile(DEFAULT_PROFILES[protocol])
