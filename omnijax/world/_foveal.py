"""The foveal (pan-tilt-zoom) camera of the synthetic world: where the true head falls, and its image.

The PTZ's centre of rotation, which is also its pinhole, is at
(D_c cos theta_c, D_c sin theta_c, H_f) of the rig (the *true* rig in the world).
Pan and tilt follow :func:`omnijax.pointing`: pan is measured at the PTZ from
the horizontal direction towards the omni camera's axis, positive towards
increasing theta; tilt is up from the horizontal. So aiming with ``pointing``
at the true head puts the head at the image centre.

The image is a pinhole view with square pixels whose pixel centres are at
integer coordinates: the optical axis meets the image at ((W - 1) / 2, (H - 1) / 2),
the focal length is ``(W / 2) / tan(fov_h / 2)`` at the zoom's angle of view
(the rig's lens table), x grows to the right and y downwards.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, UInt8

from ..config import Rig
from ..zoom import face_pixels
from ._noise import derive_key
from ._people import blocks, body, body_albedo, hit_body, shadow_rays
from ._scene import albedo, f32, intersect_room, lamp_irradiance, lit, on_screen, xyz
from ._sensor import expose

#: Rows of the foveal image cast at once (bounds memory).
FOVEAL_BLOCK_ROWS = 32


class PTZView(eqx.Module):
    """The PTZ camera's pose and intrinsics for one (pan, tilt, zoom)."""

    position: Float[Array, "3"]
    forward: Float[Array, "3"]
    right: Float[Array, "3"]
    down: Float[Array, "3"]
    focal: Float[Array, ""]
    centre: Float[Array, "2"]
    size: tuple[int, int] = eqx.field(static=True)


def ptz_view(rig: Rig, pan, tilt, zoom, size: tuple[int, int] | None = None) -> PTZView:
    """The view of the rig's PTZ at (``pan``, ``tilt``) rad and ``zoom``; ``size`` (W, H) px
    overrides the lens's image size (same angle of view)."""
    fo = rig.foveal
    W, H = size or fo.lens.image_size
    c, s = jnp.cos(fo.theta_c), jnp.sin(fo.theta_c)
    position = jnp.stack([fo.D_c * c, fo.D_c * s, fo.H_f])
    towards_axis = jnp.stack([-c, -s, jnp.zeros_like(c)])
    sideways = jnp.stack([-s, c, jnp.zeros_like(c)])
    up = jnp.array([0.0, 0.0, 1.0])
    forward = jnp.cos(tilt) * (jnp.cos(pan) * towards_axis + jnp.sin(pan) * sideways) + jnp.sin(tilt) * up
    right = jnp.cross(forward, up)
    right = right / jnp.linalg.norm(right)
    down = jnp.cross(forward, right)
    fov_h, _ = fo.lens.fov(zoom)
    focal = 0.5 * W / jnp.tan(0.5 * fov_h)
    return PTZView(position=position, forward=forward, right=right, down=down, focal=focal,
                   centre=jnp.array([(W - 1) / 2, (H - 1) / 2]), size=(W, H))


def camera_coords(view: PTZView, point: Float[Array, "*b 3"]) -> Float[Array, "*b 3"]:
    """World points in the PTZ's frame: (right, down, forward), metres."""
    v = jnp.asarray(point) - view.position
    return jnp.stack([v @ view.right, v @ view.down, v @ view.forward], axis=-1)


def project(view: PTZView, point: Float[Array, "*b 3"]) -> Float[Array, "*b 2"]:
    """Pixel (x, y) of world points in the foveal image (points must be in front)."""
    p = camera_coords(view, point)
    return view.centre + view.focal * p[..., :2] / p[..., 2:]


class HeadView(eqx.Module):
    """Where a head is in the foveal image.

    ``pixel`` the head centre's image (x, y); ``inside`` whether the whole head
    sphere is inside the frame (its centre at least R_h inside each of the four
    planes bounding the view, and in front); ``face_px`` the head's width in
    pixels (:func:`omnijax.face_pixels` at the true distance); ``distance`` from
    the PTZ to the head centre (m); ``offset`` the head centre's offset from the
    image centre (px).
    """

    pixel: Float[Array, "2"]
    inside: Bool[Array, ""]
    face_px: Float[Array, ""]
    distance: Float[Array, ""]
    offset: Float[Array, "2"]


