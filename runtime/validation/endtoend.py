"""End-to-end characterisation on rendered frames: the paper's Table 1, detection rates, containment.

docs/design.md section 5. A person stands still at eight floor positions P1-P8 (different
distances and directions from the PTZ) in the synthetic world; every trial renders
an omni frame with fresh sensor noise and runs the detector on it.

- Table 1 (the paper's experiment): one fixed rig (the world's true rig is the
  configured one) and a fresh person per trial (H_p, R_h, clothing from the priors, as
  the paper's trials had different people stand at each mark), so the trial-to-trial
  spread comes from detection and the person, not calibration; the prediction is the
  mean over trials of the pointing covariance with each detection's sigmas under the aim
  pipeline's sigma rule (the detector's sigma_r_f, sigma_theta_f scaled and widened by the
  rig's ``[detection]`` coefficients, as the loop has them) and the person priors (H_p, R_h),
  calibration sigmas zero. One person under sensor noise alone hardly moves the estimate
  (0-0.3 px).
- Table 1 with full propagation: a fresh true rig (:func:`omnijax.draw_true_rig`) and a
  fresh person (H_p, R_h, clothing) per trial; what is compared is the pointing error
  (computed from the detection with the configured rig, minus the truth), against the
  full propagation (calibration sigmas, person priors, detection sigmas).
- Rates: false alarms on empty frames (per radial line against x_f, per frame against
  the thresholds' predicted rate) and misses over all person trials (against x_m).
- Containment: for the fresh-rig trials, whether the true head disc lies in the foveal
  frame at the zoom each rule chooses for each p_contain, the detection aimed at through
  the aim pipeline (:func:`omnijax.aim_detection`), as the loop aims.
- Framing (:func:`framing`): what a user of the PTZ gets from the same trials at the rig's
  p_contain: the share of *all* trials with the head framed (a trial whose person was not
  detected is not framed), the share in which the PTZ would be aimed at no person (the
  person missed, another detection present), per position the share framed (the position's
  "face coverage": each position is one person standing there) and the median face width.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.stats import beta

from omnijax import (
    Rig,
    aim_detection,
    aim_from_image,
    build_detector,
    detect,
    detection_sigmas,
    floor_radius,
    learn_background,
    line_background,
    point_image_radius,
    pointing,
)
from omnijax.detection import Background, Detections, Detector, LineBackground, line_change
from omnijax.geometry import floor_to_image, wrap_2pi, wrap_pi
from omnijax.world import (
    Scenario,
    World,
    build_world,
    draw_people,
    draw_true_rig,
    expose,
    head_in_view,
    parse_scenario,
    render_frame,
    walkable,
)
from omnijax.zoom import ZOOM_RULES
from runtime.validation.pointing import P_CONTAIN, nees_summary, pointing_errors

#: Clearance (m) of the positions from walls and excluded zones, and their distance from the PTZ and the omni axis.
CLEARANCE, NEAR_PTZ, NEAR_AXIS = 0.5, 1.0, 0.6

Progress = Callable[[int], None]


def table1_scenario(rig: Rig, seed: int = 0) -> Scenario:
    """A plain room on the rig's floor outline, one person, three lamps near the ceiling, no drift.

    Built from the rig alone so that ``omnijax validate`` works for any rig file;
    the lamps sit on a ring around the outline's centroid, inside the room.
    """
    outline = np.asarray(rig.room.outline)
    centre = outline.mean(0)
    height = max(3.0, float(rig.omni.H_o) + 0.3)
    lamps = []
    for a in (0.3, 2.4, 4.5):
        for shrink in (0.5, 0.25, 0.0):
            p = centre + shrink * (outline - centre).max(0) * np.array([math.cos(a), math.sin(a)])
            if bool(rig.room.contains(p[0], p[1])):
                break
        lamps.append({"position": [float(p[0]), float(p[1]), height - 0.1], "intensity": 800.0})
    data = {
        "name": "table 1", "rig": "(validate)", "seed": seed,
        "room": {"height": height,
                 "floor": {"colour": [0.46, 0.40, 0.33], "tile": 0.6, "tile_variation": 0.05, "texture": 0.08,
                           "texture_scale": 0.04},
                 "walls": {"colour": [0.72, 0.70, 0.64], "texture": 0.04, "texture_scale": 0.2}},
        "people": {"count": 1},
        "lighting": {"spectrum": [1.0, 0.93, 0.80], "ambient": 60.0, "lamps": lamps},
        "sensor": {"vignetting": 0.15, "antialias": 2, "shadow_downsample": 4},
    }
    return parse_scenario(data, rig, source="validate's Table 1 scenario")


def still(scenario: Scenario) -> Scenario:
    """``scenario`` without illumination drift: trials differ by sensor noise (and the rig) only."""
    return eqx.tree_at(lambda s: s.lighting.drift_amplitude, scenario, jnp.zeros(()))


@eqx.filter_jit
def _walkable_here(rig: Rig, furniture, pts, ptz):
    """Where Table 1's person may stand (see :func:`table1_positions`)."""
    rho = jnp.hypot(pts[:, 0], pts[:, 1])
    top = point_image_radius(rho, rig.person.H_p, rig.omni.r_m, rig.omni.H_o, rig.omni.profile)
    return (walkable(rig, furniture, pts[:, 0], pts[:, 1], CLEARANCE) & (rho >= NEAR_AXIS)
            & (top < 0.95 * rig.omni.rim) & (jnp.hypot(*(pts - ptz).T) >= NEAR_PTZ))


