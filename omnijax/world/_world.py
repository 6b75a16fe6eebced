"""The synthetic world: a true rig, people walking in a lit room, rendered omni frames and their truth.

Build a :class:`World` once from (rig, scenario, seed) with :func:`build_world`;
``world.frame(t)`` (jitted) renders frame ``t`` and returns the 8-bit image, a
label image and the :class:`Truth`. A world is
a :class:`Scene` (rig, people, room, static view) plus the walks and the lighting
of every frame; the renderer takes the scene and one :class:`FrameState`. Furniture
that moves makes more than one arrangement of the room: the scene holds the room
and its static view for each, and each frame renders the one of its time.

docs/design.md section 5: calibration errors are systematic, so the world draws its
*true* rig once per seed from the configured rig and its calibration sigmas
(:func:`draw_true_rig`: H_o, r_m, H_f, D_c, theta_c) and each person's H_p and
R_h from the person priors, renders with the true values and reports them; the
system under test only knows the configured rig.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, Bool, Float, Int, UInt8, UInt32

from ..config import Rig
from ..detection import chromaticity
from ..geometry import SHOULDER, point_image_radius
from ._image import own_buffer
from ._noise import derive_key, key_from_seed
from ._people import Paths, People, body, body_distance, draw_people, walk, walkable
from ._render import OmniBackground, build_background, render_linear, window_size
from ._scenario import Scenario
from ._scene import Room3D, build_room, f32, intersect_room, xyz
from ._sensor import digitise, draw_sensor_noise

#: Spacing (m) of the floor grid on which the people's largest image is found.
WINDOW_GRID = 0.05


@eqx.filter_jit
def draw_true_rig(rig: Rig, key: Array) -> Rig:
    """The world's true rig: H_o, r_m, and each PTZ's H_f, D_c and theta_c drawn from N(configured
    value, sigma^2) (the PTZs of ``rig.more_ptzs`` with their own sigmas).

    The usable image circle scales with r_m; D_c stays non-negative. Everything
    else (image centre, lens, person priors, room) is as configured. The first PTZ's draw does not
    depend on how many more there are (their keys are folded from ``key``).
    """
    k = jax.random.split(key, 5)
    s = rig.sigmas

    def draw(kk, mean, sigma):
        return mean + sigma * jax.random.normal(kk, dtype=jnp.float64)

    r_m = draw(k[1], rig.omni.r_m, s.r_m)
    values = (draw(k[0], rig.omni.H_o, s.H_o), r_m, rig.omni.rim * r_m / rig.omni.r_m,
              draw(k[2], rig.foveal.H_f, s.H_f), jnp.abs(draw(k[3], rig.foveal.D_c, s.D_c)),
              draw(k[4], rig.foveal.theta_c, s.theta_c))
    where = lambda r: (r.omni.H_o, r.omni.r_m, r.omni.rim, r.foveal.H_f, r.foveal.D_c, r.foveal.theta_c)
    more = []
    for i, p in enumerate(rig.more_ptzs):
        kp = jax.random.split(jax.random.fold_in(key, i + 1), 3)
        fo = eqx.tree_at(lambda f: (f.H_f, f.D_c, f.theta_c), p.foveal,
                         (draw(kp[0], p.foveal.H_f, p.sigma_H_f), jnp.abs(draw(kp[1], p.foveal.D_c, p.sigma_D_c)),
                          draw(kp[2], p.foveal.theta_c, p.sigma_theta_c)))
        more.append(eqx.tree_at(lambda q: q.foveal, p, fo))
    return dataclasses.replace(eqx.tree_at(where, rig, values), more_ptzs=tuple(more))


class Truth(eqx.Module):
    """Ground truth of one frame (m, rad, px; image quantities in the true omni camera).

    Per person (index = id): ``foot`` (X, Y) on the floor; ``head`` the head's
    centre (X, Y, H_p - R_h), the point the PTZ aims at; ``H_p``, ``R_h``;
    ``r_f``, ``theta_f`` the image radius and azimuth of the foot (the body's axis
    on the floor) and ``pixel`` its (x, y); ``r_inner`` the image radius of the
    body's nearest floor point to the camera axis (the foot end of the drawn
    silhouette along the radial line) and ``r_head`` that of the top of the head
    (eq 2's r_h); ``in_image`` whether the foot is inside the image circle;
    ``foot_visible`` whether the silhouette's foot end is seen (not hidden by
    furniture or another person); ``area`` the pixels the person covers; ``moving``.
    Per frame: ``time`` (s), ``lamps_on``, ``illumination`` (the drift factor).
    """

    frame: Int[Array, ""]
    time: Float[Array, ""]
    foot: Float[Array, "p 2"]
    head: Float[Array, "p 3"]
    H_p: Float[Array, " p"]
    R_h: Float[Array, " p"]
    r_f: Float[Array, " p"]
    theta_f: Float[Array, " p"]
    pixel: Float[Array, "p 2"]
    r_inner: Float[Array, " p"]
    r_head: Float[Array, " p"]
    in_image: Bool[Array, " p"]
    foot_visible: Bool[Array, " p"]
    area: Float[Array, " p"]
    moving: Bool[Array, " p"]
    lamps_on: Bool[Array, " k"]
    illumination: Float[Array, ""]


class RenderedFrame(eqx.Module):
    """A rendered omni frame: 8-bit RGB ``image``, ``labels`` (person index covering each pixel
    by at least half, -1 for none), and the frame's :class:`Truth`."""

    image: UInt8[Array, "H W 3"]
    labels: Int[Array, "H W"]
    truth: Truth


