"""People of the synthetic world: their shape, their draw from the priors, and their walks.

A person (the paper's footnote 3: an upright cylinder) is a body cylinder of
radius ``shoulder_width / 2`` from the floor up to the shoulders
(``SHOULDER * H_p``), a neck cylinder, and a head sphere of radius ``R_h`` whose
top is at ``H_p``; the foot is the body's axis on the floor. Clothing has two
colours (trousers below ``WAIST * H_p``, a top above); the head is skin in
front and hair on the crown and the back.

People walk on smooth paths between random goals in the walkable floor (inside
the rig's room, outside its excluded zones and the furniture, at every place a
piece of furniture ever stands), keep a gap between each other (they never
overlap), and sometimes stand still: at goals, at the start (``first_pause``) and
at the scenario's stops, where their velocity is zero. Walks are simulated once
per world by :func:`walk` with ``jax.lax.scan``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Bool, Float, Int

from ..config import Rig
from ..geometry import SHOULDER
from ._scenario import Furniture, Scenario
from ._scene import XYZ, dot3

#: Hip height over body height: trousers below, the top above.
WAIST = 0.47
#: Neck radius over head radius.
NECK = 0.55
#: Person heights and head radii are drawn from their priors truncated at this many sigmas.
TRUNCATE = 4.0
#: Walking: largest acceleration (m/s^2), slowing-down distance before a goal (m), goal reached (m).
ACCEL, ARRIVE, REACHED = 1.2, 0.6, 0.25
#: Avoidance: strength (m/s) and range (m) of the push between people, and its reach (m).
PUSH, PUSH_RANGE, PUSH_REACH = 0.8, 0.35, 2.0
#: Goal sampling: candidates per draw, samples along the straight path, shortest goal distance (m).
GOAL_CANDIDATES, PATH_SAMPLES, GOAL_MIN = 64, 24, 1.0
#: Time (s) a blocked person waits before choosing a new goal.
BLOCKED_WAIT = 0.6


class People(eqx.Module):
    """Per-person constants: size (m), colours (linear RGB albedo, float32), preferred speed (m/s).

    ``floor_like`` marks people dressed close to the floor's colour.
    """

    H_p: Float[Array, " p"]
    R_h: Float[Array, " p"]
    radius: Float[Array, ""]
    top: Float[Array, "p 3"]
    bottom: Float[Array, "p 3"]
    skin: Float[Array, "p 3"]
    hair: Float[Array, "p 3"]
    speed: Float[Array, " p"]
    floor_like: Bool[Array, " p"]

    @property
    def count(self) -> int:
        return self.H_p.shape[0]

    @property
    def shoulder(self) -> Float[Array, " p"]:
        """Height of the top of the body cylinder (m)."""
        return SHOULDER * self.H_p

    @property
    def head_z(self) -> Float[Array, " p"]:
        """Height of the head's centre (m): the point the PTZ aims at (eq 4)."""
        return self.H_p - self.R_h


class Paths(eqx.Module):
    """Where everybody is at every frame: foot position (m), facing direction (unit vector in
    the floor plane), walking or standing."""

    position: Float[Array, "t p 2"]
    facing: Float[Array, "t p 2"]
    moving: Bool[Array, "t p"]


def _truncated(key, mean, sigma, shape):
    return mean + sigma * jax.random.truncated_normal(key, -TRUNCATE, TRUNCATE, shape)


