"""Typed rig configuration: a TOML schema (validated once, at the edge) and the PyTrees kernels take.

The schema (:class:`RigFile` and its sections) mirrors the TOML file key for key,
with units in the key names where they are not SI (``theta_c_deg``). Pydantic
checks types, ranges and unknown keys; :func:`parse_rig` turns a validated mapping
into :class:`Rig`, an immutable ``equinox.Module`` whose numbers are arrays (so a
new ``D_c`` does not recompile) and whose modes and sizes are static fields.

Every failure is a :class:`ConfigError` with one line naming the key and what was
expected.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Annotated, Any, Literal, get_args

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from annotated_types import Len
from jaxtyping import Array, Float
from pydantic import Field, field_validator, model_validator

from ..camera import PROFILES, OCamCalib, OmniCamera, parse_ocamcalib
from ._schema import (
    MAX_LENGTH_M,
    ConfigError,
    Coordinate,
    Degrees,
    Metres,
    NonNegPixels,
    Pixels,
    PosMetres,
    PosSigmaDegrees,
    Section,
    Side,
    SigmaDegrees,
    validate,
    within,
)
from ._zones import MAX_ZONES, Zone, ZoneSection, zones_in_image

# --------------------------------------------------------------------------------------
# Kernel-side types
# --------------------------------------------------------------------------------------

#: Order of the uncertain inputs of the pointing geometry (docs/design.md section 3.2, eq 13-14).
INPUT_NAMES: tuple[str, ...] = ("r_f", "theta_f", "H_o", "H_f", "D_c", "theta_c", "r_m", "H_p", "R_h")
#: Units of the inputs, as echoed in reports.
INPUT_UNITS: dict[str, str] = {
    "r_f": "px", "theta_f": "rad", "H_o": "m", "H_f": "m", "D_c": "m",
    "theta_c": "rad", "r_m": "px", "H_p": "m", "R_h": "m",
}
#: The zoom rules of :func:`omnijax.zoom.choose_zoom` (re-exported there): eq 15 as printed, and calibrated.
#: The schema's names, hence defined here; import them from ``omnijax.zoom``.
ZoomRule = Literal["paper", "calibrated"]
ZOOM_RULES: tuple[str, ...] = get_args(ZoomRule)


class Lens(eqx.Module):
    """The PTZ lens: horizontal angle of view at tabulated zoom factors, and the sensor's size.

    Between table entries ``log tan(fov_h / 2)`` is interpolated linearly in
    ``log zoom`` (exact for an ideal zoom lens, where ``tan(fov / 2)`` is ``1 / zoom``).
    """

    zoom: Float[Array, " k"]
    fov_h: Float[Array, " k"]
    zoom_range: Float[Array, "2"]
    image_size: tuple[int, int] = eqx.field(static=True)

    @property
    def aspect(self) -> float:
        """Height over width of the foveal image."""
        return self.image_size[1] / self.image_size[0]

    def fov(self, zoom) -> tuple[Array, Array]:
        """Horizontal and vertical angle of view (rad) at ``zoom`` (within the table)."""
        t = jnp.exp(jnp.interp(jnp.log(zoom), jnp.log(self.zoom), jnp.log(jnp.tan(0.5 * self.fov_h))))
        return 2.0 * jnp.arctan(t), 2.0 * jnp.arctan(t * self.aspect)

    def zoom_for_tan_half_fov_h(self, t) -> Array:
        """Zoom factor whose ``tan(fov_h / 2)`` is ``t`` (table ends beyond the table)."""
        log_t = jnp.log(jnp.tan(0.5 * self.fov_h))
        return jnp.exp(jnp.interp(-jnp.log(t), -log_t, jnp.log(self.zoom)))

    def clamp(self, zoom) -> Array:
        """``zoom`` clamped to the device's zoom range."""
        return jnp.clip(zoom, self.zoom_range[0], self.zoom_range[1])


class Foveal(eqx.Module):
    """The pan-tilt-zoom camera: placement (``D_c``, ``theta_c``, ``H_f``), limits and lens."""

    D_c: Float[Array, ""]
    theta_c: Float[Array, ""]
    H_f: Float[Array, ""]
    pan_limits: Float[Array, "2"]
    tilt_limits: Float[Array, "2"]
    lens: Lens


class PTZ(eqx.Module):
    """A PTZ of a rig with several (a ``[[foveal]]`` table after the first): its placement, limits and
    lens, and its own calibration sigmas (m, rad). :meth:`Rig.ptz` makes it a one-PTZ rig."""

    foveal: Foveal
    sigma_D_c: Float[Array, ""]
    sigma_H_f: Float[Array, ""]
    sigma_theta_c: Float[Array, ""]


class Person(eqx.Module):
    """Person priors: height ``H_p``, head radius ``R_h``, shoulder width (all metres)."""

    H_p: Float[Array, ""]
    R_h: Float[Array, ""]
    shoulder_width: Float[Array, ""]


class Sigmas(eqx.Module):
    """Standard deviations of the rig's calibration and of the person priors (SI, px for ``r_m``)."""

    H_o: Float[Array, ""]
    H_f: Float[Array, ""]
    D_c: Float[Array, ""]
    theta_c: Float[Array, ""]
    r_m: Float[Array, ""]
    H_p: Float[Array, ""]
    R_h: Float[Array, ""]


#: ``[detection] noise_margin``'s default: d^2 is taken against the measured sensor noise times this.
#: The measured noise is the sensor's (:func:`omnijax.detection.estimate_sensor_noise`); against it
#: the detector saw floor-coloured people better and more of what is not a person (fragments, ghosts,
#: coloured shadows). Chosen on tuning seeds 9314-9318 of five scenes (docs/detection.md, "The sensor
#: noise, measured where people walk": misses and false alarms against the margin).
NOISE_MARGIN = 1.4