def table1_positions(rig: Rig, scenario: Scenario, n: int = 8) -> np.ndarray:
    """``n`` floor positions (m, n x 2) at different directions and distances from the PTZ.

    Walkable floor here means inside the room, out of excluded zones and furniture,
    ``CLEARANCE`` from walls, ``NEAR_PTZ`` from the PTZ's foot, ``NEAR_AXIS`` from the
    omni axis (where r_f -> 0), with the whole person inside the image. Positions come
    in pairs on n / 2 directions seen from the PTZ's foot, evenly spread over the
    directions of the walkable floor (its 2nd to 98th percentile), one at 25 % and one
    at 75 % of the way from that ray's first to its last walkable point: near and far,
    all around. Raises ``ValueError`` if there is no walkable floor.
    """
    fo = rig.foveal
    ptz = np.array([float(fo.D_c * jnp.cos(fo.theta_c)), float(fo.D_c * jnp.sin(fo.theta_c))])

    def ok(pts):
        return np.asarray(_walkable_here(rig, scenario.furniture, jnp.asarray(pts), jnp.asarray(ptz)))

    outline = np.asarray(rig.room.outline)
    x0, y0 = outline.min(0)
    x1, y1 = outline.max(0)
    grid = np.stack(np.meshgrid(np.arange(x0, x1, 0.05), np.arange(y0, y1, 0.05)), -1).reshape(-1, 2)
    grid = grid[ok(grid)]
    if not len(grid):
        raise ValueError(f"no walkable floor {CLEARANCE} m from the walls and {NEAR_PTZ} m from the PTZ: "
                         "the room is too small for Table 1's positions")
    towards_axis = math.atan2(-ptz[1], -ptz[0]) if np.hypot(*ptz) > 1e-9 else 0.0
    rel = np.asarray(wrap_pi(np.arctan2(grid[:, 1] - ptz[1], grid[:, 0] - ptz[0]) - towards_axis))
    lo, hi = np.percentile(rel, [2, 98])
    s = np.arange(NEAR_PTZ, np.hypot(x1 - x0, y1 - y0) + 1, 0.02)
    out = []
    for k in range(n):
        a = towards_axis + lo + (k // 2 + 0.5) / ((n + 1) // 2) * (hi - lo)
        pts = ptz + s[:, None] * np.array([math.cos(a), math.sin(a)])
        good = np.flatnonzero(ok(pts))
        if not len(good):
            raise ValueError(f"no walkable floor along direction {math.degrees(a):.0f} deg from the PTZ")
        target = s[good[0]] + (0.25, 0.75)[k % 2] * (s[good[-1]] - s[good[0]])
        out.append(pts[good[np.argmin(np.abs(s[good] - target))]])
    return np.array(out)


#: Where the person stands for empty frames: far outside any room, seen by no pixel (and casting no shadow on it).
AWAY = (1.0e4, 0.0)


@dataclass
class Bench:
    """The world (one person), the detector and the background learnt from empty frames."""

    rig: Rig
    scenario: Scenario
    world: World
    detector: Detector
    bg: Background
    lines: LineBackground
    positions: np.ndarray


def at(world: World, foot) -> World:
    """``world`` with its one person standing still at ``foot`` (m) in every frame."""
    pos = jnp.broadcast_to(jnp.asarray(foot, world.paths.position.dtype), world.paths.position.shape)
    return eqx.tree_at(lambda w: (w.paths.position, w.paths.moving), world, (pos, jnp.zeros_like(world.paths.moving)))


def prepare(rig: Rig, scenario: Scenario, seed: int = 0, foot_mc_profiles: int | None = None) -> Bench:
    """Build the world, the detector and the background (learnt from empty frames, before a person enters).

    ``foot_mc_profiles`` overrides the rig's ``detection.foot_mc_profiles`` (fewer for quick runs).
    """
    scenario = still(scenario)
    n_bg = int(rig.detection.background_frames)
    world = build_world(rig, scenario, seed=seed, n_frames=n_bg, true_rig=rig)
    det_rig = rig if foot_mc_profiles is None else eqx.tree_at(
        lambda r: r.detection, rig, dataclasses.replace(rig.detection, foot_mc_profiles=foot_mc_profiles))
    detector = build_detector(det_rig, jax.random.key(seed))
    linear = at(world, AWAY).linear(0)
    sensor = scenario.sensor
    keys = jax.vmap(lambda j: jax.random.bits(jax.random.fold_in(jax.random.key(seed), j), (2,), jnp.uint32))(
        jnp.arange(n_bg) + 10_000)
    frames = jax.jit(jax.vmap(expose, (None, None, 0, None)), static_argnums=3)(
        linear, sensor.noise_sigma, keys, sensor.jpeg_quality)
    bg = jax.jit(learn_background)(frames)
    return Bench(rig=rig, scenario=scenario, world=world, detector=detector, bg=bg,
                 lines=line_background(detector, bg), positions=table1_positions(rig, scenario))


class Matched(eqx.Module):
    """The detection that covers the person (``found``: one did), per trial; ``r_in`` the image radius (px)
    of the inner end the foot hypothesis put the person's silhouette at."""

    found: jax.Array
    r_f: jax.Array
    r_in: jax.Array
    theta_f: jax.Array
    sigma_r_f: jax.Array
    sigma_theta_f: jax.Array
    bound_r_f: jax.Array
    bound_theta_f: jax.Array
    height_r_f: jax.Array
    from_head: jax.Array
    contrast: jax.Array


def match(dets: Detections, theta_true) -> tuple[Matched, jax.Array]:
    """The valid detection whose sector contains ``theta_true`` (nearest centre if several), and
    the number of other valid detections (false alarms)."""
    half = 0.5 * wrap_2pi(dets.theta_r - dets.theta_l)
    off = jnp.abs(wrap_pi(dets.theta_f - theta_true))
    covers = dets.valid & (off <= half + 1e-9)
    k = jnp.argmin(jnp.where(covers, off, jnp.inf))
    m = Matched(found=covers.any(), r_f=dets.r_f[k], r_in=dets.r_in[k], theta_f=dets.theta_f[k],
                sigma_r_f=dets.sigma_r_f[k], sigma_theta_f=dets.sigma_theta_f[k], bound_r_f=dets.bound_r_f[k],
                bound_theta_f=dets.bound_theta_f[k], height_r_f=dets.height_r_f[k],
                from_head=dets.from_head[k], contrast=dets.contrast[k])
    return m, jnp.sum(dets.valid) - covers.any()


class Trials(eqx.Module):
    """Trials at one position: the matched detection, the true inputs x (9: r_f, theta_f, H_o, H_f,
    D_c, theta_c, r_m, H_p, R_h), the true silhouette's inner end (``r_inner``, px) and the true head,
    the true rig, and per frame the other valid detections and the radial lines over the lower
    threshold."""

    det: Matched
    x_true: jax.Array
    r_inner: jax.Array
    head: jax.Array
    R_h: jax.Array
    true_rig: Rig
    others: jax.Array
    lines_over: jax.Array


def _observe(detector: Detector, lines, image, theta_true):
    det, others = match(detect(detector, image, lines)[0], theta_true)
    return det, others, jnp.sum(line_change(detector, image, lines).sum(-1) > detector.thresholds.lower)


def _truth_inputs(truth, true_rig: Rig):
    o, f = true_rig.omni, true_rig.foveal
    return jnp.stack([truth.r_f[0], truth.theta_f[0], o.H_o, f.H_f, f.D_c, f.theta_c, o.r_m, truth.H_p[0],
                      truth.R_h[0]])


@eqx.filter_jit
def _fresh_chunk(world: World, detector: Detector, lines, keys, feet, new_rig: bool = True) -> Trials:
    """One rendered frame per key, the person standing at that trial's foot (``feet``, m), each with a
    fresh person and sensor noise, and (``new_rig``) a fresh true rig."""
    def one(key, foot):
        k_rig, k_people, k_noise = jax.random.split(key, 3)
        true_rig = draw_true_rig(world.rig, k_rig) if new_rig else world.true_rig
        people = draw_people(world.rig, world.scenario, k_people)
        noise = jax.random.bits(k_noise, (2,), jnp.uint32)
        w = eqx.tree_at(lambda w: (w.scene.true_rig, w.scene.people, w.scene.noise_key), at(world, foot),
                        (true_rig, people, noise))
        frame = render_frame(w, 0)
        tr = frame.truth
        det, others, over = _observe(detector, lines, frame.image, tr.theta_f[0])
        return Trials(det=det, x_true=_truth_inputs(tr, true_rig), r_inner=tr.r_inner[0], head=tr.head[0],
                      R_h=tr.R_h[0], true_rig=true_rig, others=others, lines_over=over)

    return jax.vmap(one)(keys, feet)


@jax.jit
def _jittered(rig: Rig, foot, key, n_lines):
    """Feet around ``foot`` (m), one per key: the foot's image radius moved by up to half a pixel and its
    azimuth by up to half a radial line's spacing (``2 pi / n_lines``), uniformly, either way."""
    def one(k):
        u = jax.random.uniform(k, (2,), minval=-0.5, maxval=0.5)
        r_f, theta = floor_to_image(rig, foot)
        R, _ = floor_radius(r_f + u[0], rig.omni.r_m, rig.omni.H_o, rig.omni.profile)
        t = theta + u[1] * 2 * jnp.pi / n_lines
        return jnp.stack([R * jnp.cos(t), R * jnp.sin(t)])

    return jax.vmap(one)(key)


def jittered_feet(rig: Rig, foot, keys, n_lines: int) -> jax.Array:
    """Table 1's trial positions: the nominal ``foot`` (m) moved, per key, uniformly by up to half a pixel
    of image radius and half a radial line (``2 pi / n_lines``) of azimuth either way. Over the trials the
    foot then falls anywhere between the samples of the detector's polar grid, so the grid's quantisation
    of r_f and theta_f is a random error across trials, as the prediction treats it, not the constant
    offset it is at one exact position."""
    return _jittered(rig, jnp.asarray(foot, float), keys, n_lines)


@eqx.filter_jit
def _noise_chunk(detector: Detector, lines, linear, sigma, jpeg: int, keys, theta_true):
    """The same noise-free frame exposed once per key (fresh sensor noise), then detected."""
    def one(key):
        image = expose(linear, sigma, jax.random.bits(key, (2,), jnp.uint32), jpeg)
        return _observe(detector, lines, image, theta_true)

    return jax.vmap(one)(keys)


def concat(parts):
    return jax.tree.map(lambda *a: np.concatenate([np.asarray(x) for x in a]), *parts)


def _keys(key, i, chunk):
    """Keys of trials i .. i + chunk - 1: always a whole chunk (one compilation); surplus trials are dropped."""
    return jax.vmap(lambda j: jax.random.fold_in(key, j))(jnp.arange(i, i + chunk))


def _head(tree, m):
    return jax.tree.map(lambda a: a[:m], tree)


#: What changes from trial to trial: the sensor noise only; also the person (H_p, R_h, clothing:
#: Table 1, one fixed rig); also the true rig (full propagation, containment).
FRESH = ("noise", "person", "rig")


def trials(bench: Bench, foot, n: int, key, fresh: str, chunk: int = 25, jitter: bool = False,
           progress: Progress | None = None, start: int = 0) -> Trials:
    """``n`` trials with the person standing at ``foot`` (m; :data:`AWAY` for empty frames), each an
    omni frame with fresh sensor noise, detected. ``fresh`` (one of :data:`FRESH`) says what else
    is drawn anew per trial; with ``person`` or ``rig`` every trial renders anew (``chunk`` frames
    per call) and ``jitter`` moves each trial's person around ``foot`` (:func:`jittered_feet`); with
    ``noise`` the frame is rendered once and only exposed per trial (the same frames, faster; ``2 chunk``
    per call). Trials are numbered from ``start`` (their keys follow from ``key`` and the number: a
    second call with ``start = n`` continues the first). Calls are padded to whole chunks: one
    compilation per size."""
    if fresh not in FRESH:
        raise ValueError(f"fresh must be one of {FRESH}, got {fresh!r}")
    world = at(bench.world, foot)
    parts = []
    if fresh != "noise":
        chunk = min(chunk, n)
        n_lines = int(bench.detector.polar.n_theta)
        for i in range(start, start + n, chunk):
            m = min(chunk, start + n - i)
            keys = _keys(key, i, chunk)
            feet = (jittered_feet(bench.rig, foot, jax.vmap(lambda k: jax.random.fold_in(k, 1))(keys), n_lines)
                    if jitter else jnp.broadcast_to(jnp.asarray(foot, float), (chunk, 2)))
            parts.append(_head(_fresh_chunk(world, bench.detector, bench.lines, keys, feet, fresh == "rig"), m))
            if progress:
                progress(m)
        return concat(parts)
    linear = world.linear(0)
    tr = render_frame(world, 0).truth
    sensor = bench.scenario.sensor
    chunk = min(2 * chunk, n)
    for i in range(start, start + n, chunk):
        m = min(chunk, start + n - i)
        parts.append(_head(_noise_chunk(bench.detector, bench.lines, linear, sensor.noise_sigma,
                                        sensor.jpeg_quality, _keys(key, i, chunk), tr.theta_f[0]), m))
        if progress:
            progress(m)
    det, others, over = concat(parts)
    rep = lambda a: np.broadcast_to(np.asarray(a), (n, *np.shape(a)))
    return Trials(det=det, x_true=rep(_truth_inputs(tr, world.true_rig)), r_inner=rep(tr.r_inner[0]),
                  head=rep(tr.head[0]), R_h=rep(tr.R_h[0]),
                  true_rig=jax.tree.map(rep, world.true_rig), others=others, lines_over=over)


# --------------------------------------------------------------------------------------
# Statistics
# --------------------------------------------------------------------------------------


def sample_variance(v: np.ndarray, about_zero: bool = False) -> tuple[float, float]:
    """Sample variance of ``v`` and its standard error ``sqrt((m4 - s^4 (n - 3) / (n - 1)) / n)``
    (from the sample's fourth central moment, no normality assumed). With ``about_zero`` the
    mean square about 0 (an error's second moment) and its standard error ``sd(v^2) / sqrt(n)``."""
    v = np.asarray(v, float)
    n = v.size
    if n < 4:
        return float("nan"), float("nan")
    if about_zero:
        sq = v * v
        return float(sq.mean()), float(sq.std(ddof=1) / math.sqrt(n))
    d = v - v.mean()
    s2 = float(d @ d / (n - 1))
    m4 = float(np.mean(d**4))
    return s2, math.sqrt(max(m4 - s2 * s2 * (n - 3) / (n - 1), 0.0) / n)


def binomial(k: int, n: int, level: float = 0.95) -> dict:
    """Rate ``k / n`` with its Clopper-Pearson interval at ``level``."""
    a = 1 - level
    lo = float(beta.ppf(a / 2, k, n - k + 1)) if k > 0 else 0.0
    hi = float(beta.ppf(1 - a / 2, k + 1, n - k)) if k < n else 1.0
    return {"rate": k / n if n else None, "count": int(k), "n": int(n), "lower": lo, "upper": hi, "level": level}


def fixed_rig(rig: Rig) -> Rig:
    """``rig`` with its calibration sigmas (H_o, H_f, D_c, theta_c, r_m) zero: Table 1's prediction for
    one fixed rig, where only the detection and, since every trial is a different person, the person
    priors (H_p, R_h) vary."""
    s = rig.sigmas
    return eqx.tree_at(lambda r: (r.sigmas.H_o, r.sigmas.H_f, r.sigmas.D_c, r.sigmas.theta_c, r.sigmas.r_m), rig,
                       tuple(jnp.zeros_like(v) for v in (s.H_o, s.H_f, s.D_c, s.theta_c, s.r_m)))


@jax.jit
def _pointing_stats(rig: Rig, r_f, theta_f, sigma_r_f, sigma_theta_f, bound_r_f, bound_theta_f, height_r_f,
                    from_head):
    """Per detection, through the aim pipeline (the sigma rule and the foot's coupling to the height
    included): sin pan, tan tilt and their predicted variances, pan, tilt and their predicted 2 x 2
    covariance."""
    def one(r, t, sr, st, br, bt, h, fh):
        a = aim_detection(rig, r, t, sr, st, bound_r_f=br, bound_theta_f=bt, height_r_f=h, from_head=fh)
        p, c = a.pointing, a.covariance
        return p.sin_pan, p.tan_tilt, c.var_sin_pan, c.var_tan_tilt, p.pan, p.tilt, c.cov[:2, :2]

    return jax.vmap(one)(r_f, theta_f, sigma_r_f, sigma_theta_f, bound_r_f, bound_theta_f, height_r_f, from_head)


@jax.jit
def _pointing_stats_given(rig: Rig, r_f, theta_f, sd_r_f, sd_theta_f):
    """Predicted var(sin pan), var(tan tilt) with the foot's standard deviations taken as given (a
    measured spread, not a detector's sigmas: no sigma rule)."""
    def one(r, t, sr, st):
        a = aim_from_image(rig, r, t, jnp.diag(jnp.stack([sr**2, st**2])))
        return a.covariance.var_sin_pan, a.covariance.var_tan_tilt

    return jax.vmap(one)(r_f, theta_f, sd_r_f, sd_theta_f)


@jax.jit
def _true_pointing(rig: Rig, x_true):
    """sin pan, tan tilt, pan and tilt at the true inputs (the true head direction)."""
    p = jax.vmap(lambda x: pointing(x, rig.omni.profile))(x_true)
    return p.sin_pan, p.tan_tilt, p.pan, p.tilt


#: Per-detection kernels run on arrays padded to a multiple of this: one compilation for most sizes.
PAD = 512


def _padded(fn, rig: Rig, *arrays) -> list[np.ndarray]:
    """``fn(rig, *arrays)`` on the arrays padded (with their first row) to a multiple of :data:`PAD`."""
    n = len(arrays[0])
    m = max(PAD, -(-n // PAD) * PAD)
    pad = [jnp.asarray(np.concatenate([a, np.repeat(a[:1], m - n, 0)])) for a in map(np.asarray, arrays)]
    return [np.asarray(v)[:n] for v in fn(rig, *pad)]


def ratio_of_means(pred, sq) -> tuple[float, float]:
    """``mean(pred) / mean(sq)`` (predicted variance over measured mean squared error, over paired
    trials) and its standard error to first order in the two means,
    ``sqrt(var(pred_i - R sq_i) / n) / mean(sq)``; nan with fewer than 4 trials or no error."""
    pred, sq = np.asarray(pred, float), np.asarray(sq, float)
    n = sq.size
    if n < 4 or not sq.mean() > 0:
        return float("nan"), float("nan")
    r = pred.mean() / sq.mean()
    return float(r), float(np.std(pred - r * sq, ddof=1) / math.sqrt(n) / sq.mean())


@dataclass
class Errors:
    """Per detected trial: the prediction (through the aim pipeline, sigma rule included) and the error
    of the pointing computed from the detection with the configured rig, against the truth."""

    pred: dict  # predicted variance by quantity (tan_tilt, sin_pan)
    err: dict  # computed minus true, by quantity
    nees: np.ndarray  # of (pan, tilt) under the predicted covariance
    pan_sq: np.ndarray  # pan's squared error over its predicted variance
    tilt_sq: np.ndarray


def errors(pred_rig: Rig, rig: Rig, t: Trials) -> Errors:
    """:class:`Errors` of the detected trials of ``t``, predicted with ``pred_rig``'s sigmas."""
    d = t.det
    f = np.asarray(d.found, bool)
    if not f.any():
        empty = {q: np.zeros(0) for q in QUANTITIES}
        return Errors(pred=empty, err=empty, nees=np.zeros(0), pan_sq=np.zeros(0), tilt_sq=np.zeros(0))
    det = [np.asarray(a)[f] for a in (d.r_f, d.theta_f, d.sigma_r_f, d.sigma_theta_f, d.bound_r_f, d.bound_theta_f,
                                      d.height_r_f, d.from_head)]
    sp, tt, vsp, vtt, pan, tilt, cov2 = _padded(_pointing_stats, pred_rig, *det)
    true_sp, true_tt, true_pan, true_tilt = _padded(_true_pointing, rig, np.asarray(t.x_true)[f])
    v, pan_sq, tilt_sq = (np.asarray(a) for a in pointing_errors(pan, tilt, cov2, true_pan, true_tilt))
    return Errors(pred={"tan_tilt": vtt, "sin_pan": vsp}, err={"tan_tilt": tt - true_tt, "sin_pan": sp - true_sp},
                  nees=v, pan_sq=pan_sq, tilt_sq=tilt_sq)


def pointing_report(rig: Rig, fresh: list[Trials]) -> dict:
    """The report's ``pointing``: over all fresh-rig trials (each one PTZ aimed and arrived at a detected
    person, as the loop aims), the NEES of (pan, tilt) against the true head direction under the aim's
    full covariance (calibration, person priors, detection); containment at each p_contain is the
    report's ``containment.curve``, over the same trials."""
    ev = [errors(rig, rig, t) for t in fresh]
    cat = lambda name: np.concatenate([getattr(v, name) for v in ev])
    return {**nees_summary(cat("nees"), cat("pan_sq"), cat("tilt_sq")),
            "meaning": "fresh-rig trials: the aimed pan/tilt against the true head direction under the aim's "
                       "covariance (nees_mean per degree of freedom: 1 when right; nees_over_5_99: 0.05 when "
                       "right); containment at p_contain 0.9, 0.95, 0.99 over the same trials: containment.curve"}


#: Table 1's quantities (eq 13, 14).
QUANTITIES = ("tan_tilt", "sin_pan")


def ratio_rel_se(pred_rig: Rig, rig: Rig, t: Trials) -> float:
    """The larger relative standard error of the two Table 1 ratios (predicted variance over measured mean
    squared error) of ``t``: what :func:`table1_trials` stops on."""
    ev = errors(pred_rig, rig, t)
    out = []
    for q in QUANTITIES:
        r, se = ratio_of_means(ev.pred[q], ev.err[q] ** 2)
        out.append(se / r if r > 0 else math.inf)
    return max(out)


#: Table 1's sequential sample: at least MIN_TRIALS trials before the standard error is looked at (fewer
#: estimate it too poorly to stop on), then ROUND_TRIALS more at a time.
MIN_TRIALS, ROUND_TRIALS = 400, 200


def table1_trials(bench: Bench, foot, key, n_max: int, target_rel_se: float | None = None,
                  fresh: str = "person", progress: Progress | None = None) -> Trials:
    """Jittered trials at ``foot`` (:func:`trials`, ``jitter``): ``n_max`` of them, or with
    ``target_rel_se`` as many as put both ratios' relative standard error (:func:`ratio_rel_se`) at
    most ``target_rel_se`` (checked after :data:`MIN_TRIALS`, then every :data:`ROUND_TRIALS`), at most
    ``n_max``."""
    pred_rig = fixed_rig(bench.rig) if fresh == "person" else bench.rig
    parts, n = [], 0
    while n < n_max:
        m = n_max - n if target_rel_se is None else min(MIN_TRIALS if not n else ROUND_TRIALS, n_max - n)
        parts.append(trials(bench, foot, m, key, fresh, jitter=True, progress=progress, start=n))
        n += m
        if target_rel_se is not None and ratio_rel_se(pred_rig, bench.rig, concat(parts)) <= target_rel_se:
            break
    return concat(parts)


def _position(rig: Rig, name: str, foot, t: Trials) -> dict:
    fo = rig.foveal
    f = np.asarray(t.det.found, bool)
    return {"position": name, "foot_m": [float(v) for v in foot], "trials": int(f.sum()), "missed": int((~f).sum()),
            "distance_to_ptz_m": float(np.hypot(foot[0] - fo.D_c * np.cos(fo.theta_c),
                                                foot[1] - fo.D_c * np.sin(fo.theta_c)))}


def table_row(rig: Rig, name: str, foot, t: Trials, detection_only: bool, paper: Trials | None = None) -> dict:
    """One Table 1 row from jittered trials ``t`` (:func:`table1_trials`).

    ``pred_var_*`` is the mean over the trials of the predicted variance (calibration sigmas zero for
    ``detection_only``: one fixed rig); ``emp_var_*`` the measured mean squared error of the pointing
    (computed from the detection with the configured rig, minus the truth) about the truth, bias
    included: what the predicted variance claims to describe; ``ratio_*`` predicted over measured with
    its standard error (:func:`ratio_of_means`); ``bias_*`` and ``spread_var_*`` (the variance about the
    errors' mean) split the measured one. ``pointing``: the NEES of (pan, tilt) under the predicted
    covariance (:mod:`runtime.validation.pointing`). ``paper_fixed_position`` (from ``paper``: trials
    at the exact position, no jitter): the paper's Table 1 as it was measured, the variance of the
    pointing about its own mean, for comparison with the paper only (at one exact position the polar
    grid's quantisation is a constant offset, which a variance cannot see).
    ``diagnosis`` holds the detector's sigmas (and those the sigma rule hands to the covariance,
    ``*_used``) against its errors about the truth; the r_f error split into the inner end's (the
    detector's ``r_in`` against the true silhouette's ``r_inner``) and the person model's (the foot
    hypothesis's offset from inner end to axis foot against the true one); and the prediction with the
    measured root mean square errors in place of the detector's sigmas (which checks the propagation
    on its own).
    """
    d = t.det
    f = np.asarray(d.found, bool)
    r_f, th, s_r, s_th, r_in = (np.asarray(a)[f] for a in (d.r_f, d.theta_f, d.sigma_r_f, d.sigma_theta_f, d.r_in))
    x_true, r_inner = np.asarray(t.x_true)[f], np.asarray(t.r_inner)[f]
    pred_rig = fixed_rig(rig) if detection_only else rig
    ev = errors(pred_rig, rig, t)
    e_r, e_th = r_f - x_true[:, 0], np.asarray(wrap_pi(th - x_true[:, 1]))
    rms_r, rms_th = (np.full_like(r_f, np.sqrt(np.mean(v**2))) for v in (e_r, e_th))
    alt = dict(zip(("sin_pan", "tan_tilt"), _padded(_pointing_stats_given, pred_rig, r_f, th, rms_r, rms_th)))
    row = _position(rig, name, foot, t)
    for q in QUANTITIES:
        err, pred = ev.err[q], ev.pred[q]
        mse, mse_se = sample_variance(err, about_zero=True)
        ratio, ratio_se = ratio_of_means(pred, err**2)
        row[f"pred_var_{q}"] = float(np.mean(pred))
        row[f"emp_var_{q}"] = mse
        row[f"emp_var_{q}_se"] = mse_se
        row[f"ratio_{q}"] = ratio if ratio == ratio else None
        row[f"ratio_{q}_se"] = ratio_se if ratio == ratio else None
        row[f"bias_{q}"] = float(err.mean())
        row[f"spread_var_{q}"] = sample_variance(err)[0]
        row[f"pred_var_{q}_measured_detection_sigma"] = float(np.mean(alt[q]))
    row["pointing"] = nees_summary(ev.nees, ev.pan_sq, ev.tilt_sq)
    if paper is not None:
        row["paper_fixed_position"] = _fixed_position(pred_rig, rig, paper)
    b_r, b_th = (np.asarray(a)[f] for a in (d.bound_r_f, d.bound_theta_f))
    used_r, used_th = (np.asarray(a) for a in detection_sigmas(rig, jnp.asarray(s_r), jnp.asarray(s_th),
                                                               jnp.asarray(b_r), jnp.asarray(b_th), jnp.asarray(r_f)))
    row["diagnosis"] = {
        "sigma_r_f_px": float(np.mean(s_r)), "sigma_r_f_used_px": float(np.mean(used_r)),
        "sigma_theta_f_used_rad": float(np.mean(used_th)), "r_f_sd_px": float(np.std(e_r, ddof=1)),
        "r_f_error_rms_px": float(np.sqrt(np.mean(e_r**2))), "r_f_bias_px": float(np.mean(e_r)),
        "r_f_bias_se_px": float(np.std(e_r, ddof=1) / math.sqrt(e_r.size)),
        "r_in_bias_px": float(np.mean(r_in - r_inner)),
        "foot_model_offset_bias_px": float(np.mean((r_f - r_in) - (x_true[:, 0] - r_inner))),
        "sigma_theta_f_rad": float(np.mean(s_th)), "theta_f_sd_rad": float(np.std(e_th, ddof=1)),
        "theta_f_error_rms_rad": float(np.sqrt(np.mean(e_th**2))), "theta_f_bias_rad": float(np.mean(e_th)),
        "contrast_median": float(np.median(np.asarray(d.contrast)[f])),
    }
    return row


def _fixed_position(pred_rig: Rig, rig: Rig, t: Trials) -> dict:
    """The paper's Table 1 at one exact position: the variance of the pointing error about its mean
    against the mean predicted variance, the ratio's standard error from the variance's
    (:func:`sample_variance`)."""
    ev = errors(pred_rig, rig, t)
    out = {"trials": int(np.asarray(t.det.found).sum()),
           "meaning": "the person at the exact position in every trial, the variance about the errors' own mean "
                      "(the paper's Table 1); for comparison with the paper only"}
    for q in QUANTITIES:
        var, se = sample_variance(ev.err[q])
        p = float(np.mean(ev.pred[q])) if ev.pred[q].size else float("nan")
        ok = var > 0
        out |= {f"pred_var_{q}": p, f"emp_var_{q}": var, f"emp_var_{q}_se": se,
                f"ratio_{q}": p / var if ok else None, f"ratio_{q}_se": p * se / var**2 if ok else None}
    return out


@jax.jit
def _contained(rig: Rig, t: Trials, p_contain):
    """Per rule of :data:`~omnijax.zoom.ZOOM_RULES` (last axis): whether the true head disc lies in the
    foveal frame at the zoom the rule chooses for ``p_contain``, the face width (px), the predicted
    probability and the zoom. The detection goes through the aim pipeline, as in the loop."""
    rig = eqx.tree_at(lambda r: r.p_contain, rig, jnp.asarray(p_contain, float))

    def one(det, head, R_h, true_rig):
        a = aim_detection(rig, det.r_f, det.theta_f, det.sigma_r_f, det.sigma_theta_f, ZOOM_RULES,
                          bound_r_f=det.bound_r_f, bound_theta_f=det.bound_theta_f, height_r_f=det.height_r_f,
                          from_head=det.from_head)
        out = []
        for rule in ZOOM_RULES:
            z = a.zooms[rule]
            view = head_in_view(true_rig, a.pointing.pan, a.pointing.tilt, z.zoom, head, R_h)
            out.append((view.inside, view.face_px, z.probability, z.zoom))
        return tuple(jnp.stack(v, -1) for v in zip(*out))

    return jax.vmap(one)(t.det, t.head, t.R_h, t.true_rig)


def containment(rig: Rig, t: Trials, p_contain: tuple[float, ...] = P_CONTAIN) -> list[dict]:
    """The containment curve: for each rule and p_contain, the rate over the detected (fresh-rig) trials,
    its 95 % interval, the mean predicted probability, the median zoom and face width (px)."""
    found = np.asarray(t.det.found, bool)
    sub = jax.tree.map(lambda a: jnp.asarray(np.asarray(a)[found]), t)
    by_p = {p: [np.asarray(a) for a in _contained(rig, sub, p)] for p in p_contain}
    out = []
    for i, rule in enumerate(ZOOM_RULES):
        for p in p_contain:
            inside, face, prob, zoom = (a[:, i] for a in by_p[p])
            b = binomial(int(inside.sum()), inside.size)
            out.append({"p_contain": p, "rule": rule, "rate": b["rate"], "trials": b["n"], "lower": b["lower"],
                        "upper": b["upper"], "predicted_mean": float(prob.mean()),
                        "face_px_median": float(np.median(face)), "zoom_median": float(np.median(zoom))})
    return out


def framing(rig: Rig, fresh: list[Trials], names: list[str], p_contain: float) -> dict:
    """The report's ``framing`` (see the module docstring) over the fresh-rig trials ``fresh`` (one
    :class:`Trials` per position ``names``) at ``p_contain``."""
    found, others, inside, face = [], [], [], []
    for t in fresh:
        ins, px, _, _ = (np.asarray(a) for a in _contained(rig, t, p_contain))
        f = np.asarray(t.det.found, bool)
        found.append(f)
        others.append(np.asarray(t.others) > 0)
        inside.append(ins & f[:, None])
        face.append(np.where(f[:, None], px, np.nan))
    f_all, o_all, in_all, px_all = (np.concatenate(v) for v in (found, others, inside, face))
    n = len(f_all)
    out = {"p_contain": p_contain, "trials": n, "detected": int(f_all.sum()),
           "no_person_share": float(np.mean(~f_all & o_all)), "no_target_share": float(np.mean(~f_all & ~o_all)),
           "rules": {}, "face_coverage": []}
    for i, rule in enumerate(ZOOM_RULES):
        framed = in_all[:, i]
        out["rules"][rule] = {"rate_all_trials": float(framed.mean()),
                              "rate_detected": float(framed[f_all].mean()) if f_all.any() else None,
                              "face_px_median": float(np.nanmedian(px_all[:, i])) if f_all.any() else None,
                              "face_px_median_framed": float(np.median(px_all[framed, i])) if framed.any() else None}
    for name, ins in zip(names, inside):
        out["face_coverage"].append({"position": name, "trials": int(len(ins)),
                                     "rules": {rule: float(ins[:, i].mean()) for i, rule in enumerate(ZOOM_RULES)}})
    return out


def rates(rig: Rig, detector: Detector, empty: Trials, people: list[Trials]) -> dict:
    """The report's ``rates``: false alarms per radial line on empty frames against x_f (eq 10), and
    misses per person trial against x_m, with 95 % Clopper-Pearson intervals."""
    n_lines = int(detector.polar.n_theta)
    over = np.asarray(empty.lines_over)
    fa = binomial(int(over.sum()), over.size * n_lines)
    found = np.concatenate([np.asarray(t.det.found, bool) for t in people])
    others = np.concatenate([np.asarray(t.others) for t in people])
    miss = binomial(int((~found).sum()), found.size)
    return {
        "x_f": float(rig.detection.x_f), "false_alarm_rate": fa["rate"],
        "false_alarm_interval": [fa["lower"], fa["upper"]],
        "x_m": float(rig.detection.x_m), "miss_rate": miss["rate"], "miss_interval": [miss["lower"], miss["upper"]],
        "false_alarm_meaning": "share of radial lines of empty frames whose sum M exceeds the lower threshold (eq 10)",
        "miss_meaning": "share of person trials (Table 1: jittered, exact position, fresh rig) with no valid sector "
                        "covering the person",
        "false_alarm_lines": fa, "misses": miss,
        "empty_frames_with_detection": binomial(int((np.asarray(empty.others) > 0).sum()), over.size),
        "predicted_frames_with_detection": float(detector.thresholds.seed_false_alarm),
        "person_frames_with_extra_detection": binomial(int((others > 0).sum()), others.size),
        "interval_level": 0.95,
    }


def summarise(rows: list[dict], quantities: tuple[str, ...] = ("tan_tilt", "sin_pan")) -> dict:
    """Worst |ratio - 1| over the rows, per quantity, and how many rows are within +-10 %."""
    out = {}
    for q in quantities:
        r = [row[f"ratio_{q}"] for row in rows if row[f"ratio_{q}"] is not None]
        out[f"max_abs_ratio_error_{q}"] = max(abs(v - 1) for v in r) if r else None
        out[f"rows_within_10pct_{q}"] = sum(abs(v - 1) <= 0.1 for v in r)
    return out