@eqx.filter_jit
def draw_people(rig: Rig, scenario: Scenario, key: Array) -> People:
    """Draw each person's H_p and R_h from the rig's person priors (truncated at 4 sigma),
    clothing from the scenario's palette (or close to the floor's colour for a
    ``floor_like`` share), skin, hair and walking speed."""
    crowd, n = scenario.crowd, scenario.crowd.count
    k = jax.random.split(key, 9)
    pr, sg = rig.person, rig.sigmas
    H_p = _truncated(k[0], pr.H_p, sg.H_p, (n,))
    R_h = _truncated(k[1], pr.R_h, sg.R_h, (n,))
    pick = lambda kk, palette: palette[jax.random.randint(kk, (n,), 0, palette.shape[0])]
    top, bottom = pick(k[2], crowd.clothing), pick(k[3], crowd.clothing)
    floor_like = jnp.arange(n) < jnp.round(crowd.floor_like * n)
    jitter = 1.0 + 0.05 * jax.random.normal(k[4], (n, 2, 3))
    shade = jax.random.uniform(k[5], (n, 2, 1), minval=0.8, maxval=1.2)
    like = jnp.clip(scenario.floor.colour * jitter * shade, 0.0, 1.0)
    top = jnp.where(floor_like[:, None], like[:, 0], top)
    bottom = jnp.where(floor_like[:, None], like[:, 1], bottom)
    speed = jax.random.uniform(k[6], (n,), minval=crowd.speed[0], maxval=crowd.speed[1])
    f32 = lambda x: x.astype(jnp.float32)
    return People(
        H_p=H_p, R_h=R_h, radius=0.5 * pr.shoulder_width, top=f32(top), bottom=f32(bottom),
        skin=f32(pick(k[7], crowd.skin)), hair=f32(pick(k[8], crowd.hair)), speed=speed, floor_like=floor_like,
    )


# --------------------------------------------------------------------------------------
# Walking
# --------------------------------------------------------------------------------------


def walkable(rig: Rig, furniture: Furniture, X, Y, clearance) -> Bool[Array, "*b"]:
    """Whether a person of radius ``clearance`` (m) can stand at (X, Y): the disc's centre
    and 8 points of its rim are in the room (outside excluded zones), and it keeps
    clear of every furniture box at every place it ever stands (before and after a move)."""
    X, Y = jnp.asarray(X), jnp.asarray(Y)
    a = jnp.linspace(0.0, 2 * jnp.pi, 8, endpoint=False)
    px = jnp.concatenate([X[..., None], X[..., None] + clearance * jnp.cos(a)], axis=-1)
    py = jnp.concatenate([Y[..., None], Y[..., None] + clearance * jnp.sin(a)], axis=-1)
    ok = jnp.all(rig.room.contains(px, py), axis=-1)
    if furniture.count:
        lo, hi = furniture.footprints()
        dx = jnp.maximum(jnp.maximum(lo[:, 0] - X[..., None], X[..., None] - hi[:, 0]), 0.0)
        dy = jnp.maximum(jnp.maximum(lo[:, 1] - Y[..., None], Y[..., None] - hi[:, 1]), 0.0)
        ok = ok & jnp.all(jnp.hypot(dx, dy) >= clearance, axis=-1)
    return ok


def _bounds(rig: Rig):
    o = rig.room.outline
    return o.min(axis=0), o.max(axis=0)


def _first(valid: Bool[Array, " n"], cand: Float[Array, "n 2"], fallback: Float[Array, "2"]):
    i = jnp.argmax(valid)
    return jnp.where(valid[i], cand[i], fallback), valid[i]


def _sample_goal(rig, furniture, key, pos, radius):
    """A random walkable goal reachable from ``pos`` in a straight line; ``pos`` if none is found."""
    lo, hi = _bounds(rig)
    cand = jax.random.uniform(key, (GOAL_CANDIDATES, 2), minval=lo, maxval=hi)
    s = jnp.linspace(0.0, 1.0, PATH_SAMPLES)
    line = pos + s[None, :, None] * (cand[:, None, :] - pos)
    clear = jnp.all(walkable(rig, furniture, line[..., 0], line[..., 1], radius), axis=-1)
    far = jnp.hypot(*(cand - pos).T) > GOAL_MIN
    goal, _ = _first(clear & far, cand, pos)
    return goal


@eqx.filter_jit
def _place(rig, furniture, key, n: int, radius, gap):
    """Initial positions: walkable and apart; ``ok`` is False if someone did not fit."""
    lo, hi = _bounds(rig)
    keys = jax.random.split(key, n)

    def one(i, acc):
        pos, ok = acc
        cand = jax.random.uniform(keys[i], (512, 2), minval=lo, maxval=hi)
        free = walkable(rig, furniture, cand[:, 0], cand[:, 1], radius + 0.05)
        apart = jnp.all(jnp.linalg.norm(cand[:, None] - pos[None], axis=-1) >= 2 * radius + gap + 0.05, axis=-1)
        p, found = _first(free & apart, cand, jnp.full((2,), 1e6))
        return pos.at[i].set(p), ok & found

    return lax.fori_loop(0, n, one, (jnp.full((n, 2), 1e6), jnp.array(True)))