class Detection(eqx.Module):
    """Detection settings: sensor noise, rates, contrast, polar sampling, the sigma rule's coefficients
    and the default sigmas of an aim without a detection (:func:`omnijax.aiming.detection_sigmas`).

    The sigma rule: a detection's sigma is ``sqrt((sigma_gain * detector's)^2 + bound^2 + sigma_extra^2
    + range term^2)`` per coordinate (``sigma_extra_theta_f`` in rad; the range terms
    ``sigma_extra_r_f_per_m * R`` px and ``sigma_lateral_m / R`` rad at the foot's floor distance ``R``),
    and the foot's coupling to the person's height, ``height_share_r_f`` (a seen foot) and
    ``height_share_head_r_f`` (a foot from the head) of what the geometry moves a foot from the head
    (:func:`omnijax.aiming.height_coupling`), fitted by benchmarks/fit_detection_sigmas.py; without
    a detection (layout optimiser, calibration points, ``omnijax variance``) ``sigma_r_f`` and
    ``sigma_theta_f`` are used as they are.

    ``c_min`` is the smallest per-pixel non-centrality (the Mahalanobis contrast of
    a person's chromaticity against the background) for which ``x_m`` must hold.
    ``r_min``/``r_max`` bound the polar sampling (px); ``None`` derives them from the
    room. Sizes and counts are static: changing them recompiles.
    """

    sensor_sigma: Float[Array, ""]
    x_f: Float[Array, ""]
    x_m: Float[Array, ""]
    sigma_r_f: Float[Array, ""]
    sigma_theta_f: Float[Array, ""]
    c_min: Float[Array, ""]
    adapt_rate: Float[Array, ""]
    min_floor_radius: Float[Array, ""]
    n_theta: int = eqx.field(static=True)
    max_people: int = eqx.field(static=True)
    background_frames: int = eqx.field(static=True)
    foot_mc_profiles: int = eqx.field(static=True)
    r_max: float | None = eqx.field(static=True, default=None)
    sigma_gain_r_f: Float[Array, ""] = eqx.field(default=1.0, converter=jnp.asarray)
    sigma_extra_r_f: Float[Array, ""] = eqx.field(default=0.0, converter=jnp.asarray)
    sigma_gain_theta_f: Float[Array, ""] = eqx.field(default=1.0, converter=jnp.asarray)
    sigma_extra_theta_f: Float[Array, ""] = eqx.field(default=0.0, converter=jnp.asarray)
    sigma_extra_r_f_per_m: Float[Array, ""] = eqx.field(default=0.0, converter=jnp.asarray)
    sigma_lateral_m: Float[Array, ""] = eqx.field(default=0.0, converter=jnp.asarray)
    height_share_r_f: Float[Array, ""] = eqx.field(default=0.0, converter=jnp.asarray)
    height_share_head_r_f: Float[Array, ""] = eqx.field(default=1.0, converter=jnp.asarray)
    background_seconds: float = eqx.field(static=True, default=10.0)
    still_s: float = eqx.field(static=True, default=0.3)
    ghost_s: float = eqx.field(static=True, default=0.4)
    floor_shows_s: float = eqx.field(static=True, default=1.0)
    ghost_edge: float = eqx.field(static=True, default=6.0)
    noise_margin: Float[Array, ""] = eqx.field(default=NOISE_MARGIN, converter=jnp.asarray)
    absorb_s: float = eqx.field(static=True, default=90.0)
    off_floor_m: Float[Array, ""] = eqx.field(default=0.5, converter=jnp.asarray)
    light_axis: tuple[float, float, float] | None = eqx.field(static=True, default=None)


class Room(eqx.Module):
    """Floor region: outline polygon and excluded zones (metres, world frame)."""

    outline: Float[Array, "n 2"]
    exclude: tuple[Float[Array, "m 2"], ...]

    def inside_outline(self, X, Y) -> Array:
        """Whether floor points (X, Y) lie inside the outline (where a person can be)."""
        return _in_polygon(self.outline, X, Y)

    # Jitted: called eagerly (a floor grid, a config check), each of their dozen jnp operations was a
    # program of its own to compile, about 20 ms each at a cold start.
    @jax.jit
    def contains(self, X, Y) -> Array:
        """Whether floor points (X, Y) lie inside the outline and outside every excluded zone."""
        inside = self.inside_outline(X, Y)
        for zone in self.exclude:
            inside = inside & ~_in_polygon(zone, X, Y)
        return inside

    @jax.jit
    def outside_by(self, X, Y) -> Array:
        """How far (m) floor points (X, Y) lie from where a person can stand: 0 inside the outline and
        outside every excluded zone, else the distance to the outline (outside it) or to the zone's
        edge (inside an excluded zone)."""
        X, Y = jnp.asarray(X), jnp.asarray(Y)
        d = jnp.where(self.inside_outline(X, Y), 0.0, _edge_distance(self.outline, X, Y))
        for zone in self.exclude:
            d = jnp.maximum(d, jnp.where(_in_polygon(zone, X, Y), _edge_distance(zone, X, Y), 0.0))
        return d


@jax.jit
def _edge_distance(poly: Float[Array, "n 2"], X, Y) -> Array:
    """Distance from (X, Y) to the nearest point of the polygon's edges."""
    X, Y = jnp.asarray(X)[..., None], jnp.asarray(Y)[..., None]
    x0, y0 = poly[:, 0], poly[:, 1]
    ex, ey = jnp.roll(x0, -1) - x0, jnp.roll(y0, -1) - y0
    t = jnp.clip(((X - x0) * ex + (Y - y0) * ey) / jnp.maximum(ex * ex + ey * ey, 1e-12), 0.0, 1.0)
    return jnp.min(jnp.hypot(X - x0 - t * ex, Y - y0 - t * ey), axis=-1)


@jax.jit
def _in_polygon(poly: Float[Array, "n 2"], X, Y) -> Array:
    """Even-odd rule: a horizontal ray from (X, Y) crosses the polygon's edges an odd number of times."""
    X, Y = jnp.asarray(X)[..., None], jnp.asarray(Y)[..., None]
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = jnp.roll(x0, -1), jnp.roll(y0, -1)
    straddles = (y0 > Y) != (y1 > Y)
    dy = jnp.where(straddles, y1 - y0, 1.0)
    x_cross = x0 + (Y - y0) * (x1 - x0) / dy
    return (jnp.sum(straddles & (X < x_cross), axis=-1) % 2) == 1


#: The PTZ placement variables a layout search may vary (``theta_c`` in rad inside, ``_deg`` in files).
LAYOUT_NAMES: tuple[str, ...] = ("D_c", "H_f", "theta_c", "H_o")