class Schedule(eqx.Module):
    """The lighting and the furniture of every frame, tabulated once (per-frame scalars computed
    inside the per-pixel loops would be recomputed for every pixel): lamps on, the drift factor,
    each lamp's scale (on x drift), the ambient grey level (drift included), the furniture's
    arrangement (how many moving pieces have moved) and the colour each screen shows."""

    on: Bool[Array, "t k"]
    drift: Float[Array, " t"]
    lamp_light: Float[Array, "t k"]
    ambient: Float[Array, " t"]
    arrangement: Int[Array, " t"]
    screen: Float[Array, "t s 3"]


def clothing_contrast(people: People, scenario: Scenario) -> Float[Array, "p 2"]:
    """Chromaticity distance (r, g) of each person's top and trousers from the floor's mean colour,
    both under the scenario's ``lighting.spectrum``.

    Albedos are scaled to grey levels (x 255) first: chromaticity only sees ratios, but
    :func:`omnijax.chromaticity` treats sums below one grey level as dark."""
    s = 255.0 * scenario.lighting.spectrum
    floor = chromaticity(scenario.floor.colour * s)
    clothes = jnp.stack([people.top, people.bottom], axis=1) * s
    return jnp.linalg.norm(chromaticity(clothes) - floor, axis=-1)


@eqx.filter_jit
def light_schedule(scenario: Scenario, n_frames: int) -> Schedule:
    """:class:`Schedule` of frames 0 .. n_frames - 1 at the scenario's fps."""
    li = scenario.lighting
    time = jnp.arange(n_frames) / scenario.fps
    on = jax.vmap(li.lamp_on)(time)
    drift = jax.vmap(li.drift)(time)
    return Schedule(on=on, drift=drift, lamp_light=f32(on * drift[:, None]), ambient=f32(li.ambient * drift),
                    arrangement=scenario.furniture.arrangement(time),
                    screen=f32(jax.vmap(scenario.screens.shown)(time)))


class Scene(eqx.Module):
    """What does not change from frame to frame: the configured and the true rig, the scenario,
    the people (sizes, colours), the room and its static view in each arrangement of the
    furniture (one unless furniture moves), the sensor noise's key."""

    rig: Rig
    true_rig: Rig
    scenario: Scenario
    people: People
    rooms: tuple[Room3D, ...]
    backgrounds: tuple[OmniBackground, ...]
    noise_key: UInt32[Array, "2"]

    @property
    def room(self) -> Room3D:
        """The room in the furniture's first arrangement."""
        return self.rooms[0]

    @property
    def background(self) -> OmniBackground:
        """The static view in the furniture's first arrangement."""
        return self.backgrounds[0]

    def room_at(self, arrangement: Int[Array, ""]) -> Room3D:
        """The room in ``arrangement`` (a traced index is fine)."""
        if len(self.rooms) == 1:
            return self.rooms[0]
        return jax.tree.map(lambda *x: jnp.stack(x)[arrangement], *self.rooms)