def _clip_norm(v, limit):
    n = jnp.linalg.norm(v)
    return v * jnp.minimum(1.0, limit / jnp.maximum(n, 1e-12))


@eqx.filter_jit
def _simulate(rig: Rig, scenario: Scenario, people: People, pos: Float[Array, "p 2"], key: Array, n_frames: int):
    crowd, n = scenario.crowd, people.count
    furniture = scenario.furniture
    dt = 1.0 / scenario.fps
    r, gap = people.radius, crowd.gap
    k_goal, k_pause, k_steps = jax.random.split(key, 3)
    goals = jax.vmap(lambda kk, p: _sample_goal(rig, furniture, kk, p, r))(jax.random.split(k_goal, n), pos)
    kp1, kp2 = jax.random.split(k_pause)
    pause0 = jnp.where(jax.random.uniform(kp1, (n,)) < crowd.pause_probability,
                       jax.random.uniform(kp2, (n,), minval=crowd.pause[0], maxval=crowd.pause[1]), 0.0)
    first = jax.random.uniform(jax.random.fold_in(k_pause, 1), (n,), minval=crowd.first_pause[0],
                               maxval=crowd.first_pause[1])
    pause0 = jnp.where(crowd.first_pause[1] > 0, first, pause0)
    stops = crowd.stop_start.shape[-1] > 0
    to_goal = goals - pos
    facing0 = to_goal / jnp.maximum(jnp.linalg.norm(to_goal, axis=-1, keepdims=True), 1e-9)
    others = lambda i: jnp.arange(n) != i

    def person(i, state, keys, time):
        pos, vel, goal, pause, facing, blocked, moving = state
        to_goal = goal[i] - pos[i]
        dist = jnp.linalg.norm(to_goal)
        want = people.speed[i] * to_goal / jnp.maximum(dist, 1e-9) * jnp.minimum(1.0, dist / ARRIVE)
        away = pos[i] - pos
        d = jnp.linalg.norm(away, axis=-1)
        push = jnp.where(others(i) & (d < PUSH_REACH), PUSH * jnp.exp(-(d - 2 * r - gap) / PUSH_RANGE), 0.0)
        want = want + jnp.sum(push[:, None] * away / jnp.maximum(d, 1e-9)[:, None], axis=0)
        standing = pause[i] > 0
        if stops:  # slow down in time for the next stop (at most ACCEL), stand still through it
            start, end = crowd.stop_start[i], crowd.stop_end[i]
            stopped = jnp.any((start <= time) & (time < end))
            standing = standing | stopped
            want = _clip_norm(want, ACCEL * jnp.min(jnp.where(start > time, start - time, jnp.inf)))
        want = jnp.where(standing, 0.0, _clip_norm(want, 1.3 * people.speed[i]))
        v = vel[i] + _clip_norm(want - vel[i], ACCEL * dt)
        if stops:
            v = jnp.where(stopped, 0.0, v)
        new = pos[i] + v * dt
        apart = jnp.where(others(i), jnp.linalg.norm(pos - new, axis=-1), jnp.inf) >= 2 * r + gap
        fits = walkable(rig, furniture, new[0], new[1], r) & jnp.all(apart)
        v = jnp.where(fits, v, 0.0)
        blocked_i = jnp.where(fits | standing, 0.0, blocked[i] + dt)
        arrived = (dist < REACHED) & ~standing
        stuck = blocked_i > BLOCKED_WAIT
        here = jnp.where(fits, new, pos[i])
        rest = (jax.random.uniform(keys[i, 0]) < crowd.pause_probability) & arrived
        pause_i = jnp.where(rest, jax.random.uniform(keys[i, 1], minval=crowd.pause[0], maxval=crowd.pause[1]),
                            jnp.maximum(pause[i] - dt, 0.0))
        goal_i = lax.cond(arrived | stuck, lambda: _sample_goal(rig, furniture, keys[i, 2], here, r), lambda: goal[i])
        speed = jnp.linalg.norm(v)
        walking = speed > 0.05
        return (pos.at[i].set(here), vel.at[i].set(v), goal.at[i].set(goal_i), pause.at[i].set(pause_i),
                facing.at[i].set(jnp.where(walking, v / jnp.maximum(speed, 1e-9), facing[i])),
                blocked.at[i].set(jnp.where(stuck, 0.0, blocked_i)), moving.at[i].set(walking))

    def step(state, t):
        keys = jax.random.split(jax.random.fold_in(k_steps, t), (n, 3))
        time = t / scenario.fps  # the time of the frame this step makes
        state = lax.fori_loop(0, n, lambda i, s: person(i, s, keys, time), state)
        pos, _, _, _, facing, _, moving = state
        return state, (pos, facing, moving)

    state0 = (pos, jnp.zeros((n, 2)), goals, pause0, facing0, jnp.zeros((n,)), jnp.zeros((n,), bool))
    _, (position, facing, moving) = lax.scan(step, state0, jnp.arange(n_frames))
    return Paths(position=position, facing=facing, moving=moving)