class LayoutSearch(eqx.Module):
    """What a layout search varies and optimises (the optional ``[layout]`` section).

    ``lower`` and ``upper`` bound the variables of :data:`LAYOUT_NAMES` (m, rad; only
    the varied ones are used); ``theta_c``'s box is periodic when it spans the
    full circle. ``grid_step`` (m) spaces the floor grid the objectives average
    over; floor points within ``near_radius`` (m) of the PTZ's foot are left out
    of them; ``face_target_px`` outlines the operational region on the maps.
    ``landscape`` is the number of grid values per varied variable of the global check.
    """

    vary: tuple[str, ...] = eqx.field(static=True)
    lower: Float[Array, "4"]
    upper: Float[Array, "4"]
    objective: Literal["face_px", "variance"] = eqx.field(static=True)
    statistic: Literal["mean", "worst"] = eqx.field(static=True)
    grid_step: float = eqx.field(static=True)
    near_radius: Float[Array, ""]
    face_target_px: Float[Array, ""]
    starts: int = eqx.field(static=True)
    landscape: int = eqx.field(static=True)


class Rig(eqx.Module):
    """A whole dual-camera set-up: what every kernel of omnijax takes.

    ``foveal`` (and the D_c, H_f, theta_c sigmas of ``sigmas``) is the first PTZ; a rig of several
    (``[[foveal]]`` tables) holds the others in ``more_ptzs``, and every kernel sees one PTZ at a
    time through :meth:`ptz`. ``ptz_profiles``: each PTZ's device profile as the file names it
    (``None``: the command's ``--ptz-profile``), for the run-time; empty in :meth:`ptz`'s rigs, so
    that those of PTZs of one lens table have one structure.
    """

    omni: OmniCamera
    foveal: Foveal
    person: Person
    sigmas: Sigmas
    detection: Detection
    room: Room
    p_contain: Float[Array, ""]
    layout: LayoutSearch
    zoom_rule: ZoomRule = eqx.field(static=True)
    more_ptzs: tuple[PTZ, ...] = ()
    ptz_profiles: tuple[str | None, ...] = eqx.field(static=True, default=())

    @property
    def ptz_count(self) -> int:
        """How many PTZs the rig has (1 for a ``[foveal]`` table)."""
        return 1 + len(self.more_ptzs)

    def ptz(self, i: int) -> Rig:
        """The one-PTZ rig of PTZ ``i`` (0: the first): its placement, lens, limits and sigmas in
        ``foveal`` and ``sigmas``, the omni camera, person, room and search shared (the device profile
        left out). One-PTZ rigs of PTZs with lens tables of one length stack for ``jax.vmap``."""
        if not 0 <= i < self.ptz_count:
            raise ValueError(f"PTZ {i} of a rig with {self.ptz_count}")
        one = dataclasses.replace(self, more_ptzs=(), ptz_profiles=())
        if i == 0:
            return one
        p = self.more_ptzs[i - 1]
        return eqx.tree_at(lambda r: (r.foveal, r.sigmas.D_c, r.sigmas.H_f, r.sigmas.theta_c), one,
                           (p.foveal, p.sigma_D_c, p.sigma_H_f, p.sigma_theta_c))

    def ptz_stack(self) -> Rig:
        """Every PTZ's one-PTZ rig (:meth:`ptz`) stacked along a new leading axis, for ``jax.vmap``
        over the PTZs (:func:`stack_ptzs`)."""
        return stack_ptzs([self.ptz(i) for i in range(self.ptz_count)])

    #: ``[[zones]]`` of the omni image (:mod:`omnijax.config._zones`): static, read when the detector
    #: and the target selector are built, never traced.
    zones: tuple[Zone, ...] = eqx.field(static=True, default=())

    def input_mean(self, r_f, theta_f) -> Float[Array, "*b 9"]:
        """The input vector x of the pointing geometry, in :data:`INPUT_NAMES` order.

        ``r_f`` (px) and ``theta_f`` (rad) may be arrays of one shape; the rig's
        values broadcast to it.
        """
        r_f, theta_f = jnp.broadcast_arrays(jnp.asarray(r_f, float), jnp.asarray(theta_f, float))
        rig = (self.omni.H_o, self.foveal.H_f, self.foveal.D_c, self.foveal.theta_c,
               self.omni.r_m, self.person.H_p, self.person.R_h)
        parts = [r_f, theta_f] + [jnp.broadcast_to(v, r_f.shape) for v in rig]
        return jnp.stack(parts, axis=-1)

    def input_sigma(self, sigma_r_f=None, sigma_theta_f=None) -> Float[Array, "*b 9"]:
        """Standard deviations of x; the detection's defaults unless given (may be arrays)."""
        s_r = self.detection.sigma_r_f if sigma_r_f is None else sigma_r_f
        s_t = self.detection.sigma_theta_f if sigma_theta_f is None else sigma_theta_f
        s_r, s_t = jnp.broadcast_arrays(jnp.asarray(s_r, float), jnp.asarray(s_t, float))
        s = self.sigmas
        rig = (s.H_o, s.H_f, s.D_c, s.theta_c, s.r_m, s.H_p, s.R_h)
        return jnp.stack([s_r, s_t] + [jnp.broadcast_to(v, s_r.shape) for v in rig], axis=-1)


def stack_ptzs(trees: Sequence) -> object:
    """PyTrees of one structure (one-PTZ rigs, placements) stacked along a new leading axis; a
    ``ValueError`` naming the difference otherwise (PTZs whose lens tables differ in length do not stack)."""
    structures = {jax.tree.structure(t) for t in trees}
    if len(structures) > 1:
        raise ValueError("the PTZs differ in structure (lens tables of different lengths?); several PTZs are "
                         "stacked only with lens tables of one length")
    return jax.tree.map(lambda *v: jnp.stack(v), *trees)