class FrameState(eqx.Module):
    """One instant of a world (or a stack of them, along leading axes): frame index, the people's
    feet (m), facing and walking, which lamps are on, the drift, each lamp's scale, the ambient
    grey level, the furniture's arrangement and the colour each screen shows."""

    t: Int[Array, "*n"]
    foot: Float[Array, "*n p 2"]
    facing: Float[Array, "*n p 2"]
    moving: Bool[Array, "*n p"]
    lamps_on: Bool[Array, "*n k"]
    drift: Float[Array, "*n"]
    lamp_light: Float[Array, "*n k"]
    ambient: Float[Array, "*n"]
    arrangement: Int[Array, "*n"]
    screen: Float[Array, "*n s 3"]


class World(eqx.Module):
    """One synthetic world: the :class:`Scene`, everybody's walk and the lighting of every frame.

    Build with :func:`build_world`. ``frame(t)`` renders frame ``t`` (0 <= t <
    ``n_frames``, an error otherwise); the same ``t`` always gives the same frame. The
    renderer is compiled for the scene's shapes only: worlds that differ in seed or in
    the number of frames reuse it, and the walk's simulation is compiled once for every
    number of frames up to the same power of two (:func:`~omnijax.world._people.simulated_frames`).
    """

    scene: Scene
    paths: Paths
    schedule: Schedule
    seed: Int[Array, ""]

    @property
    def rig(self) -> Rig:
        return self.scene.rig

    @property
    def true_rig(self) -> Rig:
        return self.scene.true_rig

    @property
    def scenario(self) -> Scenario:
        return self.scene.scenario

    @property
    def people(self) -> People:
        return self.scene.people

    @property
    def room(self) -> Room3D:
        """The room in the furniture's first arrangement."""
        return self.scene.room

    @property
    def background(self) -> OmniBackground:
        """The static view in the furniture's first arrangement."""
        return self.scene.background

    @property
    def moved_furniture(self) -> np.ndarray:
        """Footprint centres (m) of every piece of furniture that moves, before and after its
        move, in pairs: (2 x moving pieces, 2)."""
        return np.asarray(self.scenario.furniture.moved_centres()).reshape(-1, 2)

    @property
    def n_frames(self) -> int:
        return self.paths.position.shape[0]

    def state(self, t) -> FrameState:
        """The :class:`FrameState` of frame ``t`` (an integer, or an array of them for stacked states)."""
        return frame_state(self.paths, self.schedule, jnp.asarray(t, jnp.int32))

    @property
    def noise_key(self) -> UInt32[Array, "2"]:
        return self.scene.noise_key

    def frame(self, t) -> RenderedFrame:
        """Frame ``t``: image, labels and truth (jitted)."""
        return render_state(self.scene, self.state(t))

    def frames(self, ts) -> RenderedFrame:
        """Frames ``ts`` (1-D), stacked along a leading axis (see :func:`render_frames`)."""
        return render_frames(self, ts)

    def clothing_contrast(self) -> Float[Array, "p 2"]:
        """Each person's chromaticity distance from the floor (top, trousers): Euclidean distance in
        (r, g) between the clothing's and the floor's mean albedo under the lamps' spectrum."""
        return clothing_contrast(self.people, self.scenario)

    def linear(self, t) -> Array:
        """Frame ``t`` before the sensor: noise-free grey levels (float32, H x W x 3)."""
        return render_noise_free(self.scene, self.state(t))


