"""The static room of the synthetic world: ray casting, procedural textures, lamp irradiance.

The room stands on the rig's floor outline (``rig.room.outline``): a floor at
z = 0, vertical walls along the outline's edges up to the ceiling at the
scenario's ``room.height``, and furniture boxes on the floor. Rays are
``origin + t * direction`` in the world frame of docs/design.md section 3.1 (metres,
z up); ``direction`` need not be unit length, and ``t`` is in its units.

Light (see ``_scenario``): the grey level of a surface point is
``albedo * (ambient spectrum + sum_k on_k E_k spectrum_k)``, with ``E_k`` the
lamp's intensity times the cosine of incidence over the squared distance, zero
where a wall or a furniture box blocks the lamp. When all lamps and the ambient
light share one spectrum, this is ``albedo * spectrum * (ambient + sum_k on_k E_k)``:
shadows and switching scale a pixel's colour and keep its chromaticity (the
paper's assumption); a lamp of another spectrum (daylight beside lamps) breaks it.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int, UInt32

from ..config import Rig
from ._noise import derive_key, lattice_uniform, value_noise
from ._scenario import Scenario, Screens, Surface

FLOOR, CEILING, WALL, FURNITURE = 0, 1, 2, 3
#: Offset (m) that lifts shadow rays off their surface, and the smallest accepted hit distance.
EPS = 1e-4
#: Relative amplitude of the furniture's fine texture.
FURNITURE_TEXTURE = 0.04


#: A vector field as its three component arrays (x, y, z): per-pixel work on planes stays
#: vectorised, where arrays with a trailing axis of 3 make XLA's CPU loops gather.
XYZ = tuple[Array, Array, Array]


def xyz(v: Float[Array, "*b 3"]) -> XYZ:
    """The components of an array of 3-vectors."""
    return v[..., 0], v[..., 1], v[..., 2]


class Room3D(eqx.Module):
    """Geometry and looks of the static room, as arrays (float32) for per-pixel work."""

    wall_a: Float[Array, "n 2"]
    wall_b: Float[Array, "n 2"]
    height: Float[Array, ""]
    box_lo: Float[Array, "m 3"]
    box_hi: Float[Array, "m 3"]
    box_colour: Float[Array, "m 3"]
    floor: Surface
    walls: Surface
    ceiling: Float[Array, "3"]
    skirting_colour: Float[Array, "3"]
    skirting_height: Float[Array, ""]
    key: UInt32[Array, "2"]


def build_room(rig: Rig, scenario: Scenario, key: UInt32[Array, "2"], arrangement: int = 0) -> Room3D:
    """The room of ``scenario`` on ``rig``'s floor outline with the furniture in its
    ``arrangement`` (see :class:`Furniture`); ``key`` seeds the textures."""
    outline = np.asarray(rig.room.outline)
    fu = scenario.furniture
    lo, hi = fu.placed(arrangement)
    zeros = np.zeros((fu.count, 1))
    return Room3D(
        wall_a=f32(outline), wall_b=f32(np.roll(outline, -1, axis=0)), height=f32(scenario.height),
        box_lo=f32(np.concatenate([np.asarray(lo), zeros], axis=1)),
        box_hi=f32(np.concatenate([np.asarray(hi), np.asarray(fu.height)[:, None]], axis=1)),
        box_colour=f32(fu.colour), floor=f32(scenario.floor), walls=f32(scenario.walls),
        ceiling=f32(scenario.ceiling), skirting_colour=f32(scenario.skirting_colour),
        skirting_height=f32(scenario.skirting_height), key=key,
    )


def f32(tree):
    """``tree`` (an array, a number or a PyTree of them) with every floating array as float32."""
    def cast(x):
        x = jnp.asarray(x)
        return x.astype(jnp.float32) if jnp.issubdtype(x.dtype, jnp.floating) else x

    return jax.tree.map(cast, tree)


class Hit(eqx.Module):
    """Nearest intersection of rays with the room: distance ``t`` (inf: none), point, normal
    (facing the ray), surface kind (FLOOR, CEILING, WALL, FURNITURE), wall or box index,
    and ``u`` (m along the wall from its first corner; 0 elsewhere)."""

    t: Float[Array, "*b"]
    point: Float[Array, "*b 3"]
    normal: Float[Array, "*b 3"]
    surface: Int[Array, "*b"]
    index: Int[Array, "*b"]
    u: Float[Array, "*b"]


def dot3(a: Float[Array, "*a 3"], b: Float[Array, "*b 3"]) -> Array:
    """Dot product over the last axis (of length 3; other axes broadcast), written out: XLA's
    CPU reductions over a 3-long minor axis are several times slower than the sum of products."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross2(ax, ay, bx, by):
    return ax * by - ay * bx


def _planes(origin, direction, room: Room3D):
    """Distances to the floor (z = 0) and the ceiling, inf where the ray does not reach them."""
    oz, dz = origin[..., 2], direction[..., 2]
    safe = jnp.where(dz == 0, 1.0, dz)
    t_floor = jnp.where(dz < 0, -oz / safe, jnp.inf)
    t_ceil = jnp.where(dz > 0, (room.height - oz) / safe, jnp.inf)
    return t_floor, t_ceil