def with_ptz_count(rig: Rig, k: int) -> Rig:
    """``rig`` with ``k`` PTZs: its first ``k``, and where it has fewer, copies of its first PTZ (lens,
    limits, height, sigmas) spread evenly in azimuth around the omni axis, PTZ ``i`` at
    ``theta_c + 360 deg * i / k`` and the first's floor distance ``D_c``, pulled in to 0.05 m inside
    the room's outline along that azimuth where the wall is nearer. Their device profiles are the
    command's (``None``). The demo's ``--ptz-count``."""
    if not 1 <= k <= MAX_PTZS:
        raise ValueError(f"a rig has 1 to {MAX_PTZS} PTZs, asked for {k}")
    ptzs = [PTZ(foveal=rig.foveal, sigma_D_c=rig.sigmas.D_c, sigma_H_f=rig.sigmas.H_f,
                sigma_theta_c=rig.sigmas.theta_c), *rig.more_ptzs][:k]
    profiles = (tuple(rig.ptz_profiles) + (None,) * MAX_PTZS)[:k]
    outline = np.asarray(rig.room.outline, float)
    first = ptzs[0]
    for i in range(len(ptzs), k):
        azimuth = float(first.foveal.theta_c) + 2.0 * math.pi * i / k
        wall = _wall_distance(outline, azimuth)
        D_c = float(first.foveal.D_c) if wall is None else min(float(first.foveal.D_c), wall - 0.05)
        foveal = eqx.tree_at(lambda f: (f.D_c, f.theta_c), first.foveal,
                             (_a(max(D_c, 0.0)), _a(math.remainder(azimuth, 2.0 * math.pi))))
        ptzs.append(eqx.tree_at(lambda p: p.foveal, first, foveal))
    return dataclasses.replace(rig, more_ptzs=tuple(ptzs[1:]), ptz_profiles=profiles)


# --------------------------------------------------------------------------------------
# TOML schema
# --------------------------------------------------------------------------------------

Prob = Annotated[float, Field(gt=0, lt=1)]
Pair = Annotated[list[float], Len(2, 2)]
Size = Annotated[list[Side], Len(2, 2)]
Point = Annotated[list[Coordinate], Len(2, 2)]
Polygon = Annotated[list[Point], Len(3)]
#: How far (m) outside the room's outline a camera may be: mounted on a wall.
WALL_TOLERANCE_M = 0.5
#: Least floor (m^2) a room's outline must enclose: a person can stand in it.
MIN_ROOM_AREA_M2 = 1.0
#: Most magnification a PTZ lens table may give.
MAX_ZOOM = 1000.0
Zoom = Annotated[float, within(1.0, MAX_ZOOM, "a zoom factor", why="no PTZ lens magnifies more")]
MetrePair = Annotated[list[Metres], Len(2, 2)]
PanLimits = Annotated[list[Degrees], Len(2, 2)]
TiltLimits = Annotated[list[Annotated[float, within(-90.0, 90.0, "degrees",
                                                    why="straight down to straight up")]], Len(2, 2)]
#: Largest person contrast (d^2 non-centrality per pixel): two 8-bit colours' chromaticities, at the
#: least noise a sensor has, are never further apart.
MAX_CONTRAST = 1e6
#: A bright 8-bit image's whole range, in grey levels: the most a sensor's noise sigma can be.
MAX_GREY = 255.0


def _area(poly: list[list[float]]) -> float:
    """Area (m^2) of a polygon by the shoelace formula."""
    x, y = np.asarray(poly, float).T
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _outside_by(poly: list[list[float]], x: float, y: float) -> float:
    """How far (m) the floor point (x, y) lies outside the polygon: 0 inside, else its distance to the edges."""
    if bool(_in_polygon(jnp.asarray(poly, dtype=float), x, y)):
        return 0.0
    a = np.asarray(poly, float)
    e = np.roll(a, -1, axis=0) - a
    t = np.clip(((np.array([x, y]) - a) * e).sum(1) / np.maximum((e * e).sum(1), 1e-300), 0.0, 1.0)
    return float(np.hypot(*(a + t[:, None] * e - np.array([x, y])).T).min())


class OmniSection(Section):
    model: Literal["paraboloid", "equidistant", "equisolid", "ocamcalib"]
    H_o: PosMetres = Field(description="height of the mirror focus / lens centre above the floor, m")
    sigma_H_o: Metres
    image_size: Size | None = Field(None, description="width, height in px (ocamcalib: from the file)")
    center: Pair | None = Field(None, description="image centre x_c, y_c in px (ocamcalib: from the file)")
    r_m: Pixels | None = Field(None, description="horizon radius (phi = 90 deg) in px (ocamcalib: from the file)")
    sigma_r_m: NonNegPixels = Field(description="calibration sigma of r_m, px")
    rim: Pixels | None = Field(None, description="radius of the usable image circle, px")
    fov_deg: Annotated[float, Field(gt=0, le=360)] | None = Field(
        None, description="fisheye field of view; sets the rim when `rim` is absent"
    )
    calib_file: str | None = Field(None, description="ocamcalib: path of calib_results.txt")

    @model_validator(mode="after")
    def _model_keys(self):
        if self.model == "ocamcalib":
            if self.calib_file is None:
                raise ValueError("calib_file is required for model = 'ocamcalib'")
        else:
            for key in ("image_size", "center", "r_m"):
                if getattr(self, key) is None:
                    raise ValueError(f"{key} is required for model = '{self.model}'")
            if self.calib_file is not None:
                raise ValueError("calib_file is only for model = 'ocamcalib'")
        return self


class LensSection(Section):
    zoom: Annotated[list[Zoom], Len(2)]
    fov_h_deg: Annotated[list[Annotated[float, Field(gt=0, lt=180)]], Len(2)]

    @model_validator(mode="after")
    def _monotone(self):
        if len(self.zoom) != len(self.fov_h_deg):
            raise ValueError("zoom and fov_h_deg must have the same length")
        if any(b <= a for a, b in zip(self.zoom, self.zoom[1:])):
            raise ValueError("zoom must increase strictly")
        if any(b >= a for a, b in zip(self.fov_h_deg, self.fov_h_deg[1:])):
            raise ValueError("fov_h_deg must decrease strictly as zoom grows")
        return self


