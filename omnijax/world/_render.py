"""The omni renderer: inverse mapping from pixels to rays, a static background, people per frame.

Inverse mapping: pixel (x, y) -> ``omni.to_polar`` -> (r, theta) -> ``phi =
omni.angle(r)`` -> the ray from the single viewpoint (0, 0, H_o) with direction
(sin phi cos theta, sin phi sin theta, -cos phi), through the foundation's camera
model (any radial profile). Rays never change, so :func:`build_background`
casts them once per world (3 x 3 samples per pixel) and stores the room's
colour, each lamp's irradiance (with the furniture's shadows), the depth, and
the rays the people are drawn with.

Per frame (:func:`render_linear`) only the people are new: each is ray cast in
a fixed-size window of the image around it (``jax.lax.dynamic_slice``) with
``antialias^2`` rays per pixel, far people first so that nearer ones cover them
(along a ray from the camera the horizontal distance grows, and people's discs
are disjoint, so this order is the depth order); their cast shadows are found
on a grid ``shadow_downsample`` times coarser than the image and interpolated
(a soft penumbra). Under one spectrum, shadows and lamps only scale the light, so
chromaticity is unchanged in shadow; the light is then one plane per pixel and the
spectrum is folded into the background's colour. When a lamp has a spectrum of its
own, light, shadows and the people's shading are computed per colour channel, each
lamp weighted by its spectrum. All per-pixel work is float32.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Float, Int

from ..camera import OmniCamera
from ..geometry import world_to_image
from ._image import own_buffer, upsample
from ._people import People, ShadowRays, blocks, body, body_albedo, body_distance, hit_body, shadow_rays
from ._scenario import Screens
from ._scene import Room3D, albedo, f32, intersect_room, lamp_irradiance, lit, on_screen

#: Rays per pixel (per axis) of the static background.
BACKGROUND_SAMPLES = 3
#: Rows of the image cast at once while building the background (bounds memory).
BLOCK_ROWS = 8
#: Points around a person's outline used for its image bounding box.
HULL_POINTS = 24


def omni_rays(omni: OmniCamera, x, y) -> tuple[Array, Array]:
    """Unit ray directions (..., 3) of pixels (x, y) through the omni camera model, and
    whether each pixel lies inside the usable image circle (``r <= rim``)."""
    r, theta = omni.to_polar(x, y)
    phi = omni.angle(r)
    s = jnp.sin(phi)
    d = jnp.stack([s * jnp.cos(theta), s * jnp.sin(theta), -jnp.cos(phi)], axis=-1)
    return d, r <= omni.rim


class OmniBackground(eqx.Module):
    """Everything static about the omni view of one world (float32).

    ``colour`` albedo x ``spectrum`` x gain; ``irradiance`` per lamp (grey levels for
    albedo 1, furniture shadows included); ``depth`` distance to the room along
    each pixel's central ray (m); ``gain`` vignetting times the pixel's share
    inside the image circle; ``rays`` the people's sample rays (``antialias^2``
    per pixel; sample, component, row, column); ``shadow`` the segments from the coarse
    grid's surface points (cells inside the image circle only, packed) to each lamp,
    ``shadow_irradiance`` each lamp's mean irradiance over those cells, and
    ``shadow_index`` the packed index of each grid cell (``n`` outside the circle);
    ``screen_cover`` the share of each pixel's samples on each self-lit screen, times
    ``gain`` (the screens' albedo counts as zero in ``colour``: they emit instead).

    Spectra: when every lamp has the ambient light's spectrum, ``spectrum`` is that
    spectrum (folded into ``colour``) and ``lamp_spectrum`` and ``ambient_spectrum`` are
    None: light is one plane, computed as it always was. Otherwise ``spectrum`` is ones
    (3,), ``lamp_spectrum`` the lamps' spectra (k, 3) and ``ambient_spectrum`` the ambient
    light's (3,): light is three planes, one per channel.
    """

    colour: Float[Array, "H W 3"]
    irradiance: Float[Array, "k H W"]
    depth: Float[Array, "H W"]
    gain: Float[Array, "H W"]
    screen_cover: Float[Array, "screens H W"]
    rays: Float[Array, "s 3 H W"]
    shadow: ShadowRays
    shadow_irradiance: Float[Array, "k n"]
    shadow_index: Int[Array, "h w"]
    eye: Float[Array, "3"]
    lamps: Float[Array, "k 3"]
    intensity: Float[Array, " k"]
    spectrum: Float[Array, "3"]
    lamp_spectrum: Float[Array, "k 3"] | None
    ambient_spectrum: Float[Array, "3"] | None
    window: tuple[int, int] = eqx.field(static=True)
    antialias: int = eqx.field(static=True)
    downsample: int = eqx.field(static=True)

    @property
    def size(self) -> tuple[int, int]:
        """Image (height, width)."""
        return self.depth.shape

    def light_weights(self, lamp_light: Float[Array, " k"]) -> Float[Array, "k s"]:
        """Each lamp's scale (on x drift) times its spectrum per light plane: (k, 3), or the
        scale alone (k, 1) under one spectrum."""
        if self.lamp_spectrum is None:
            return lamp_light[:, None]
        return lamp_light[:, None] * self.lamp_spectrum

    def ambient_light(self, ambient) -> tuple[Array, ...]:
        """The ambient grey level per light plane."""
        if self.ambient_spectrum is None:
            return (ambient,)
        return tuple(ambient * self.ambient_spectrum[c] for c in range(3))


def _sample_offsets(n: int) -> np.ndarray:
    return (np.arange(n) + 0.5) / n - 0.5


def _background_rows(omni, room: Room3D, screens: Screens, lamps, intensity, vignetting, row0, n_rows: int,
                     width: int):
    """Colour, irradiance, depth, gain and screen cover of ``n_rows`` image rows starting at ``row0``."""
    n = BACKGROUND_SAMPLES
    off = jnp.asarray(_sample_offsets(n))
    y = (row0 + jnp.arange(n_rows))[:, None, None, None] + off[None, :, None, None]
    x = jnp.arange(width)[None, None, :, None] + off[None, None, None, :]
    d, inside = omni_rays(omni, x, y)
    d = d.astype(jnp.float32)
    eye = jnp.array([0.0, 0.0, 1.0], jnp.float32) * omni.H_o.astype(jnp.float32)
    hit = intersect_room(room, eye, d)
    alb = albedo(room, hit)
    e = lamp_irradiance(room, hit.point, hit.normal, lamps, intensity)
    w = inside.astype(jnp.float32)
    cover = w.mean(axis=(1, 3))
    safe = jnp.maximum(cover, 1e-6)
    screen = on_screen(screens, hit) * w[..., None]  # (rows, n, cols, n, screens)
    if screens.size:
        alb = alb * (1.0 - jnp.max(screen, axis=-1))[..., None]
    screen_cover = jnp.moveaxis(screen.mean(axis=(1, 3)) / safe[..., None], -1, 0)
    colour = (alb * w[..., None]).mean(axis=(1, 3)) / safe[..., None]
    irr = (e * w[..., None]).mean(axis=(1, 3)) / safe[..., None]
    c = n // 2  # the central sample (n is odd)
    depth = hit.t[:, c, :, c]
    r, _ = omni.to_polar(jnp.arange(width)[None, :], (row0 + jnp.arange(n_rows))[:, None])
    gain = cover * (1.0 - vignetting * (r / omni.rim) ** 2)
    return colour, jnp.moveaxis(irr, -1, 0), depth, gain.astype(jnp.float32), screen_cover


def _shadow_starts(omni, room: Room3D, h: int, w: int, s: int) -> Float[Array, "h w 3"]:
    """Surface points seen through the centres of the coarse shadow grid's cells, lifted off the
    surface (the camera's viewpoint where nothing is hit)."""
    y = (jnp.arange(h) + 0.5) * s - 0.5
    x = (jnp.arange(w) + 0.5) * s - 0.5
    d, _ = omni_rays(omni, x[None, :], y[:, None])
    eye = jnp.array([0.0, 0.0, 1.0], jnp.float32) * omni.H_o.astype(jnp.float32)
    hit = intersect_room(room, eye, d.astype(jnp.float32))
    return jnp.where(jnp.isfinite(hit.t)[..., None], hit.point + 1e-3 * hit.normal, eye)


@eqx.filter_jit
def _static_view(omni, room: Room3D, screens: Screens, lamps, intensity, vignetting, antialias: int,
                 downsample: int):
    """Colour, irradiance, depth, gain, screen cover and the people's rays of the whole image, cast in
    blocks of rows, and the coarse shadow grid's surface points."""
    width, height = omni.image_size

    def rows(r0):
        colour, irr, depth, gain, screen = _background_rows(omni, room, screens, lamps, intensity, vignetting, r0,
                                                            BLOCK_ROWS, width)
        return colour, irr, depth, gain, screen, _people_rays(omni, r0, BLOCK_ROWS, width, antialias)

    starts = jnp.arange(0, height, BLOCK_ROWS, dtype=jnp.int32)
    colour, irr, depth, gain, screen, rays = lax.map(rows, starts)

    def join(x, axis=0):  # (blocks, ..., rows, ...) -> (..., the image's rows, ...)
        x = jnp.moveaxis(x, 0, axis)
        rows = x.shape[axis] * x.shape[axis + 1]  # not -1: a screen cover of no screens is empty
        return x.reshape(*x.shape[:axis], rows, *x.shape[axis + 2:])[(slice(None),) * axis + (slice(0, height),)]

    starts = _shadow_starts(omni, room, -(-height // downsample), -(-width // downsample), downsample)
    return join(colour), join(irr, 1), join(depth), join(gain), join(screen, 1), join(rays, 2), starts


def _block_mean(x: np.ndarray, s: int) -> np.ndarray:
    """Means over s x s blocks of the last two axes (NumPy; padded with edge values to a multiple of s)."""
    H, W = x.shape[-2:]
    h, w = -(-H // s), -(-W // s)
    x = np.pad(x, [(0, 0)] * (x.ndim - 2) + [(0, h * s - H), (0, w * s - W)], mode="edge")
    return x.reshape(*x.shape[:-2], h, s, w, s).mean(axis=(-3, -1))


def _people_rays(omni, row0, n_rows: int, width: int, a: int):
    """The ``a x a`` sample rays of each pixel of ``n_rows`` rows: (a^2, 3, n_rows, width)."""
    off = jnp.asarray(_sample_offsets(a))
    y = (row0 + jnp.arange(n_rows))[None, None, :, None] + off[:, None, None, None]
    x = jnp.arange(width)[None, None, None, :] + off[None, :, None, None]
    shape = (a, a, n_rows, width)
    d, _ = omni_rays(omni, jnp.broadcast_to(x, shape), jnp.broadcast_to(y, shape))
    return jnp.moveaxis(d, -1, 2).reshape(a * a, 3, n_rows, width).astype(jnp.float32)


def build_background(omni: OmniCamera, room: Room3D, screens: Screens, lamps, intensity, spectrum, lamp_spectrum,
                     vignetting, window: tuple[int, int], antialias: int, downsample: int) -> OmniBackground:
    """Cast every pixel's rays once and store the static view of the room (see :class:`OmniBackground`).

    ``screens`` the self-lit screens on the walls, ``lamps`` (k, 3) m, ``intensity`` (k,) grey
    levels at 1 m, ``spectrum`` (3,) the ambient light's, ``lamp_spectrum`` (k, 3) the lamps'
    (one light plane when they all equal ``spectrum``, three otherwise), ``vignetting`` (relative darkening at the rim),
    ``window`` the people's
    window (rows, columns) in pixels. Rows are cast in blocks of ``BLOCK_ROWS``
    (``lax.map``) to bound memory.
    """
    width, height = omni.image_size
    lamps, intensity, spectrum, lamp_spectrum = f32(lamps), f32(intensity), f32(spectrum), f32(lamp_spectrum)
    k = lamps.shape[0]
    if np.array_equal(np.asarray(lamp_spectrum), np.broadcast_to(np.asarray(spectrum), (k, 3))):
        lamp_spectrum, ambient_spectrum = None, None
    else:
        ambient_spectrum, spectrum = spectrum, jnp.ones((3,), jnp.float32)
    colour, irr, depth, gain, screen, rays, starts = _static_view(omni, room, f32(screens), lamps, intensity,
                                                                  jnp.float32(vignetting), antialias, downsample)
    h, w = starts.shape[:2]
    g = np.pad(np.asarray(gain), ((0, h * downsample - height), (0, w * downsample - width)))
    inside = g.reshape(h, downsample, w, downsample).max(axis=(1, 3)) > 0
    cells = np.argwhere(inside)
    index = np.full((h, w), len(cells), np.int32)
    index[cells[:, 0], cells[:, 1]] = np.arange(len(cells), dtype=np.int32)
    start = np.asarray(starts)[cells[:, 0], cells[:, 1]]
    to_lamp = np.asarray(lamps)[:, None, :] - start[None]
    coarse = _block_mean(np.asarray(irr), downsample)[:, cells[:, 0], cells[:, 1]]
    shadow = shadow_rays(jnp.asarray(np.broadcast_to(start[None], to_lamp.shape)), jnp.asarray(to_lamp))
    return OmniBackground(
        colour=colour * spectrum * gain[..., None], irradiance=irr, depth=depth, gain=gain,
        screen_cover=screen * gain, rays=rays,
        shadow=shadow, shadow_irradiance=jnp.asarray(coarse, jnp.float32), shadow_index=jnp.asarray(index),
        eye=jnp.array([0.0, 0.0, 1.0], jnp.float32) * f32(omni.H_o),
        lamps=lamps, intensity=intensity, spectrum=spectrum, lamp_spectrum=lamp_spectrum,
        ambient_spectrum=ambient_spectrum, window=window, antialias=antialias, downsample=downsample,
    )


# --------------------------------------------------------------------------------------
# People's image footprint
# --------------------------------------------------------------------------------------


def hull(foot: Float[Array, "*b 2"], radius, shoulder, head_z, R_h) -> Float[Array, "*b n 3"]:
    """World points on a person's outline: rims of the body's base and top, the head's equator, the crown."""
    a = jnp.linspace(0.0, 2 * jnp.pi, HULL_POINTS, endpoint=False)
    ring = jnp.stack([jnp.cos(a), jnp.sin(a)], axis=-1)
    foot = jnp.asarray(foot)
    col = lambda v: jnp.broadcast_to(jnp.asarray(v, foot.dtype), foot.shape[:-1])[..., None, None]
    radius, shoulder, head_z, R_h = col(radius), col(shoulder), col(head_z), col(R_h)
    f = foot[..., None, :]

    def circle(r, z):
        xy = f + r * ring
        return jnp.concatenate([xy, jnp.broadcast_to(z, xy[..., :1].shape)], axis=-1)

    crown = jnp.concatenate([f, head_z + R_h], axis=-1)
    rings = [circle(radius, 0.0 * radius), circle(radius, shoulder), circle(R_h, head_z), crown]
    return jnp.concatenate(rings, axis=-2)


def image_box(omni: OmniCamera, points: Float[Array, "*b n 3"]) -> Float[Array, "*b 4"]:
    """Bounding box (x0, y0, x1, y1) in pixels of world points' images."""
    x, y = world_to_image(omni, points[..., 0], points[..., 1], points[..., 2])
    return jnp.stack([x.min(-1), y.min(-1), x.max(-1), y.max(-1)], axis=-1)


@eqx.filter_jit
def _largest_box(omni: OmniCamera, xy, ok, radius, shoulder, head_z, R_h):
    box = image_box(omni, hull(xy, radius, shoulder, head_z, R_h))
    size = jnp.where(ok[..., None], box[..., 2:] - box[..., :2], 0.0)
    return size.reshape(-1, 2).max(axis=0)


def window_size(omni: OmniCamera, xy: ArrayLike, ok: ArrayLike, radius: ArrayLike, shoulder: ArrayLike,
                head_z: ArrayLike, R_h: ArrayLike) -> tuple[int, int]:
    """Smallest window (rows, columns) that holds the image of the largest person anywhere on the walkable floor.

    ``xy`` (..., 2) samples the floor, ``ok`` marks the walkable samples; 4 pixels of
    margin on each side cover positions between samples. Columns are rounded up to a
    multiple of 8.
    """
    w, h = (int(math.ceil(float(v))) + 8 for v in _largest_box(omni, xy, ok, radius, shoulder, head_z, R_h))
    width, height = omni.image_size
    return min(h, height), min(-(-w // 8) * 8, width)


# --------------------------------------------------------------------------------------
# One frame
# --------------------------------------------------------------------------------------


def shadow_factor(bg: OmniBackground, people: People, foot: Float[Array, "p 2"],
                  weight: Float[Array, "k s"]) -> tuple[Float[Array, "H W"], ...]:
    """The share of the lamps' light that reaches each pixel's surface past the people
    (1 where nobody casts a shadow), per light plane c, found on the coarse grid as
    ``sum_k w_kc E_k lit_k / sum_k w_kc E_k`` (``weight`` w: :meth:`OmniBackground.light_weights`)
    and interpolated bilinearly (a soft penumbra). With lamps of different spectra the
    share differs between channels: a shadow changes the light's colour."""
    lit = jnp.ones(bg.shadow.inv.shape, bool)
    for i in range(people.count):
        lit = lit & ~blocks(body(people, i, foot[i]), bg.shadow)
    h, w = bg.size
    planes = []
    for c in range(weight.shape[1]):
        e = bg.shadow_irradiance * weight[:, c, None]
        total = jnp.sum(e, axis=0)
        share = jnp.where(total > 0, jnp.sum(jnp.where(lit, e, 0.0), axis=0) / jnp.where(total > 0, total, 1.0), 1.0)
        grid = jnp.concatenate([share, jnp.ones((1,), share.dtype)])[bg.shadow_index]
        planes.append(upsample(grid, bg.downsample)[:h, :w])
    return tuple(planes)


def _window_origin(bg: OmniBackground, box: Float[Array, "4"]) -> Int[Array, "2"]:
    """(row, column) of the people's window centred on an image box, kept inside the image."""
    h, w = bg.size
    wh, ww = bg.window
    cy, cx = 0.5 * (box[1] + box[3]), 0.5 * (box[0] + box[2])
    oy = jnp.clip(jnp.round(cy - 0.5 * (wh - 1)), 0, h - wh)
    ox = jnp.clip(jnp.round(cx - 0.5 * (ww - 1)), 0, w - ww)
    return jnp.stack([oy, ox]).astype(jnp.int32)


def draw_person(bg: OmniBackground, people: People, i, foot: Float[Array, "2"], facing: Float[Array, "2"],
                lamp_light: Float[Array, " k"], ambient, origin: Int[Array, "2"]) -> tuple[Array, Array]:
    """Ray cast person ``i`` in the window at ``origin`` (row, column).

    Multisample anti-aliasing: the coverage of each pixel comes from ``antialias^2``
    rays (hidden where the room, e.g. furniture, is nearer); the colour is shaded once
    per pixel, on the first of its rays that sees the person: albedo x gain x
    (ambient x ambient spectrum + sum_k lamp_light_k lambert_k spectrum_k), per light
    plane (see :class:`OmniBackground`). Returns the premultiplied colour and the coverage."""
    a2 = bg.antialias**2
    wh, ww = bg.window
    b = body(people, i, foot)
    rays, depth, gain = own_buffer(
        (lax.dynamic_slice(bg.rays, jnp.concatenate([jnp.zeros((2,), origin.dtype), origin]), (a2, 3, wh, ww)),
         lax.dynamic_slice(bg.depth, origin, (wh, ww)), lax.dynamic_slice(bg.gain, origin, (wh, ww))),
        origin[0] >= 0)
    d = (rays[:, 0], rays[:, 1], rays[:, 2])
    eye = (bg.eye[0], bg.eye[1], bg.eye[2])
    seen = own_buffer(body_distance(b, eye, d) < depth, origin[0] >= 0)  # else recomputed per use
    cover = sum(seen[k].astype(jnp.float32) for k in range(a2)) / a2 * (gain > 0)  # not a reduce: XLA's is slow
    rep = tuple(c[a2 - 1] for c in d)
    for k in reversed(range(a2 - 1)):
        rep = tuple(jnp.where(seen[k], c[k], r) for c, r in zip(d, rep))
    hit = hit_body(b, eye, rep)
    ts = jnp.where(jnp.isfinite(hit.t), hit.t, 0.0)
    p = tuple(o + ts * c for o, c in zip(eye, rep))
    lamp = lit(p, (hit.nx, hit.ny, hit.nz), bg.lamps, bg.intensity, bg.light_weights(lamp_light))
    scale = [(a + e) * cover * gain for a, e in zip(bg.ambient_light(ambient), lamp)]
    col = tuple(alb * scale[c % len(scale)] * bg.spectrum[c]
                for c, alb in enumerate(body_albedo(people, i, hit, facing)))
    col, cover = own_buffer((col, cover), origin[0] >= 0)  # stacking would recompute the shading per channel
    return jnp.stack(col, axis=-1), cover


class LinearFrame(eqx.Module):
    """A noise-free frame in grey levels (float32), which person covers each pixel most
    (-1: nobody), and each person's window origin and covered area (pixels)."""

    image: Float[Array, "H W 3"]
    labels: Int[Array, "H W"]
    origin: Int[Array, "p 2"]
    area: Float[Array, " p"]


def render_linear(omni: OmniCamera, bg: OmniBackground, people: People, foot: Float[Array, "p 2"],
                  facing: Float[Array, "p 2"], lamp_light: Float[Array, " k"], ambient,
                  screen: Float[Array, "screens 3"]) -> LinearFrame:
    """One noise-free omni frame in grey levels (float32): the background lit by the lamps
    (``lamp_light`` scales each lamp's intensity: on/off times drift; each lamp of its own
    spectrum) and ``ambient`` (grey levels, drift included), minus the people's cast shadows,
    plus the light each self-lit screen emits (``screen``, grey levels), with the people drawn
    over it far to near."""
    foot32 = foot.astype(jnp.float32)
    facing32 = facing.astype(jnp.float32)
    weight = bg.light_weights(lamp_light)
    share = shadow_factor(bg, people, foot32, weight)
    ambient_light = bg.ambient_light(ambient)
    light = []
    for c in range(weight.shape[1]):
        lamps = jnp.zeros(bg.size, jnp.float32)
        for k in range(bg.lamps.shape[0]):
            lamps = lamps + weight[k, c] * bg.irradiance[k]
        light.append(ambient_light[c] + lamps * share[c])
    image = bg.colour * jnp.stack(light, axis=-1)
    for i in range(bg.screen_cover.shape[0]):
        image = image + bg.screen_cover[i, ..., None] * screen[i].astype(jnp.float32)
    labels = jnp.full(bg.size, -1, jnp.int32)
    n = people.count
    if n == 0:
        return LinearFrame(image=image, labels=labels, origin=jnp.zeros((0, 2), jnp.int32),
                           area=jnp.zeros((0,), jnp.float32))
    wh, ww = bg.window
    boxes = image_box(omni, hull(foot, people.radius, people.shoulder, people.head_z, people.R_h))
    origin = jax.vmap(lambda box: _window_origin(bg, box))(boxes)
    order = jnp.argsort(-jnp.hypot(foot[:, 0], foot[:, 1]))  # far to near

    def draw(j, acc):
        image, labels = acc
        i = order[j]
        o = origin[i]
        o3 = jnp.concatenate([o, jnp.zeros((1,), o.dtype)])
        col, cover = draw_person(bg, people, i, foot32[i], facing32[i], lamp_light, ambient, o)
        window = col + (1.0 - cover[..., None]) * lax.dynamic_slice(image, o3, (wh, ww, 3))
        lab = jnp.where(cover >= 0.5, i.astype(jnp.int32), lax.dynamic_slice(labels, o, (wh, ww)))
        window, lab = own_buffer((window, lab), o[0] >= 0)  # then the updates below happen in place
        return lax.dynamic_update_slice(image, window, o3), lax.dynamic_update_slice(labels, lab, o)

    image, labels = lax.fori_loop(0, n, draw, (image, labels))
    area = jax.vmap(lambda i, o: jnp.sum(lax.dynamic_slice(labels, o, (wh, ww)) == i))(jnp.arange(n), origin)
    return LinearFrame(image=image, labels=labels, origin=origin, area=area.astype(jnp.float32))