def _walls(origin, direction, room: Room3D):
    """Distance to each wall (..., n) and the position along it (m), inf where missed."""
    ox, oy = origin[..., 0, None], origin[..., 1, None]
    dx, dy = direction[..., 0, None], direction[..., 1, None]
    ex, ey = room.wall_b[:, 0] - room.wall_a[:, 0], room.wall_b[:, 1] - room.wall_a[:, 1]
    ax, ay = room.wall_a[:, 0] - ox, room.wall_a[:, 1] - oy
    den = _cross2(dx, dy, ex, ey)
    ok = jnp.abs(den) > 1e-12
    den = jnp.where(ok, den, 1.0)
    t = _cross2(ax, ay, ex, ey) / den
    s = _cross2(ax, ay, dx, dy) / den
    z = origin[..., 2, None] + t * direction[..., 2, None]
    hit = ok & (s >= 0) & (s <= 1) & (t > EPS) & (z >= 0) & (z <= room.height)
    return jnp.where(hit, t, jnp.inf), s * jnp.hypot(ex, ey)


def _boxes(origin, direction, lo, hi):
    """Slab test against boxes (m, 3): entry distance (..., m) (inf where missed) and entry axis."""
    o, d = origin[..., None, :], direction[..., None, :]
    inside = (o >= lo) & (o <= hi)
    safe = jnp.where(d == 0, 1.0, d)
    t1, t2 = (lo - o) / safe, (hi - o) / safe
    t_near = jnp.where(d == 0, jnp.where(inside, -jnp.inf, jnp.inf), jnp.minimum(t1, t2))
    t_far = jnp.where(d == 0, jnp.where(inside, jnp.inf, -jnp.inf), jnp.maximum(t1, t2))
    t_in, t_out = jnp.max(t_near, axis=-1), jnp.min(t_far, axis=-1)
    hit = (t_in <= t_out) & (t_in > EPS)
    return jnp.where(hit, t_in, jnp.inf), jnp.argmax(t_near, axis=-1)


def intersect_room(room: Room3D, origin: Float[Array, "*o 3"], direction: Float[Array, "*d 3"]) -> Hit:
    """Nearest hit of the rays ``origin + t direction`` (t > EPS; the two broadcast) with floor,
    ceiling, walls and boxes."""
    origin, direction = jnp.broadcast_arrays(origin, direction)
    t_floor, t_ceil = _planes(origin, direction, room)
    t_wall, s_wall = _walls(origin, direction, room)
    t_box, axis = _boxes(origin, direction, room.box_lo, room.box_hi)
    cand = jnp.concatenate([t_floor[..., None], t_ceil[..., None], t_wall, t_box], axis=-1)
    k = jnp.argmin(cand, axis=-1)
    t = jnp.min(cand, axis=-1)
    n_wall = room.wall_a.shape[0]
    surface = jnp.where(k == 0, FLOOR, jnp.where(k == 1, CEILING, jnp.where(k < 2 + n_wall, WALL, FURNITURE)))
    index = jnp.where(surface == WALL, k - 2, jnp.where(surface == FURNITURE, k - 2 - n_wall, 0))
    point = origin + jnp.where(jnp.isfinite(t), t, 0.0)[..., None] * direction
    # normals: floor up, ceiling down, walls and box faces turned towards the ray
    e = room.wall_b - room.wall_a
    wall_n = jnp.stack([e[:, 1], -e[:, 0], jnp.zeros_like(e[:, 0])], -1) / jnp.hypot(e[:, 0], e[:, 1])[:, None]
    n_w = wall_n[jnp.clip(index, 0, n_wall - 1)]
    if room.box_lo.shape[0]:
        box_axis = jnp.take_along_axis(axis, index[..., None], -1)[..., 0]
    else:
        box_axis = jnp.zeros_like(index)
    n_b = (jnp.arange(3) == box_axis[..., None]).astype(direction.dtype)
    up = jnp.array([0.0, 0.0, 1.0], direction.dtype)
    normal = jnp.where((surface == FLOOR)[..., None], up,
                       jnp.where((surface == CEILING)[..., None], -up,
                                 jnp.where((surface == WALL)[..., None], n_w, n_b)))
    normal = jnp.where(dot3(normal, direction)[..., None] > 0, -normal, normal)
    wall_s = jnp.take_along_axis(s_wall, jnp.clip(k - 2, 0, n_wall - 1)[..., None], -1)[..., 0]
    u = jnp.where(surface == WALL, wall_s, 0.0)
    return Hit(t=t, point=point, normal=normal, surface=surface, index=index, u=u)