class FovealSection(Section):
    D_c: Metres = Field(description="floor distance from the omni axis to the PTZ, m")
    sigma_D_c: Metres
    theta_c_deg: Degrees = Field(description="azimuth of the PTZ around the omni axis, deg")
    sigma_theta_c_deg: SigmaDegrees
    H_f: PosMetres = Field(description="height of the PTZ's rotation centre, m")
    sigma_H_f: Metres
    pan_limits_deg: PanLimits
    tilt_limits_deg: TiltLimits
    image_size: Size
    zoom_range: Annotated[list[Zoom], Len(2, 2)]
    lens: LensSection
    profile: str | None = Field(None, description="device profile: a TOML file (relative to the rig) or a name "
                                                   "in configs/devices (optional; default: the command's)")

    @model_validator(mode="after")
    def _ranges(self):
        for key in ("pan_limits_deg", "tilt_limits_deg", "zoom_range"):
            lo, hi = getattr(self, key)
            if not lo < hi:
                raise ValueError(f"{key} must be [low, high] with low < high")
        if self.pan_limits_deg[1] - self.pan_limits_deg[0] > 360:
            raise ValueError(f"pan_limits_deg {self.pan_limits_deg} span more than one turn (360 deg)")
        if self.zoom_range[0] < self.lens.zoom[0] or self.zoom_range[1] > self.lens.zoom[-1]:
            raise ValueError(
                f"zoom_range {self.zoom_range} must lie inside the lens table "
                f"[{self.lens.zoom[0]}, {self.lens.zoom[-1]}]"
            )
        return self


class PersonSection(Section):
    H_p: PosMetres = Field(description="person height, m")
    sigma_H_p: Metres
    R_h: PosMetres = Field(description="head radius, m")
    sigma_R_h: Metres
    shoulder_width: PosMetres

    @model_validator(mode="after")
    def _head(self):
        if self.R_h >= self.H_p / 2:
            raise ValueError("R_h must be less than half of H_p")
        if self.shoulder_width >= self.H_p:
            raise ValueError(f"shoulder_width = {self.shoulder_width:g} m must be less than H_p = {self.H_p:g} m "
                             "(a person is taller than wide)")
        return self


class DetectionSection(Section):
    sensor_sigma: Annotated[float, within(0.0, MAX_GREY, "grey levels", open_low=True,
                                          why="an 8-bit image's whole range")] = Field(
        description="sensor noise per channel, grey levels")
    x_f: Prob = Field(description="false-alarm probability of a background radial line (eq 10)")
    x_m: Prob = Field(description="miss rate per person of contrast >= c_min")
    sigma_r_f: Pixels = Field(description="sigma of the foot radius of an aim without a detection, px")
    sigma_theta_f_deg: PosSigmaDegrees = Field(
        description="sigma of the foot azimuth of an aim without a detection, deg")
    sigma_gain_r_f: Annotated[float, Field(gt=0, le=100)] = Field(
        1.0, description="sigma rule: factor on the detector's sigma_r_f")
    sigma_extra_r_f: NonNegPixels = Field(0.0, description="sigma rule: independent foot-radius error, px")
    sigma_gain_theta_f: Annotated[float, Field(gt=0, le=100)] = Field(
        1.0, description="sigma rule: factor on the detector's sigma_theta_f")
    sigma_extra_theta_f_deg: SigmaDegrees = Field(0.0, description="sigma rule: independent azimuth error, deg")
    sigma_extra_r_f_per_m: Annotated[float, Field(ge=0, le=1000)] = Field(
        0.0, description="sigma rule: foot-radius error growing with the foot's floor distance, px per m")
    sigma_lateral_m: Annotated[float, Field(ge=0, le=10)] = Field(
        0.0, description="sigma rule: the foot's error across the line of sight, m (an azimuth error of "
                         "sigma_lateral_m / R at floor distance R)")
    height_share_r_f: Annotated[float, Field(ge=0, le=1)] = Field(
        0.0, description="sigma rule: a seen foot's coupling to the person's height, as a share of a foot "
                         "placed from the head's (d r_f / d H); 0: not coupled")
    height_share_head_r_f: Annotated[float, Field(ge=0, le=1)] = Field(
        1.0, description="sigma rule: a foot placed from the head's top with the prior's height, its coupling to "
                         "the person's height as a share of what the geometry says (d r_f / d H); 1: all of it")
    c_min: Annotated[float, within(0.0, MAX_CONTRAST, "a non-centrality per pixel", open_low=True,
                                   why="more than two 8-bit colours' chromaticities can differ by")] = Field(
        4.0, description="smallest person contrast (non-centrality per pixel) x_m holds for")
    n_theta: Annotated[int, Field(ge=36, le=4096)] = Field(360, description="radial lines")
    min_floor_radius: Metres = Field(0.3, description="floor radius under the camera left out, m")
    r_max: Pixels | None = Field(None, description="outer radius of the polar sampling, px (default: room)")
    max_people: Annotated[int, Field(ge=1, le=64)] = 8
    background_frames: Annotated[int, Field(ge=3, le=1000)] = Field(
        30, description="frames the background is learnt from, spread over background_seconds")
    background_seconds: Annotated[float, within(0.0, 3600.0, "seconds", why="an hour")] = Field(
        10.0, description="span of the learning frames, s (0: consecutive frames)")
    adapt_rate: Annotated[float, Field(ge=0, lt=1)] = Field(
        0.02, description="drift: update rate per frame of unchanged pixels outside every detection")
    still_s: Annotated[float, within(0.0, 60.0, "seconds", why="a minute")] = Field(
        0.3, description="a changed sample must stay still this long before a ghost's repair takes it, s")
    ghost_s: Annotated[float, within(0.0, 60.0, "seconds", why="a minute")] = Field(
        0.4, description="a changed sample inside a ghost (a detection with no object edge) this long is "
                         "re-learnt, s")
    floor_shows_s: Annotated[float, within(0.0, 60.0, "seconds", why="a minute")] = Field(
        1.0, description="a changed sample on a detection's lines still this long, where the frame continues "
                         "the floor beside the region and the background did not, gets a ghost's votes "
                         "whatever the region's verdict (someone learnt in who walks out along their line), s")
    ghost_edge: Annotated[float, within(0.0, 1e6, "a mean d^2", open_low=True,
                                        why="an edge so strong no object has it")] = Field(
        6.0, description="object-edge test: mean least d^2 across a person's edge below this is no edge")
    absorb_s: Annotated[float, within(0.0, 86400.0, "seconds", open_low=True, why="a day")] = Field(
        90.0, description="what stays changed and at rest this long, outside every trusted person, is "
                          "learnt as background, s")
    foot_mc_profiles: Annotated[int, Field(ge=16, le=4096)] = Field(
        256, description="Monte Carlo profiles per table cell of sigma_r_f")
    noise_margin: Annotated[float, within(1.0, 10.0, "times the measured noise",
                                          why="a margin ten times the noise sees nobody")] = Field(
        NOISE_MARGIN, description="d^2 compares the frame with the background against the sensor noise "
                                  "measured in the learning frames times this (1: the paper's d^2, chi-square(2) "
                                  "on the background; more: less sensitive); docs/detection.md, \"The sensor "
                                  "noise, measured where people walk\"")
    off_floor_m: Annotated[float, within(0.0, 100.0, "metres", why="larger than any room")] = Field(
        0.5, description="a detection whose foot lies farther than this outside the room's floor (beyond "
                         "the outline, or inside an excluded zone) is no person and is dropped, m")
    light_axis: Annotated[list[Annotated[float, within(-10.0, 10.0, "log RGB", why="a light e^10 times "
                                                       "redder than another")]], Len(3, 3)] | None = Field(
        None, description="lights of two colours (daylight and warm lamps): the direction in log RGB of a "
                          "change of the light's colour, e.g. log(lamp / daylight); d^2 leaves it out "
                          "(1 dof per pixel). Default: light of one colour, the paper's 2 dof")

    @field_validator("light_axis")
    @classmethod
    def _axis_has_colour(cls, v):
        if v is not None:
            m = sum(v) / 3.0
            if max(abs(x - m) for x in v) < 1e-3:
                raise ValueError("light_axis must change the light's colour, not only its brightness "
                                 f"(its three entries must differ; got {list(v)})")
        return v