def build_world(rig: Rig, scenario: Scenario, seed: int | None = None, n_frames: int = 1,
                true_rig: Rig | None = None) -> World:
    """Draw the true rig and the people, simulate ``n_frames`` frames of walking, cast the static view.

    ``seed`` (an integer >= 0) defaults to the scenario's; every draw follows from it.
    Pass ``true_rig`` to fix the rig instead of drawing it (e.g. the paper's Table 1:
    one rig, many trials). Raises ``ValueError`` if the people do not fit.
    """
    if n_frames < 1:
        raise ValueError(f"n_frames must be at least 1, got {n_frames}")
    seed = scenario.seed if seed is None else int(seed)
    if not 0 <= seed < 2**63:
        raise ValueError(f"seed must be an integer in [0, 2^63), got {seed}")
    k_rig, k_people, k_walk = jax.random.split(jax.random.key(seed), 3)
    base = key_from_seed(seed)
    truth_rig = draw_true_rig(rig, k_rig) if true_rig is None else true_rig
    people = draw_people(rig, scenario, k_people)
    paths = walk(rig, scenario, people, k_walk, n_frames)
    fu = scenario.furniture
    rooms = tuple(build_room(rig, scenario, derive_key(base, 1), j) for j in range(fu.arrangements))
    omni = truth_rig.omni
    lo, hi = np.asarray(rig.room.outline).min(0), np.asarray(rig.room.outline).max(0)
    xy = np.stack(np.meshgrid(np.arange(lo[0], hi[0], WINDOW_GRID), np.arange(lo[1], hi[1], WINDOW_GRID)), -1)
    ok = _walkable_grid(rig, fu, xy, people.radius)
    tall = rig.person.H_p + 4 * rig.sigmas.H_p
    big = rig.person.R_h + 4 * rig.sigmas.R_h
    window = window_size(omni, xy, ok, people.radius, SHOULDER * tall, tall - big, big) if people.count else (8, 8)
    li, se = scenario.lighting, scenario.sensor
    backgrounds = []
    for room in rooms:
        bg = build_background(omni, room, scenario.screens, li.position, li.intensity, li.spectrum, li.lamp_spectrum,
                              se.vignetting,
                              window, se.antialias, se.shadow_downsample)
        if backgrounds:  # the people's rays do not depend on the furniture: share one buffer
            bg = eqx.tree_at(lambda b: b.rays, bg, backgrounds[0].rays)
        backgrounds.append(bg)
    scene = Scene(rig=rig, true_rig=truth_rig, scenario=scenario, people=people, rooms=rooms,
                  backgrounds=tuple(backgrounds), noise_key=derive_key(base, 2))
    return World(scene=scene, paths=paths, schedule=light_schedule(scenario, n_frames),
                 seed=jnp.asarray(seed, jnp.int64))


@eqx.filter_jit
def _walkable_grid(rig: Rig, furniture, xy, radius):
    return walkable(rig, furniture, xy[..., 0], xy[..., 1], radius)


@eqx.filter_jit
def frame_state(paths: Paths, schedule: Schedule, t: Int[Array, "*n"]) -> FrameState:
    """The :class:`FrameState` of frame(s) ``t`` (an error outside 0 .. n_frames - 1).

    Render one state per call: vmapping the renderer over states turns the people's windows
    into gathers, several times slower than a loop."""
    n = paths.position.shape[0]
    t = eqx.error_if(t, jnp.any((t < 0) | (t >= n)), f"frame index outside 0..{n - 1}")
    return FrameState(t=t, foot=paths.position[t], facing=paths.facing[t], moving=paths.moving[t],
                      lamps_on=schedule.on[t], drift=schedule.drift[t], lamp_light=schedule.lamp_light[t],
                      ambient=schedule.ambient[t], arrangement=schedule.arrangement[t], screen=schedule.screen[t])


def _linear(scene: Scene, state: FrameState):
    """The frame over the static view of the state's arrangement (only that one is rendered)."""
    def render(bg):
        return render_linear(scene.true_rig.omni, bg, scene.people, state.foot, state.facing, state.lamp_light,
                             state.ambient, state.screen)

    if len(scene.backgrounds) == 1:
        return render(scene.backgrounds[0])
    return lax.switch(state.arrangement, [lambda bg=bg: render(bg) for bg in scene.backgrounds])