def surface_albedo(surface: Surface, key: UInt32[Array, "2"], u, v) -> Float[Array, "*b 3"]:
    """Albedo of a (possibly tiled) textured surface at surface coordinates (u, v) in metres."""
    tile = jnp.maximum(surface.tile, 1e-6)
    iu, iv = jnp.floor(u / tile), jnp.floor(v / tile)
    fu, fv = u - iu * tile, v - iv * tile
    tiled = surface.tile > 0
    grout = tiled & ((fu < surface.grout) | (fv < surface.grout))
    tile_u = lattice_uniform(key, iu.astype(jnp.int32), iv.astype(jnp.int32))
    tile_factor = 1.0 + jnp.where(tiled, surface.tile_variation * (2.0 * tile_u - 1.0), 0.0)
    k2 = derive_key(key, 1)
    g = 1.0 / surface.texture_scale
    fine = value_noise(k2, u * g, v * g) + 0.5 * value_noise(k2, 2.3 * u * g + 17.0, 2.3 * v * g + 5.0)
    factor = tile_factor * (1.0 + surface.texture * 1.3 * fine)
    colour = jnp.where(grout[..., None], surface.grout_colour, surface.colour * factor[..., None])
    return jnp.clip(colour, 0.0, 1.0)


def albedo(room: Room3D, hit: Hit) -> Float[Array, "*b 3"]:
    """Albedo (linear RGB) at the hit points; zero where nothing was hit."""
    p = hit.point
    floor = surface_albedo(room.floor, derive_key(room.key, FLOOR), p[..., 0], p[..., 1])
    wall = surface_albedo(room.walls, derive_key(room.key, WALL), hit.u + 7.0 * hit.index, p[..., 2])
    wall = jnp.where((p[..., 2] < room.skirting_height)[..., None], room.skirting_colour, wall)
    nb = room.box_colour.shape[0]
    if nb:
        grain_key = derive_key(room.key, FURNITURE, hit.index)
        grain = value_noise(grain_key, 12.0 * (p[..., 0] + p[..., 1]), 12.0 * p[..., 2])
        box = room.box_colour[jnp.clip(hit.index, 0, nb - 1)] * (1.0 + FURNITURE_TEXTURE * 2.0 * grain)[..., None]
    else:
        box = jnp.zeros_like(floor)
    s = hit.surface[..., None]
    out = jnp.where(s == FLOOR, floor, jnp.where(s == WALL, wall, jnp.where(s == CEILING, room.ceiling, box)))
    return jnp.where(jnp.isfinite(hit.t)[..., None], jnp.clip(out, 0.0, 1.0), 0.0)


def on_screen(screens: Screens, hit: Hit) -> Float[Array, "*b s"]:
    """1.0 where a hit lies on each screen (its wall, within its extent along the wall and in
    height), else 0.0."""
    z = hit.point[..., 2, None]
    u = hit.u[..., None]
    on = ((hit.surface == WALL)[..., None] & (hit.index[..., None] == screens.wall)
          & (u >= screens.along[:, 0]) & (u <= screens.along[:, 1])
          & (z >= screens.height[:, 0]) & (z <= screens.height[:, 1]))
    return on.astype(jnp.float32)


def _lambert_one(p, n, lamp, intensity):
    lx, ly, lz = lamp[0] - p[0], lamp[1] - p[1], lamp[2] - p[2]
    d2 = lx * lx + ly * ly + lz * lz
    return intensity * jnp.maximum(lx * n[0] + ly * n[1] + lz * n[2], 0.0) / (d2 * jnp.sqrt(d2))


def lambert(point: Float[Array, "*b 3"], normal: Float[Array, "*b 3"], lamps: Float[Array, "k 3"],
            intensity: Float[Array, " k"]) -> Float[Array, "*b k"]:
    """Unshadowed irradiance of each lamp (grey levels for albedo 1): ``I cos(incidence) / d^2``."""
    p, n = xyz(point), xyz(normal)
    return jnp.stack([_lambert_one(p, n, lamps[k], intensity[k]) for k in range(lamps.shape[0])], axis=-1)


def lit(p, n, lamps: Float[Array, "k 3"], intensity: Float[Array, " k"],
        weight: Float[Array, "k s"]) -> tuple[Array, ...]:
    """For each column ``c`` of ``weight`` (a lamp's scale times its spectrum, or one column for
    one spectrum): ``sum_k weight_kc`` times :func:`lambert`'s irradiance at points ``p`` with unit
    normals ``n``, both given as component triples (x, y, z): one elementwise loop for XLA."""
    zero = jnp.zeros(jnp.broadcast_shapes(*(jnp.shape(c) for c in (*p, *n))), jnp.result_type(*p))
    totals = [zero] * weight.shape[1]
    for k in range(lamps.shape[0]):
        e = _lambert_one(p, n, lamps[k], intensity[k])
        totals = [total + weight[k, c] * e for c, total in enumerate(totals)]
    return tuple(totals)


def lamp_irradiance(room: Room3D, point: Float[Array, "*b 3"], normal: Float[Array, "*b 3"],
                    lamps: Float[Array, "k 3"], intensity: Float[Array, " k"]) -> Float[Array, "*b k"]:
    """Irradiance of each lamp at surface points, with the walls' and furniture's cast shadows."""
    e = lambert(point, normal, lamps, intensity)
    start = point + EPS * normal
    to_lamp = lamps - start[..., None, :]
    blocked = intersect_room(room, jnp.broadcast_to(start[..., None, :], to_lamp.shape), to_lamp).t < 1.0
    return jnp.where(blocked, 0.0, e)