class ZoomSection(Section):
    p_contain: Prob = Field(description="probability that the whole head is in the foveal frame")
    rule: ZoomRule = "calibrated"


class RoomSection(Section):
    outline: Polygon = Field(description="floor outline polygon [[x, y], ...] in m")
    exclude: list[Polygon] = Field(default_factory=list, description="excluded floor zones (optional, default none)")

    @model_validator(mode="after")
    def _areas(self):
        if _area(self.outline) < MIN_ROOM_AREA_M2:
            raise ValueError(f"outline encloses {_area(self.outline):.3g} m^2 of floor; expected a room "
                             f"(at least {MIN_ROOM_AREA_M2:g} m^2: its corners not all on one line)")
        return self


#: Landscape cells per varied variable when ``[layout] landscape`` is not given (by number varied).
LANDSCAPE_DEFAULT = {1: 31, 2: 15, 3: 7, 4: 5}
#: Most layouts the landscape may hold, and most floor points the objective may average over.
LANDSCAPE_MAX, FLOOR_POINTS_MAX = 20_000, 20_000


class LayoutSection(Section):
    vary: Annotated[list[Literal["D_c", "H_f", "theta_c", "H_o"]], Len(1, 4)] = Field(
        default_factory=lambda: ["D_c", "H_f"], description="placement variables to search"
    )
    objective: Literal["face_px", "variance"] = "face_px"
    statistic: Literal["mean", "worst"] = "mean"
    D_c: MetrePair | None = Field(None, description="bounds of D_c, m")
    H_f: MetrePair | None = Field(None, description="bounds of H_f, m")
    theta_c_deg: Annotated[list[Degrees], Len(2, 2)] | None = Field(None, description="bounds of theta_c, deg")
    H_o: MetrePair | None = Field(None, description="bounds of H_o, m (required to search H_o)")
    grid_step: Annotated[float, Field(ge=0.02, le=2.0)] = Field(0.25, description="floor grid spacing, m")
    near_radius: Annotated[float, Field(ge=0.1, le=MAX_LENGTH_M)] = Field(
        1.0, description="left out around the PTZ's foot, m")
    face_target_px: Pixels = Field(60.0, description="face width that bounds the operational region, px")
    starts: Annotated[int, Field(ge=1, le=32)] = 4
    landscape: Annotated[int, Field(ge=3, le=401)] | None = None

    @model_validator(mode="after")
    def _bounds(self):
        if len(set(self.vary)) != len(self.vary):
            raise ValueError(f"vary must not repeat a variable (got {self.vary})")
        for key in ("D_c", "H_f", "theta_c_deg", "H_o"):
            pair = getattr(self, key)
            if pair is not None and not pair[0] < pair[1]:
                raise ValueError(f"{key} must be [low, high] with low < high (got {pair})")
        if self.H_f is not None and self.H_f[0] <= 0:
            raise ValueError(f"H_f bounds must be > 0 m (got {self.H_f})")
        if self.theta_c_deg is not None and self.theta_c_deg[1] - self.theta_c_deg[0] > 360:
            raise ValueError(f"theta_c_deg bounds may span at most 360 deg (got {self.theta_c_deg})")
        if "H_o" in self.vary and self.H_o is None:
            raise ValueError("H_o bounds [low, high] are required when vary includes H_o")
        cells = (self.landscape or LANDSCAPE_DEFAULT[len(self.vary)]) ** len(self.vary)
        if cells > LANDSCAPE_MAX:
            raise ValueError(
                f"landscape^{len(self.vary)} = {cells} layouts is more than {LANDSCAPE_MAX}; lower landscape"
            )
        return self