def walk(rig: Rig, scenario: Scenario, people: People, key: Array, n_frames: int) -> Paths:
    """Simulate everybody's walk for ``n_frames`` frames at the scenario's fps (deterministic in ``key``).

    Each step moves one person after the other; a move that would leave the
    walkable floor or come closer than ``2 radius + gap`` to anybody is refused
    (the person stops, and after ``BLOCKED_WAIT`` chooses a new goal), so people
    never overlap. Everybody starts standing for a time drawn from the crowd's
    ``first_pause`` (when it is not [0, 0]); a person with a stop slows down
    before it (at most ``ACCEL``) and has zero velocity in every frame whose time
    lies in it. Raises ``ValueError`` when the people do not all fit.
    """
    n = people.count
    if n == 0:
        return Paths(position=jnp.zeros((n_frames, 0, 2)), facing=jnp.zeros((n_frames, 0, 2)),
                     moving=jnp.zeros((n_frames, 0), bool))
    k_place, k_walk = jax.random.split(key)
    pos, ok = _place(rig, scenario.furniture, k_place, n, people.radius, scenario.crowd.gap)
    if not bool(ok):
        raise ValueError(f"people.count = {n}: not everybody fits on the walkable floor")
    paths = _simulate(rig, scenario, people, pos, k_walk, simulated_frames(n_frames))
    return jax.tree.map(lambda a: a[:n_frames], paths)


#: Fewest frames a walk is simulated for (see :func:`simulated_frames`).
MIN_SIMULATED = 512


def simulated_frames(n_frames: int) -> int:
    """The frames a walk of ``n_frames`` is simulated for before it is cut to length: the next power of two,
    at least :data:`MIN_SIMULATED`. The simulation's length is a static shape (a new length is a new program,
    10-20 s to compile), and each step draws from its own frame's key and the state before it, so the first
    ``n_frames`` of a longer walk are the walk itself: one compiled program serves every frame count up to the
    power of two (a world of 400 frames and a render of 2; demos of 600 and 1000 frames), for at most twice the
    steps."""
    return max(MIN_SIMULATED, 1 << (n_frames - 1).bit_length())


# --------------------------------------------------------------------------------------
# Geometry: rays against one person
# --------------------------------------------------------------------------------------

#: Which part of a person a ray hits.
NONE, LEGS, TORSO, NECK_PART, HEAD = 0, 1, 2, 3, 4


class Body(eqx.Module):
    """One person's solid at one instant (float32): foot (m), body radius, heights, head."""

    foot: Float[Array, "2"]
    radius: Float[Array, ""]
    shoulder: Float[Array, ""]
    waist: Float[Array, ""]
    head_z: Float[Array, ""]
    R_h: Float[Array, ""]


def body(people: People, i, foot: Float[Array, "2"]) -> Body:
    """The solid of person ``i`` standing at ``foot``."""
    f = lambda x: jnp.asarray(x, jnp.float32)
    return Body(foot=f(foot), radius=f(people.radius), shoulder=f(people.shoulder[i]),
                waist=f(WAIST * people.H_p[i]), head_z=f(people.head_z[i]), R_h=f(people.R_h[i]))