@eqx.filter_jit
def render_noise_free(scene: Scene, state: FrameState) -> Array:
    """The frame of ``state`` in noise-free grey levels (float32, H x W x 3, not clipped or quantised)."""
    return _linear(scene, state).image


def frame_truth(scene: Scene, state: FrameState, area: Float[Array, " p"]) -> Truth:
    """The :class:`Truth` of one frame (``area``: pixels each person covers, from the renderer)."""
    omni, people = scene.true_rig.omni, scene.people
    foot = state.foot
    X, Y = foot[:, 0], foot[:, 1]
    rho = jnp.hypot(X, Y)
    theta = jnp.arctan2(Y, X)
    prof = omni.profile
    r_f = point_image_radius(rho, 0.0, omni.r_m, omni.H_o, prof)
    px, py = omni.to_pixel(r_f, theta)
    r_inner = point_image_radius(jnp.maximum(rho - people.radius, 0.0), 0.0, omni.r_m, omni.H_o, prof)
    r_head = point_image_radius(rho, people.H_p, omni.r_m, omni.H_o, prof)
    return Truth(
        frame=state.t, time=state.t / scene.scenario.fps, foot=foot,
        head=jnp.concatenate([foot, people.head_z[:, None]], axis=-1), H_p=people.H_p, R_h=people.R_h,
        r_f=r_f, theta_f=theta, pixel=jnp.stack([px, py], -1), r_inner=r_inner, r_head=r_head,
        in_image=r_f <= omni.rim, foot_visible=_foot_visible(scene, scene.room_at(state.arrangement), foot),
        area=area,
        moving=state.moving, lamps_on=state.lamps_on, illumination=state.drift,
    )


def _foot_visible(scene: Scene, room: Room3D, foot: Float[Array, "p 2"]) -> Bool[Array, " p"]:
    """Whether the camera sees each body's floor point nearest to its axis (not hidden by ``room``
    or others)."""
    people, n = scene.people, scene.people.count
    eye = scene.background.eye
    rho = jnp.hypot(foot[:, 0], foot[:, 1])
    inner = foot * (jnp.maximum(rho - people.radius, 0.0) / jnp.maximum(rho, 1e-9))[:, None]
    target = f32(jnp.concatenate([inner, jnp.zeros((n, 1))], axis=-1))
    d = target - eye
    hidden = intersect_room(room, eye, d).t < 1.0 - 1e-3
    for j in range(n):
        t_j = body_distance(body(people, j, f32(foot[j])), xyz(eye), xyz(d))
        hidden = hidden | ((jnp.arange(n) != j) & (t_j < 1.0 - 1e-3))
    return ~hidden


def _frame(scene: Scene, state: FrameState) -> RenderedFrame:
    sensor = scene.scenario.sensor
    lin = _linear(scene, state)
    live = state.t >= 0  # True at run time, unknown to XLA: see own_buffer
    clean = own_buffer(lin.image, live)  # else XLA fuses the noise into the composition, unvectorised
    noise = draw_sensor_noise(sensor.noise_sigma, derive_key(scene.noise_key, state.t), clean.shape)
    image = digitise(clean + noise, sensor.jpeg_quality, live)
    return RenderedFrame(image=image, labels=lin.labels, truth=frame_truth(scene, state, lin.area))


@eqx.filter_jit
def render_state(scene: Scene, state: FrameState) -> RenderedFrame:
    """The omni camera's frame of ``state``: 8-bit image, labels and truth (see :class:`RenderedFrame`)."""
    return _frame(scene, state)


def render_frame(world: World, t) -> RenderedFrame:
    """Frame ``t`` of ``world`` (same as ``world.frame(t)``)."""
    return world.frame(t)


def render_frames(world: World, ts) -> RenderedFrame:
    """Frames ``ts`` (a sequence or 1-D array of indices) of ``world``, rendered one by one (see
    :func:`frame_state`) and stacked along a leading axis."""
    frames = [world.frame(t) for t in np.asarray(ts, np.int64).reshape(-1)]
    if not frames:
        raise ValueError("render_frames needs at least one frame index")
    return jax.tree.map(lambda *x: jnp.stack(x), *frames)