class RigFile(Section):
    omni: OmniSection
    foveal: FovealSection
    person: PersonSection
    detection: DetectionSection
    zoom: ZoomSection
    room: RoomSection
    layout: LayoutSection = Field(default_factory=LayoutSection)
    zones: Annotated[list[ZoneSection], Len(0, MAX_ZONES)] = Field(
        default_factory=list, description="[[zones]] of the omni image (optional)")

    @model_validator(mode="after")
    def _geometry(self, info):  # info: pydantic.ValidationInfo (a Protocol the jaxtyping hook cannot check)
        """What no rig can be: the omni camera hangs from the ceiling looking down, so people stand
        below it and nothing the PTZ is mounted on is above it; a face is framed inside the PTZ's image.
        The PTZ's table is named as the context's ``foveal`` says (``foveal.1``: the second of several)."""
        fkey = (info.context or {}).get("foveal", "foveal")
        H_o = self.omni.H_o
        if self.person.H_p >= H_o:
            raise ValueError(
                f"person.H_p = {self.person.H_p} m must be below omni.H_o = {H_o} m"
            )
        if self.foveal.H_f > H_o:
            raise ValueError(
                f"{fkey}.H_f = {self.foveal.H_f:g} m is above the omni camera (omni.H_o = {H_o:g} m); the omni "
                "camera looks down from the ceiling, so the PTZ's pan/tilt centre cannot be above it"
            )
        if self.layout.H_o is not None and self.layout.H_o[0] <= self.person.H_p:
            raise ValueError(
                f"layout.H_o bounds {self.layout.H_o} must lie above person.H_p = {self.person.H_p} m"
            )
        top = max(H_o, self.layout.H_o[1] if self.layout.H_o is not None else H_o)
        if self.layout.H_f is not None and self.layout.H_f[1] > top:
            raise ValueError(
                f"layout.H_f bounds {self.layout.H_f} reach above the omni camera ({top:g} m); the PTZ's "
                "centre cannot be above it"
            )
        outline = self.room.outline
        off = _outside_by(outline, 0.0, 0.0)
        if off > WALL_TOLERANCE_M:
            raise ValueError(
                f"the omni camera's axis (the origin of room.outline) lies {off:.3g} m outside the room's outline; "
                f"expected it over the room (within {WALL_TOLERANCE_M:g} m of a wall): it sees the room from above"
            )
        theta = math.radians(self.foveal.theta_c_deg)
        D_c = self.foveal.D_c
        off = _outside_by(outline, D_c * math.cos(theta), D_c * math.sin(theta))
        if off > WALL_TOLERANCE_M:
            raise ValueError(
                f"{fkey}.D_c = {D_c:g} m at theta_c_deg = {self.foveal.theta_c_deg:g} puts the PTZ {off:.3g} m "
                f"outside the room's outline; expected it in the room or on a wall (within {WALL_TOLERANCE_M:g} m): "
                "from outside, the walls hide the room"
            )
        if self.layout.face_target_px > self.foveal.image_size[0]:
            raise ValueError(
                f"layout.face_target_px = {self.layout.face_target_px:g} px is wider than the PTZ's image "
                f"({fkey}.image_size {self.foveal.image_size[0]} px): no face can be that wide"
            )
        return self


# --------------------------------------------------------------------------------------
# Mapping -> Rig
# --------------------------------------------------------------------------------------


def _a(x) -> Array:
    """``x`` as a float array, converted on the host (on the device, a jax array of another dtype is a
    program to compile)."""
    return jnp.asarray(np.asarray(x, dtype=float))


def _omni_camera(sec: OmniSection, read_text: Callable[[str], str] | None, source: str) -> OmniCamera:
    if sec.model == "ocamcalib":
        if read_text is None:
            raise ConfigError(f"{source}: omni.calib_file: cannot read files here")
        try:
            calib = parse_ocamcalib(read_text(sec.calib_file))
        except OSError as exc:
            raise ConfigError(f"{source}: omni.calib_file: cannot read {sec.calib_file!r}: {exc.strerror}") from exc
        except ValueError as exc:
            raise ConfigError(f"{source}: omni.calib_file: {exc}") from exc
        profile = OCamCalib(ss=_a(calib.ss), invpol=_a(calib.invpol), rho0=calib.horizon_radius)
        width = calib.width + calib.crop_left + calib.crop_right
        size = tuple(sec.image_size) if sec.image_size else (width, calib.height)
        center = sec.center or [calib.center_col + calib.crop_left, calib.center_row]
        r_m = sec.r_m or calib.horizon_radius
        rim = sec.rim or calib.roi_max or r_m
        affine = calib.affine
    else:
        profile = PROFILES[sec.model]()
        size, center, r_m, affine = tuple(sec.image_size), sec.center, sec.r_m, (1.0, 0.0, 0.0)
        if sec.rim is not None:
            rim = sec.rim
        elif sec.fov_deg is not None:
            rim = float(r_m * profile.u(math.radians(sec.fov_deg) / 2))
        else:
            rim = r_m
    W, H = int(size[0]), int(size[1])
    if not (0 <= center[0] <= W and 0 <= center[1] <= H):
        raise ConfigError(
            f"{source}: omni.center: ({center[0]:g}, {center[1]:g}) px lies outside the {W}x{H} image "
            "(omni.image_size); the optical axis images inside the image"
        )
    return OmniCamera(
        profile=profile, center=_a(center), r_m=_a(r_m), rim=_a(rim), H_o=_a(sec.H_o),
        affine=_a(affine), image_size=(W, H),
    )


def _wall_distance(outline: np.ndarray, azimuth: float) -> float | None:
    """Distance from the omni axis along ``azimuth`` to the nearest crossing of the room's outline."""
    d = np.array([math.cos(azimuth), math.sin(azimuth)])
    a, b = outline, np.roll(outline, -1, axis=0)
    e = b - a
    denom = d[0] * e[:, 1] - d[1] * e[:, 0]
    ok = np.abs(denom) > 1e-12
    safe = np.where(ok, denom, 1.0)
    dist = (a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0]) / safe  # along the ray
    frac = (a[:, 0] * d[1] - a[:, 1] * d[0]) / safe  # along the edge
    hits = dist[ok & (dist > 1e-9) & (frac >= 0) & (frac <= 1)]
    return float(hits.min()) if hits.size else None


def _layout_search(f: RigFile, source: str) -> LayoutSearch:
    """The ``[layout]`` section with its defaults filled in from the rig (see configs/paper.toml)."""
    la, fo, pe = f.layout, f.foveal, f.person
    outline = np.asarray(f.room.outline, float)
    wall = _wall_distance(outline, math.radians(fo.theta_c_deg))
    reach = wall if wall is not None else float(np.hypot(outline[:, 0], outline[:, 1]).max())
    defaults = {
        "D_c": (min(0.25, fo.D_c), max(fo.D_c, reach)),
        "H_f": (min(fo.H_f, pe.H_p - pe.R_h - 0.5), max(fo.H_f, f.omni.H_o)),
        "theta_c": (math.radians(fo.theta_c_deg - 180.0), math.radians(fo.theta_c_deg + 180.0)),
        "H_o": (f.omni.H_o, f.omni.H_o),  # no default box: required when H_o is searched
    }
    given = {"D_c": la.D_c, "H_f": la.H_f, "H_o": la.H_o,
             "theta_c": None if la.theta_c_deg is None else [math.radians(v) for v in la.theta_c_deg]}
    bounds = [given[n] if given[n] is not None else defaults[n] for n in LAYOUT_NAMES]
    x0, x1 = outline.min(0), outline.max(0)
    points = math.prod(math.ceil((hi - lo) / la.grid_step) for lo, hi in zip(x0, x1))
    if points > FLOOR_POINTS_MAX:
        raise ConfigError(
            f"{source}: layout.grid_step: {la.grid_step} m gives about {points} floor points over the room's "
            f"bounding box, more than {FLOOR_POINTS_MAX}; expected a coarser step"
        )
    return LayoutSearch(
        vary=tuple(n for n in LAYOUT_NAMES if n in la.vary),
        lower=_a([b[0] for b in bounds]), upper=_a([b[1] for b in bounds]),
        objective=la.objective, statistic=la.statistic, grid_step=float(la.grid_step),
        near_radius=_a(la.near_radius), face_target_px=_a(la.face_target_px), starts=la.starts,
        landscape=la.landscape or LANDSCAPE_DEFAULT[len(la.vary)],
    )