def head_in_view(rig: Rig, pan, tilt, zoom, head: Float[Array, "3"], R_h) -> HeadView:
    """Where the head sphere (centre ``head`` m, radius ``R_h`` m) falls in the PTZ frame at
    (``pan``, ``tilt``, ``zoom``) of ``rig`` (pass the world's true rig)."""
    view = ptz_view(rig, pan, tilt, zoom)
    p = camera_coords(view, head)
    W, H = view.size
    half_w, half_h = 0.5 * W / view.focal, 0.5 * H / view.focal
    margin = lambda t, q: (t * p[2] - jnp.abs(q)) / jnp.sqrt(1.0 + t * t)
    inside = (margin(half_w, p[0]) >= R_h) & (margin(half_h, p[1]) >= R_h) & (p[2] > R_h)
    distance = jnp.linalg.norm(p)
    pixel = view.centre + view.focal * p[:2] / p[2]
    return HeadView(pixel=pixel, inside=inside, face_px=face_pixels(rig.foveal.lens, zoom, distance, R_h),
                    distance=distance, offset=pixel - view.centre)


def foveal_head(world, t, person: int, pan, tilt, zoom) -> HeadView:
    """:func:`head_in_view` for ``person`` of ``world`` at frame ``t``, with the world's true rig."""
    foot = world.state(t).foot[person]
    head = jnp.concatenate([foot, world.people.head_z[person][None]])
    return head_in_view(world.true_rig, pan, tilt, zoom, head, world.people.R_h[person])


@eqx.filter_jit
def _foveal_rows(scene, view: PTZView, state, row0, n_rows: int):
    """Noise-free grey levels of ``n_rows`` rows of the foveal image (the self-lit screens' light
    where nobody stands in front of them)."""
    W, _ = view.size
    y, x = jnp.meshgrid(row0 + jnp.arange(n_rows), jnp.arange(W), indexing="ij")
    v = f32(view)
    u, w = (x - v.centre[0]) / v.focal, (y - v.centre[1]) / v.focal
    d = v.forward + u[..., None] * v.right + w[..., None] * v.down
    d = f32(d)
    eye = v.position
    people, bg, room = scene.people, scene.background, scene.room_at(state.arrangement)
    weight, ambient = bg.light_weights(state.lamp_light), jnp.stack(bg.ambient_light(state.ambient))
    room_hit = intersect_room(room, eye, d)
    surface_alb = albedo(room, room_hit)
    screen = on_screen(scene.scenario.screens, room_hit)  # the screens emit, added after the spectrum below
    glow = jnp.sum(screen[..., None] * f32(state.screen), axis=-2)
    if screen.shape[-1]:
        surface_alb = surface_alb * (1.0 - jnp.max(screen, axis=-1))[..., None]
    e = lamp_irradiance(room, room_hit.point, room_hit.normal, bg.lamps, bg.intensity)
    foot = f32(state.foot)
    start = room_hit.point + 1e-3 * room_hit.normal
    to_lamp = bg.lamps - start[..., None, :]
    segments = shadow_rays(jnp.broadcast_to(start[..., None, :], to_lamp.shape), to_lamp)
    for i in range(people.count):
        e = jnp.where(blocks(body(people, i, foot[i]), segments), 0.0, e)
    colour = surface_alb * (ambient + jnp.sum(e[..., None] * weight, axis=-2))
    depth = room_hit.t
    rays = xyz(d)
    eye3 = xyz(eye)
    for i in range(people.count):
        hit = hit_body(body(people, i, foot[i]), eye3, rays)
        nearer = hit.t < depth
        alb = jnp.stack(body_albedo(people, i, hit, f32(state.facing[i])), axis=-1)
        ts = jnp.where(nearer, hit.t, 0.0)
        p = tuple(o + ts * c for o, c in zip(eye3, rays))
        light = ambient + jnp.stack(lit(p, (hit.nx, hit.ny, hit.nz), bg.lamps, bg.intensity, weight), axis=-1)
        colour = jnp.where(nearer[..., None], alb * light, colour)
        depth = jnp.where(nearer, hit.t, depth)
    return colour * bg.spectrum + jnp.where((depth == room_hit.t)[..., None], glow, 0.0)


def render_foveal(world, t: int, pan, tilt, zoom, size: tuple[int, int] | None = None,
                  ptz: int = 0) -> UInt8[Array, "H W 3"]:
    """The foveal camera's 8-bit image of frame ``t`` at (``pan``, ``tilt``) rad and ``zoom``: the same
    room (furniture where it stands at ``t``), people and light as the omni frame, seen through a
    pinhole at the true pose of PTZ ``ptz`` (the rig's order), with the scenario's sensor noise (one
    ray per pixel; for demos). ``size`` (W, H) overrides the lens's."""
    view = ptz_view(world.true_rig.ptz(ptz), pan, tilt, zoom, size)
    state = world.state(t)
    W, H = view.size
    rows = [_foveal_rows(world.scene, view, state, jnp.int32(r0), FOVEAL_BLOCK_ROWS)
            for r0 in range(0, H, FOVEAL_BLOCK_ROWS)]
    linear = jnp.concatenate(rows, axis=0)[:H]
    key = derive_key(world.scene.noise_key, t, np.uint32(0xF0FEA1))
    return expose(linear, world.scenario.sensor.noise_sigma, key, world.scenario.sensor.jpeg_quality)
