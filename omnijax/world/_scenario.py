"""Scenario files of the synthetic world: a TOML schema and the PyTree the renderer takes.

A scenario names its rig file (``rig = "../paper.toml"``, relative to the
scenario) and adds what the rig does not say: the room's walls and textures,
furniture boxes (some may move once, at a given time), the people (how many,
clothing, walking, standing still at the start or at given times), the lamps
(one shared spectrum unless a lamp has its own, positions, intensities, switching
times), slow illumination drift, self-lit screens on the walls that change colour (a
false-alarm source), and the sensor (noise, JPEG, anti-aliasing). Every key is documented in
``configs/scenarios/one_person.toml``.

:func:`parse_scenario` validates the mapping against the schema and against the
rig (lamps below the ceiling and inside the room, ...) and builds
:class:`Scenario`; every failure is a :class:`ConfigError` with one line naming
the key and what was expected.

Light is in grey levels: a lamp's ``intensity`` is the grey level of a white
(albedo 1) surface 1 m from the lamp and facing it; ``ambient`` is the grey
level of a white surface under the ambient light alone. Albedos are linear RGB
in [0, 1]; the camera's response is linear.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from annotated_types import Len
from jaxtyping import Array, Bool, Float, Int
from pydantic import Field, model_validator

from ..config import ConfigError, Coordinate, Metres, PosMetres, Rig, Section, validate, within
from ..config._config import _in_polygon

# --------------------------------------------------------------------------------------
# Kernel-side types
# --------------------------------------------------------------------------------------


class Surface(eqx.Module):
    """Look of a surface: mean albedo, per-tile spread, fine texture (relative) and its scale (m).

    ``tile`` is the tile edge (m, 0: no tiles); tiles are separated by grout
    lines of width ``grout`` (m) and colour ``grout_colour``.
    """

    colour: Float[Array, "3"]
    tile: Float[Array, ""]
    grout: Float[Array, ""]
    grout_colour: Float[Array, "3"]
    tile_variation: Float[Array, ""]
    texture: Float[Array, ""]
    texture_scale: Float[Array, ""]


class Furniture(eqx.Module):
    """Axis-aligned boxes standing on the floor: footprint corners (m), heights (m), albedos.

    A piece may move once: at ``move_at`` (s; inf: never) its footprint's corner_min
    jumps from ``lo`` to ``moved_lo`` (same size) and it stays there. ``moving`` lists
    the pieces that move, in the order of their times (ties in file order): the
    furniture's *arrangement* ``j`` has the first ``j`` of them moved.
    """

    lo: Float[Array, "n 2"]
    hi: Float[Array, "n 2"]
    height: Float[Array, " n"]
    colour: Float[Array, "n 3"]
    move_at: Float[Array, " n"]
    moved_lo: Float[Array, "n 2"]
    moving: tuple[int, ...] = eqx.field(static=True)

    @property
    def count(self) -> int:
        return self.lo.shape[0]

    @property
    def arrangements(self) -> int:
        """How many arrangements the furniture goes through (1 when nothing moves)."""
        return len(self.moving) + 1

    def arrangement(self, t) -> Int[Array, "*b"]:
        """The arrangement at time(s) ``t`` (s): how many moving pieces have moved."""
        t = jnp.asarray(t)
        if not self.moving:
            return jnp.zeros(t.shape, jnp.int32)
        times = self.move_at[jnp.asarray(self.moving)]
        return jnp.sum(times <= t[..., None], axis=-1).astype(jnp.int32)

    def placed(self, j: int) -> tuple[Float[Array, "n 2"], Float[Array, "n 2"]]:
        """Footprint corners (lo, hi) of every piece in arrangement ``j``."""
        lo, hi = self.lo, self.hi
        for i in self.moving[:j]:
            lo, hi = lo.at[i].set(self.moved_lo[i]), hi.at[i].set(self.moved_lo[i] + (self.hi[i] - self.lo[i]))
        return lo, hi

    def footprints(self) -> tuple[Float[Array, "m 2"], Float[Array, "m 2"]]:
        """Footprint corners (lo, hi) of every place any piece ever stands (the first
        arrangement, then each moving piece's new place): what people walk around."""
        if not self.moving:
            return self.lo, self.hi
        i = jnp.asarray(self.moving)
        lo = self.moved_lo[i]
        return jnp.concatenate([self.lo, lo]), jnp.concatenate([self.hi, lo + (self.hi[i] - self.lo[i])])

    def moved_centres(self) -> Float[Array, "m2 2"]:
        """Footprint centres (m) of each moving piece before and after its move, in pairs."""
        centres = []
        for i in self.moving:
            size = self.hi[i] - self.lo[i]
            centres += [self.lo[i] + 0.5 * size, self.moved_lo[i] + 0.5 * size]
        return jnp.stack(centres) if centres else jnp.zeros((0, 2))


class Crowd(eqx.Module):
    """How many people, how they walk, and what they wear.

    ``speed`` is the range of preferred walking speeds (m/s); at each reached
    goal a person stands still with probability ``pause_probability`` for a
    time drawn from ``pause`` (s). ``first_pause`` is the range (s) of the
    standing time everybody starts with ([0, 0]: a chance of a ``pause`` as at
    a goal). Person ``i`` also stands still from ``stop_start[i, j]`` until
    ``stop_end[i, j]`` (s; padded with +inf). ``floor_like`` is the share of
    people whose clothing is close to the floor's colour. ``gap`` is the
    smallest distance (m) kept between two people's body cylinders.
    """

    count: int = eqx.field(static=True)
    speed: Float[Array, "2"]
    pause_probability: Float[Array, ""]
    pause: Float[Array, "2"]
    first_pause: Float[Array, "2"]
    stop_start: Float[Array, "p m"]
    stop_end: Float[Array, "p m"]
    gap: Float[Array, ""]
    clothing: Float[Array, "k 3"]
    skin: Float[Array, "ks 3"]
    hair: Float[Array, "kh 3"]
    floor_like: Float[Array, ""]


class Lighting(eqx.Module):
    """Lamps, ambient light of the scenario's ``spectrum``, and a slow global drift.

    Each lamp has its own spectrum, ``lamp_spectrum`` (the scenario's ``spectrum``
    unless the file gives one: then all light shares one spectrum, the paper's
    assumption). ``switch`` holds each lamp's switching times (s), padded with +inf; a lamp
    is on at time t when ``on`` xor (an odd number of switches at or before t).
    The drift multiplies all light by ``1 + drift_amplitude sin(2 pi t / drift_period)``.
    """

    spectrum: Float[Array, "3"]
    ambient: Float[Array, ""]
    position: Float[Array, "k 3"]
    lamp_spectrum: Float[Array, "k 3"]
    intensity: Float[Array, " k"]
    on: Bool[Array, " k"]
    switch: Float[Array, "k m"]
    drift_amplitude: Float[Array, ""]
    drift_period: Float[Array, ""]

    @property
    def count(self) -> int:
        return self.position.shape[0]

    def lamp_on(self, t) -> Bool[Array, " k"]:
        """Which lamps are on at time ``t`` (s)."""
        toggles = jnp.sum(self.switch <= t, axis=-1) % 2 == 1
        return self.on ^ toggles

    def drift(self, t) -> Float[Array, ""]:
        """Global illumination factor at time ``t`` (s)."""
        return 1.0 + self.drift_amplitude * jnp.sin(2.0 * jnp.pi * t / self.drift_period)


class Screens(eqx.Module):
    """Self-lit rectangles on walls (a television, a monitor): a scripted false-alarm source.

    Screen ``i`` covers wall ``wall[i]`` (edge ``wall[i]`` of the rig's ``room.outline``,
    from its corner ``wall[i]`` to the next) from ``along[i, 0]`` to ``along[i, 1]`` m
    along it and from ``height[i, 0]`` to ``height[i, 1]`` m above the floor. It emits
    (is not lit) its ``colours[i, j]`` (grey levels) for ``j < count[i]`` in turn, each
    for ``period[i] / count[i]`` s, starting with the first at t = 0 (rows past
    ``count[i]`` are padding).
    """

    wall: Int[Array, " s"]
    along: Float[Array, "s 2"]
    height: Float[Array, "s 2"]
    colours: Float[Array, "s c 3"]
    count: Int[Array, " s"]
    period: Float[Array, " s"]

    @property
    def size(self) -> int:
        return self.wall.shape[0]

    def shown(self, t) -> Float[Array, "s 3"]:
        """The colour (grey levels) each screen emits at time ``t`` (s)."""
        j = jnp.floor(self.count * jnp.asarray(t) / self.period).astype(jnp.int32) % self.count
        return jnp.take_along_axis(self.colours, j[:, None, None], axis=1)[:, 0]


class Sensor(eqx.Module):
    """The omni camera's sensor: noise sigma (grey levels), vignetting, JPEG, sampling.

    ``vignetting`` v darkens the image towards the rim as ``1 - v (r / rim)^2``.
    ``antialias`` n renders people with n x n samples per pixel;
    ``shadow_downsample`` s computes people's cast shadows on a grid s times
    coarser than the image and interpolates it bilinearly (a soft penumbra).
    ``jpeg_quality`` 0 means no JPEG compression.
    """

    noise_sigma: Float[Array, ""]
    vignetting: Float[Array, ""]
    jpeg_quality: int = eqx.field(static=True)
    antialias: int = eqx.field(static=True)
    shadow_downsample: int = eqx.field(static=True)


class Scenario(eqx.Module):
    """A whole synthetic-world scenario (the rig is separate: see :func:`parse_scenario`)."""

    name: str = eqx.field(static=True)
    fps: float = eqx.field(static=True)
    seed: int = eqx.field(static=True)
    height: Float[Array, ""]
    floor: Surface
    walls: Surface
    ceiling: Float[Array, "3"]
    skirting_colour: Float[Array, "3"]
    skirting_height: Float[Array, ""]
    furniture: Furniture
    crowd: Crowd
    lighting: Lighting
    screens: Screens
    sensor: Sensor


# --------------------------------------------------------------------------------------
# TOML schema
# --------------------------------------------------------------------------------------

Unit = Annotated[float, Field(ge=0, le=1)]
Colour = Annotated[list[Unit], Len(3, 3)]
PosColour = Annotated[list[Annotated[float, Field(gt=0, le=1)]], Len(3, 3)]
Point2 = Annotated[list[Coordinate], Len(2, 2)]
Point3 = Annotated[list[Coordinate], Len(3, 3)]
#: Times (s): at most a day, the longest a scenario is rendered for.
Seconds = Annotated[float, within(0.0, 86_400.0, "seconds", why="a day")]
PosSeconds = Annotated[float, within(0.0, 86_400.0, "seconds", open_low=True, why="a day")]
#: Walking speeds (m/s): nobody indoors is faster.
Speed = Annotated[float, within(0.0, 10.0, "metres per second", why="faster than anyone walks")]
#: Light (grey levels of a white surface): any image is white long before.
Light = Annotated[float, within(0.0, 1e6, "grey levels", why="an image is white long before")]

#: Default clothing palette (linear RGB albedos): saturated, dark and light garments.
CLOTHING = (
    (0.60, 0.10, 0.10), (0.10, 0.20, 0.55), (0.12, 0.40, 0.15), (0.70, 0.60, 0.15),
    (0.08, 0.08, 0.10), (0.75, 0.75, 0.72), (0.45, 0.20, 0.45), (0.20, 0.45, 0.55),
    (0.50, 0.30, 0.15), (0.35, 0.35, 0.38),
)
SKIN = ((0.70, 0.50, 0.40), (0.55, 0.37, 0.28), (0.35, 0.22, 0.15), (0.80, 0.62, 0.52))
HAIR = ((0.08, 0.06, 0.05), (0.30, 0.20, 0.10), (0.55, 0.45, 0.30), (0.45, 0.45, 0.45))


def _ordered(pair: list[float], key: str) -> None:
    if pair[0] > pair[1]:
        raise ValueError(f"{key} must be [low, high] with low <= high")


class SurfaceSection(Section):
    colour: Colour = Field(description="mean albedo, linear RGB in [0, 1]")
    tile: Metres = Field(0.0, description="tile edge, m; 0: no tiles")
    grout: Metres = Field(0.006, description="width of the lines between tiles, m")
    grout_colour: Colour | None = Field(None, description="albedo of the grout; default: 0.6 x colour")
    tile_variation: Unit = Field(0.0, description="relative brightness spread between tiles")
    texture: Unit = Field(0.0, description="relative amplitude of the fine texture")
    texture_scale: PosMetres = Field(0.05, description="size of the fine texture's grain, m")


class RoomSection(Section):
    height: PosMetres = Field(description="ceiling height, m (walls stand on the rig's room.outline)")
    floor: SurfaceSection
    walls: SurfaceSection
    ceiling: Colour = [0.85, 0.85, 0.85]
    skirting_colour: Colour = [0.25, 0.22, 0.20]
    skirting_height: Metres = 0.08


class FurnitureSection(Section):
    name: str = ""
    corner_min: Point2 = Field(description="footprint corner with the smallest x and y, m")
    corner_max: Point2 = Field(description="footprint corner with the largest x and y, m")
    height: PosMetres
    colour: Colour
    move_at_s: Seconds | None = Field(None, description="time the piece moves to moved_to, s; default: never")
    moved_to: Point2 | None = Field(None, description="footprint centre after the move, m")

    @model_validator(mode="after")
    def _box(self):
        if not (self.corner_min[0] < self.corner_max[0] and self.corner_min[1] < self.corner_max[1]):
            raise ValueError("corner_min must be below corner_max in both x and y")
        if (self.move_at_s is None) != (self.moved_to is None):
            raise ValueError("move_at_s and moved_to go together: give both or neither")
        return self

    def moved_min(self) -> list[float]:
        """corner_min after the move (``moved_to`` is the footprint's new centre)."""
        half = [0.5 * (b - a) for a, b in zip(self.corner_min, self.corner_max)]
        return [c - h for c, h in zip(self.moved_to, half)]


class StopSection(Section):
    person: Annotated[int, Field(ge=0, le=63)] = Field(description="index of the person, 0 .. count - 1")
    at_s: Seconds = Field(description="time the person stands still from, s")
    seconds: PosSeconds = Field(description="how long the person stands still, s")


class PeopleSection(Section):
    count: Annotated[int, Field(ge=0, le=64)]
    speed: Annotated[list[Speed], Len(2, 2)] = Field([0.8, 1.4], description="preferred walking speed range, m/s")
    pause_probability: Unit = 0.3
    pause: Annotated[list[Seconds], Len(2, 2)] = Field([1.0, 4.0], description="standing time range at a goal, s")
    first_pause: Annotated[list[Seconds], Len(2, 2)] = Field(
        [0.0, 0.0], description="standing time range everybody starts with, s; [0, 0]: none")
    stops: list[StopSection] = Field(default_factory=list, description="times given people stand still")
    gap: Metres = Field(0.10, description="smallest distance kept between two people, m")
    clothing: Annotated[list[Colour], Len(1)] = Field(default_factory=lambda: [list(c) for c in CLOTHING])
    skin: Annotated[list[Colour], Len(1)] = Field(default_factory=lambda: [list(c) for c in SKIN])
    hair: Annotated[list[Colour], Len(1)] = Field(default_factory=lambda: [list(c) for c in HAIR])
    floor_like: Unit = Field(0.0, description="share of people dressed close to the floor's colour")

    @model_validator(mode="after")
    def _ranges(self):
        _ordered(self.speed, "speed")
        _ordered(self.pause, "pause")
        _ordered(self.first_pause, "first_pause")
        if self.speed[0] <= 0:
            raise ValueError("speed must be positive")
        return self


class LampSection(Section):
    position: Point3 = Field(description="lamp position x, y, z in m (world frame)")
    intensity: Light = Field(description="grey level of a white surface 1 m away, facing the lamp")
    on: bool = Field(True, description="on at t = 0")
    switch: list[Seconds] = Field(default_factory=list, description="times (s) at which the lamp toggles")
    spectrum: PosColour | None = Field(None, description="RGB of this lamp's spectrum; default: lighting.spectrum")

    @model_validator(mode="after")
    def _times(self):
        if any(b <= a for a, b in zip(self.switch, self.switch[1:])):
            raise ValueError("switch times must increase strictly")
        return self


class DriftSection(Section):
    amplitude: Annotated[float, Field(ge=0, lt=1)] = 0.0
    period: PosSeconds = Field(60.0, description="period of the drift, s")


class LightingSection(Section):
    spectrum: PosColour = Field(description="RGB of the ambient light's spectrum, and of every lamp without its own")
    ambient: Light
    drift: DriftSection = DriftSection()
    lamps: list[LampSection] = Field(default_factory=list)


class ScreenSection(Section):
    name: str = ""
    wall: Annotated[int, Field(ge=0, le=1023)] = Field(
        description="edge of the rig's room.outline the screen hangs on, from corner `wall` to the next")
    along_m: Annotated[list[Metres], Len(2, 2)] = Field(
        description="from .. to, m along the wall from its first corner")
    height_m: Annotated[list[Metres], Len(2, 2)] = Field(description="bottom .. top above the floor, m")
    colours: Annotated[list[Annotated[list[Light], Len(3, 3)]], Len(1, 64)] = Field(
        description="RGB grey levels the screen emits, shown in turn")
    period_s: PosSeconds = Field(description="time to show every colour once, s; each for period_s / count")

    @model_validator(mode="after")
    def _ranges(self):
        if not self.along_m[0] < self.along_m[1]:
            raise ValueError("along_m must be [from, to] with from < to")
        if not self.height_m[0] < self.height_m[1]:
            raise ValueError("height_m must be [bottom, top] with bottom < top")
        return self


class SensorSection(Section):
    noise_sigma: Annotated[float, within(0.0, 255.0, "grey levels", why="an 8-bit image's whole range")] | None = (
        Field(None, description="grey levels; default: the rig's detection.sensor_sigma"))
    vignetting: Annotated[float, Field(ge=0, lt=1)] = 0.0
    jpeg_quality: Annotated[int, Field(ge=1, le=100)] | None = None
    antialias: Annotated[int, Field(ge=1, le=4)] = 2
    shadow_downsample: Annotated[int, Field(ge=1, le=8)] = 4


class ScenarioFile(Section):
    name: str
    rig: str = Field(description="rig TOML file, relative to this scenario file")
    fps: Annotated[float, within(0.0, 1000.0, "frames per second", open_low=True, why="no camera is faster")] = 25.0
    seed: Annotated[int, Field(ge=0)] = 0
    room: RoomSection
    furniture: list[FurnitureSection] = Field(default_factory=list)
    people: PeopleSection
    lighting: LightingSection
    screens: list[ScreenSection] = Field(default_factory=list, description="self-lit screens on the walls")
    sensor: SensorSection = SensorSection()


def read_scenario_header(data: Mapping[str, Any], *, source: str = "scenario") -> ScenarioFile:
    """Validate a parsed scenario mapping against the schema (rig not yet needed)."""
    return validate(ScenarioFile, data, source)


# --------------------------------------------------------------------------------------
# Mapping + rig -> Scenario
# --------------------------------------------------------------------------------------


def _a(x) -> Array:
    return jnp.asarray(x, dtype=float)


def _surface(sec: SurfaceSection) -> Surface:
    grout = sec.grout_colour if sec.grout_colour is not None else [0.6 * c for c in sec.colour]
    return Surface(
        colour=_a(sec.colour), tile=_a(sec.tile), grout=_a(sec.grout), grout_colour=_a(grout),
        tile_variation=_a(sec.tile_variation), texture=_a(sec.texture), texture_scale=_a(sec.texture_scale),
    )


def _check_against_rig(f: ScenarioFile, rig: Rig, source: str) -> None:
    def fail(key: str, msg: str):
        raise ConfigError(f"{source}: {key}: {msg}")

    H_o = float(rig.omni.H_o)
    if f.room.height <= H_o:
        fail("room.height", f"{f.room.height} m must be above the omni camera (omni.H_o = {H_o} m)")
    outline = rig.room.outline
    tallest = float(rig.person.H_p + 4 * rig.sigmas.H_p)
    for i, lamp in enumerate(f.lighting.lamps):
        x, y, z = lamp.position
        if not bool(_in_polygon(outline, x, y)):
            fail(f"lighting.lamps.{i}.position", f"({x}, {y}) is outside the rig's room.outline")
        if not tallest < z < f.room.height:
            fail(f"lighting.lamps.{i}.position",
                 f"z = {z} m must lie between the tallest person ({tallest:.2f} m) and the ceiling ({f.room.height} m)")
    def inside(lo, hi) -> bool:
        (x0, y0), (x1, y1) = lo, hi
        e = 1e-3  # boxes may touch the walls
        corners = np.array([[x0 + e, y0 + e], [x1 - e, y1 - e], [x0 + e, y1 - e], [x1 - e, y0 + e]])
        return bool(np.all(_in_polygon(outline, corners[:, 0], corners[:, 1])))

    for i, box in enumerate(f.furniture):
        if not inside(box.corner_min, box.corner_max):
            fail(f"furniture.{i}", "the box must stand inside the rig's room.outline")
        if box.height >= f.room.height:
            fail(f"furniture.{i}.height", f"{box.height} m must be below room.height = {f.room.height} m")
        if box.moved_to is not None:
            lo = box.moved_min()
            hi = [a + b - c for a, b, c in zip(lo, box.corner_max, box.corner_min)]
            if not inside(lo, hi):
                fail(f"furniture.{i}.moved_to", f"{box.moved_to}: the moved box must stand inside the room.outline")
    corners = np.asarray(outline)
    for i, screen in enumerate(f.screens):
        if screen.wall >= len(corners):
            fail(f"screens.{i}.wall", f"{screen.wall} is not an edge of the rig's room.outline "
                                      f"(0 .. {len(corners) - 1})")
        length = float(np.linalg.norm(corners[(screen.wall + 1) % len(corners)] - corners[screen.wall]))
        if screen.along_m[1] > length:
            fail(f"screens.{i}.along_m", f"{screen.along_m} must lie within the wall's {length:g} m")
        if screen.height_m[1] > f.room.height:
            fail(f"screens.{i}.height_m", f"{screen.height_m} must lie below room.height = {f.room.height} m")
    count = f.people.count
    for j, stop in enumerate(f.people.stops):
        if stop.person >= count:
            fail(f"people.stops.{j}.person", f"{stop.person} is not a person of people.count = {count}")
        for k, other in enumerate(f.people.stops[:j]):
            overlap = stop.at_s < other.at_s + other.seconds and other.at_s < stop.at_s + stop.seconds
            if other.person == stop.person and overlap:
                fail(f"people.stops.{j}", f"overlaps people.stops.{k} of the same person")


def parse_scenario(data: Mapping[str, Any], rig: Rig, *, source: str = "scenario") -> Scenario:
    """Validate a parsed scenario mapping (its ``rig`` already loaded) and build :class:`Scenario`.

    Raises :class:`ConfigError` with one line naming the key and what was expected.
    """
    f = read_scenario_header(data, source=source)
    _check_against_rig(f, rig, source)
    furn = f.furniture
    move_at = [np.inf if b.move_at_s is None else b.move_at_s for b in furn]
    furniture = Furniture(
        lo=_a(np.reshape([b.corner_min for b in furn], (-1, 2))),
        hi=_a(np.reshape([b.corner_max for b in furn], (-1, 2))),
        height=_a([b.height for b in furn]),
        colour=_a(np.reshape([b.colour for b in furn], (-1, 3))),
        move_at=_a(move_at),
        moved_lo=_a(np.reshape([b.corner_min if b.moved_to is None else b.moved_min() for b in furn], (-1, 2))),
        moving=tuple(sorted((i for i, b in enumerate(furn) if b.moved_to is not None), key=lambda i: move_at[i])),
    )
    pe = f.people
    per_person = [[s for s in pe.stops if s.person == i] for i in range(pe.count)]
    n_stops = max([len(s) for s in per_person] + [0])
    stop_start, stop_end = np.full((pe.count, n_stops), np.inf), np.full((pe.count, n_stops), np.inf)
    for i, stops in enumerate(per_person):
        stop_start[i, : len(stops)] = [s.at_s for s in stops]
        stop_end[i, : len(stops)] = [s.at_s + s.seconds for s in stops]
    crowd = Crowd(
        count=pe.count, speed=_a(pe.speed), pause_probability=_a(pe.pause_probability), pause=_a(pe.pause),
        first_pause=_a(pe.first_pause), stop_start=_a(stop_start), stop_end=_a(stop_end),
        gap=_a(pe.gap), clothing=_a(pe.clothing), skin=_a(pe.skin), hair=_a(pe.hair),
        floor_like=_a(pe.floor_like),
    )
    li = f.lighting
    n_switch = max([len(lamp.switch) for lamp in li.lamps] + [1])
    switch = np.full((len(li.lamps), n_switch), np.inf)
    for i, lamp in enumerate(li.lamps):
        switch[i, : len(lamp.switch)] = lamp.switch
    lighting = Lighting(
        spectrum=_a(li.spectrum), ambient=_a(li.ambient),
        position=_a(np.reshape([lamp.position for lamp in li.lamps], (-1, 3))),
        lamp_spectrum=_a(np.reshape([lamp.spectrum or li.spectrum for lamp in li.lamps], (-1, 3))),
        intensity=_a([lamp.intensity for lamp in li.lamps]),
        on=jnp.asarray([lamp.on for lamp in li.lamps], dtype=bool),
        switch=_a(switch), drift_amplitude=_a(li.drift.amplitude), drift_period=_a(li.drift.period),
    )
    sc = f.screens
    n_colours = max([len(x.colours) for x in sc] + [1])
    colours = np.zeros((len(sc), n_colours, 3))
    for i, x in enumerate(sc):
        colours[i, : len(x.colours)] = x.colours
    screens = Screens(
        wall=jnp.asarray([x.wall for x in sc], jnp.int32), along=_a(np.reshape([x.along_m for x in sc], (-1, 2))),
        height=_a(np.reshape([x.height_m for x in sc], (-1, 2))), colours=_a(colours),
        count=jnp.asarray([len(x.colours) for x in sc], jnp.int32), period=_a([x.period_s for x in sc]),
    )
    se = f.sensor
    sigma = float(rig.detection.sensor_sigma) if se.noise_sigma is None else se.noise_sigma
    sensor = Sensor(
        noise_sigma=_a(sigma), vignetting=_a(se.vignetting), jpeg_quality=se.jpeg_quality or 0,
        antialias=se.antialias, shadow_downsample=se.shadow_downsample,
    )
    ro = f.room
    return Scenario(
        name=f.name, fps=float(f.fps), seed=int(f.seed), height=_a(ro.height), floor=_surface(ro.floor),
        walls=_surface(ro.walls), ceiling=_a(ro.ceiling), skirting_colour=_a(ro.skirting_colour),
        skirting_height=_a(ro.skirting_height), furniture=furniture, crowd=crowd, lighting=lighting,
        screens=screens, sensor=sensor,
    )