#: Most PTZs a rig may have (``[[foveal]]`` tables).
MAX_PTZS = 8


def _rig_files(data: Mapping[str, Any], source: str) -> list[RigFile]:
    """The rig file validated once per PTZ: one ``[foveal]`` table, or each of the ``[[foveal]]`` tables
    in turn (its errors named ``foveal.I``)."""
    tables = data.get("foveal")
    if not isinstance(tables, list):
        return [validate(RigFile, data, source)]
    if not 1 <= len(tables) <= MAX_PTZS:
        raise ConfigError(f"{source}: foveal: expected 1 to {MAX_PTZS} [[foveal]] tables (PTZs), got {len(tables)}")
    files = []
    for i, table in enumerate(tables):
        key = f"foveal.{i}"
        files.append(validate(RigFile, {**data, "foveal": table}, source, context={"foveal": key},
                              rename={"foveal": key}))
    return files


def _foveal(fo: FovealSection) -> Foveal:
    lens = Lens(
        zoom=_a(fo.lens.zoom), fov_h=_a(np.radians(fo.lens.fov_h_deg)),
        zoom_range=_a(fo.zoom_range), image_size=(fo.image_size[0], fo.image_size[1]),
    )
    return Foveal(
        D_c=_a(fo.D_c), theta_c=_a(math.radians(fo.theta_c_deg)), H_f=_a(fo.H_f),
        pan_limits=_a(np.radians(fo.pan_limits_deg)), tilt_limits=_a(np.radians(fo.tilt_limits_deg)),
        lens=lens,
    )


def parse_rig(
    data: Mapping[str, Any], *, source: str = "config", read_text: Callable[[str], str] | None = None
) -> Rig:
    """Validate a parsed TOML mapping and build the :class:`Rig`.

    A rig has one ``[foveal]`` table or up to :data:`MAX_PTZS` ``[[foveal]]`` tables (several PTZs,
    each with its placement, sigmas, lens, limits and optional device profile); the first is
    ``Rig.foveal``, the others ``Rig.more_ptzs``, and every PTZ is checked against the room and
    the omni camera like a single one.
    ``read_text`` reads files the config names (the OCamCalib calibration), relative
    to the config; it is the only I/O, and the caller provides it.
    Raises :class:`ConfigError` with one line naming the key and what was expected.
    """
    files = _rig_files(data, source)
    f = files[0]
    omni = _omni_camera(f.omni, read_text, source)
    fo = f.foveal
    foveal = _foveal(fo)
    more = tuple(PTZ(foveal=_foveal(g.foveal), sigma_D_c=_a(g.foveal.sigma_D_c), sigma_H_f=_a(g.foveal.sigma_H_f),
                     sigma_theta_c=_a(math.radians(g.foveal.sigma_theta_c_deg))) for g in files[1:])
    pe = f.person
    person = Person(H_p=_a(pe.H_p), R_h=_a(pe.R_h), shoulder_width=_a(pe.shoulder_width))
    sigmas = Sigmas(
        H_o=_a(f.omni.sigma_H_o), H_f=_a(fo.sigma_H_f), D_c=_a(fo.sigma_D_c),
        theta_c=_a(math.radians(fo.sigma_theta_c_deg)), r_m=_a(f.omni.sigma_r_m),
        H_p=_a(pe.sigma_H_p), R_h=_a(pe.sigma_R_h),
    )
    de = f.detection
    detection = Detection(
        sensor_sigma=_a(de.sensor_sigma), x_f=_a(de.x_f), x_m=_a(de.x_m),
        sigma_r_f=_a(de.sigma_r_f), sigma_theta_f=_a(math.radians(de.sigma_theta_f_deg)),
        c_min=_a(de.c_min), adapt_rate=_a(de.adapt_rate), min_floor_radius=_a(de.min_floor_radius),
        n_theta=de.n_theta, max_people=de.max_people, background_frames=de.background_frames,
        foot_mc_profiles=de.foot_mc_profiles, r_max=de.r_max,
        sigma_gain_r_f=_a(de.sigma_gain_r_f), sigma_extra_r_f=_a(de.sigma_extra_r_f),
        sigma_gain_theta_f=_a(de.sigma_gain_theta_f),
        sigma_extra_theta_f=_a(math.radians(de.sigma_extra_theta_f_deg)),
        sigma_extra_r_f_per_m=_a(de.sigma_extra_r_f_per_m), sigma_lateral_m=_a(de.sigma_lateral_m),
        height_share_r_f=_a(de.height_share_r_f), height_share_head_r_f=_a(de.height_share_head_r_f),
        background_seconds=de.background_seconds, still_s=de.still_s, ghost_s=de.ghost_s,
        floor_shows_s=de.floor_shows_s,
        ghost_edge=de.ghost_edge, noise_margin=_a(de.noise_margin), absorb_s=de.absorb_s,
        off_floor_m=_a(de.off_floor_m),
        light_axis=None if de.light_axis is None else tuple(float(x) for x in de.light_axis),
    )
    room = Room(outline=_a(f.room.outline), exclude=tuple(_a(p) for p in f.room.exclude))
    return Rig(
        omni=omni, foveal=foveal, person=person, sigmas=sigmas, detection=detection, room=room,
        p_contain=_a(f.zoom.p_contain), layout=_layout_search(f, source), zoom_rule=f.zoom.rule,
        more_ptzs=more, ptz_profiles=tuple(g.foveal.profile for g in files),
        zones=zones_in_image(f.zones, omni.image_size, source),
    )