def _cylinder(o: XYZ, d: XYZ, cx, cy, radius, z0, z1):
    ox, oy, oz = o[0] - cx, o[1] - cy, o[2]
    dx, dy, dz = d
    a = dx * dx + dy * dy
    b = ox * dx + oy * dy
    c = ox * ox + oy * oy - radius * radius
    horizontal = a > 1e-12
    a_s = jnp.where(horizontal, a, 1.0)
    disc = b * b - a * c
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    side_in = jnp.where(horizontal, (-b - root) / a_s, jnp.where(c <= 0, -jnp.inf, jnp.inf))
    side_out = jnp.where(horizontal, (-b + root) / a_s, jnp.where(c <= 0, jnp.inf, -jnp.inf))
    side_in = jnp.where(horizontal & (disc < 0), jnp.inf, side_in)
    vertical = jnp.abs(dz) > 1e-12
    dz_s = jnp.where(vertical, dz, 1.0)
    ta, tb = (z0 - oz) / dz_s, (z1 - oz) / dz_s
    oz_in = (oz >= z0) & (oz <= z1)
    slab_in = jnp.where(vertical, jnp.minimum(ta, tb), jnp.where(oz_in, -jnp.inf, jnp.inf))
    slab_out = jnp.where(vertical, jnp.maximum(ta, tb), jnp.where(oz_in, jnp.inf, -jnp.inf))
    t_in = jnp.maximum(side_in, slab_in)
    t_out = jnp.minimum(side_out, slab_out)
    hit = (t_in <= t_out) & (t_in > 0)
    return jnp.where(hit, t_in, jnp.inf), slab_in > side_in


def _sphere(o: XYZ, d: XYZ, cx, cy, cz, radius):
    ox, oy, oz = o[0] - cx, o[1] - cy, o[2] - cz
    dx, dy, dz = d
    a = dx * dx + dy * dy + dz * dz
    b = ox * dx + oy * dy + oz * dz
    c = ox * ox + oy * oy + oz * oz - radius * radius
    disc = b * b - a * c
    t = (-b - jnp.sqrt(jnp.maximum(disc, 0.0))) / jnp.maximum(a, 1e-30)
    return jnp.where((disc >= 0) & (t > 0) & (c > 0), t, jnp.inf)


class BodyHit(eqx.Module):
    """Rays against one person: entry distance (inf: missed), unit surface normal (components),
    part hit."""

    t: Float[Array, "*b"]
    nx: Float[Array, "*b"]
    ny: Float[Array, "*b"]
    nz: Float[Array, "*b"]
    part: Int[Array, "*b"]

    @property
    def normal(self) -> Float[Array, "*b 3"]:
        return jnp.stack([self.nx, self.ny, self.nz], axis=-1)


def _distances(b: Body, o: XYZ, d: XYZ):
    fx, fy = b.foot[0], b.foot[1]
    t_body, cap = _cylinder(o, d, fx, fy, b.radius, 0.0, b.shoulder)
    t_neck, _ = _cylinder(o, d, fx, fy, NECK * b.R_h, b.shoulder, b.head_z)
    t_head = _sphere(o, d, fx, fy, b.head_z, b.R_h)
    return t_body, cap, t_neck, t_head


def body_distance(b: Body, o: XYZ, d: XYZ) -> Array:
    """Distance along rays (origin and direction as :data:`XYZ`) to the person's body cylinder,
    neck or head (inf where missed)."""
    t_body, _, t_neck, t_head = _distances(b, o, d)
    return jnp.minimum(jnp.minimum(t_body, t_neck), t_head)


def hit_body(b: Body, o: XYZ, d: XYZ) -> BodyHit:
    """Nearest hit of rays (origin and direction as :data:`XYZ`) with the person's body cylinder,
    neck and head: distance, normal, part."""
    t_body, cap, t_neck, t_head = _distances(b, o, d)
    t = jnp.minimum(jnp.minimum(t_body, t_neck), t_head)
    ts = jnp.where(jnp.isfinite(t), t, 0.0)
    px, py, pz = o[0] + ts * d[0] - b.foot[0], o[1] + ts * d[1] - b.foot[1], o[2] + ts * d[2]
    is_head, is_neck = t == t_head, (t == t_neck) & (t != t_head)
    nx = jnp.where(is_head | ~cap, px, 0.0)
    ny = jnp.where(is_head | ~cap, py, 0.0)
    nz = jnp.where(is_head, pz - b.head_z, jnp.where(cap, 1.0, 0.0))
    inv = 1.0 / jnp.sqrt(jnp.maximum(nx * nx + ny * ny + nz * nz, 1e-24))
    part = jnp.where(is_head, HEAD, jnp.where(is_neck, NECK_PART, jnp.where(pz < b.waist, LEGS, TORSO)))
    return BodyHit(t=t, nx=nx * inv, ny=ny * inv, nz=nz * inv, part=jnp.where(jnp.isfinite(t), part, NONE))


class ShadowRays(eqx.Module):
    """Segments from surface points to lamps, with the reciprocals :func:`blocks` needs:
    ``inv_h = 1 / |to_lamp_xy|^2`` (0 for a vertical segment), ``inv = 1 / |to_lamp|^2``,
    ``inv_z = 1 / to_lamp_z``."""

    start: Float[Array, "*b 3"]
    to_lamp: Float[Array, "*b 3"]
    inv_h: Float[Array, "*b"]
    inv: Float[Array, "*b"]
    inv_z: Float[Array, "*b"]


def shadow_rays(start: Float[Array, "*b 3"], to_lamp: Float[Array, "*b 3"]) -> ShadowRays:
    """The segments ``start -> start + to_lamp`` prepared for :func:`blocks`."""
    dh2 = to_lamp[..., 0] ** 2 + to_lamp[..., 1] ** 2
    return ShadowRays(start=start, to_lamp=to_lamp, inv_h=jnp.where(dh2 > 1e-12, 1.0 / jnp.maximum(dh2, 1e-12), 0.0),
                      inv=1.0 / jnp.maximum(dot3(to_lamp, to_lamp), 1e-12),
                      inv_z=1.0 / jnp.maximum(to_lamp[..., 2], 1e-9))


def blocks(b: Body, seg: ShadowRays) -> Bool[Array, "*b"]:
    """Whether the person's body cylinder or head lies on the segments (a cast shadow).

    Closest approach: the body is hit where the part of the segment below the
    shoulders passes within the body's radius of its axis, the head where the
    segment passes within R_h of its centre. Lamps are above everybody (the scenario
    checks it), so a segment only rises towards its lamp."""
    S, D = seg.start, seg.to_lamp
    sx, sy, sz = S[..., 0], S[..., 1], S[..., 2]
    dx, dy, dz = D[..., 0], D[..., 1], D[..., 2]
    cx, cy = b.foot[0] - sx, b.foot[1] - sy
    s_top = jnp.clip((b.shoulder - sz) * seg.inv_z, 0.0, 1.0)
    s = jnp.clip((cx * dx + cy * dy) * seg.inv_h, 0.0, s_top)
    body_hit = (sz < b.shoulder) & ((cx - s * dx) ** 2 + (cy - s * dy) ** 2 < b.radius**2)
    cz = b.head_z - sz
    s = jnp.clip((cx * dx + cy * dy + cz * dz) * seg.inv, 0.0, 1.0)
    head_hit = (cx - s * dx) ** 2 + (cy - s * dy) ** 2 + (cz - s * dz) ** 2 < b.R_h**2
    return body_hit | head_hit


def hair(hit: BodyHit, facing: Float[Array, "2"]) -> Bool[Array, "*b"]:
    """Where the head is hair: the crown and the back (away from the unit vector ``facing``)."""
    return (hit.nz > 0.45) | (hit.nx * facing[0] + hit.ny * facing[1] < -0.2)


def body_albedo(people: People, i, hit: BodyHit, facing: Float[Array, "2"]) -> XYZ:
    """Albedo (r, g, b planes) where rays hit person ``i``: trousers, top, skin of neck and face, hair."""
    on_hair = hair(hit, facing)
    part = hit.part

    def channel(c):
        skin = people.skin[i, c]
        head = jnp.where(on_hair, people.hair[i, c], skin)
        return jnp.where(part == HEAD, head, jnp.where(part == NECK_PART, skin,
                                                       jnp.where(part == TORSO, people.top[i, c], people.bottom[i, c])))

    return channel(0), channel(1), channel(2)
