"""The background's life after learning: drift, ghost repair and absorption (docs/design.md section 4,
"The background's life"; docs/detection.md, "The background's life").

The paper learns a background once; a system that runs for hours must keep it right. Per frame
(:func:`live_step`, one jitted call):

1. **Ghost evidence** of every detection (:func:`ghost_evidence`): is there an object's edge in the
   *current* image at both sides of the sector? Over the detection's changed samples (d^2 against the
   background above :data:`CHANGED`), the mean d^2 between each sample and the sample at the same
   image radius just outside the sector, in the same frame. A person (a standing one too) differs
   from the floor beside it: hundreds. A ghost (the background still holds someone who has gone, or
   an object moved away) shows floor that continues the floor beside it: about 2, the mean of
   chi-square(2). Chromaticity makes this hold under shadows and the floor's shading. The smaller of
   the two sides is returned (the other may be a wall, furniture or another person).
2. **Repair**: the changed pixels of the detections the caller marks (``repair``: ghosts the tracker
   has seen static for long enough, objects absorbed after their time; runtime.realtime.perception
   decides) are re-learnt at once from the short-term average of the frames (``recent``).
3. **Drift**: unchanged pixels outside every detection's region follow the frames at ``adapt_rate``;
   nothing detected and nothing changed is ever learnt into the background, so a person who stops
   is not absorbed by drift.
4. ``recent`` follows every frame at ``recent_rate`` (about 0.4 s): what a repaired pixel takes.

Pixels are placed in a detection's region by their polar coordinates (:class:`PixelPolar`): inside
its sector widened by :data:`MARGIN_RAD` and between its radial ends widened by :data:`MARGIN_PX`
plus :data:`MARGIN_SHARE` of its extent; a repair reaches further (:func:`repair_regions`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, UInt8

from ..camera import OmniCamera
from ..geometry import wrap_2pi
from ._change import Background, change_against, change_measure, reference_terms
from ._detector import Detections, Detector, LineBackground, line_background
from ._indexing import gather_rgb

#: d^2 of a changed pixel: the chi-square(2) 1 - 1e-3 quantile (a background pixel exceeds it once in 1,000).
CHANGED = 13.8155
#: A detection's region: its sector widened by MARGIN_RAD each side, its radial extent by MARGIN_PX plus
#: MARGIN_SHARE of the extent each end.
MARGIN_RAD, MARGIN_PX, MARGIN_SHARE = 0.035, 4.0, 0.1
#: A repair's region: the sector widened by REPAIR_MARGIN of its width, the extent by REPAIR_SHARE of it.
REPAIR_MARGIN, REPAIR_SHARE = 0.3, 0.3
#: Ghost evidence: lines sampled across a sector, and how many lines outside its edges the flanks lie.
EVIDENCE_LINES, FLANK_LINES = 16, (3, 7)


class BackgroundLife(eqx.Module):
    """The background and the short-term average of the frames ``recent`` (a repaired pixel takes it;
    ``recent_var`` is its variance factor as an estimate of the colour, ``a / (2 - a)`` for rate ``a``)."""

    bg: Background
    recent: Float[Array, "H W 3"]
    recent_var: Float[Array, ""]


def start_life(bg: Background) -> BackgroundLife:
    """A life starting from a learnt background (``recent`` starts as the background)."""
    return BackgroundLife(bg=bg, recent=bg.mean, recent_var=jnp.asarray(1.0, jnp.float32))


class PixelPolar(eqx.Module):
    """Every pixel's polar image coordinates (r px, theta rad), for the region masks."""

    r: Float[Array, "H W"]
    theta: Float[Array, "H W"]


def pixel_polar(omni: OmniCamera) -> PixelPolar:
    """The polar coordinates of every pixel of ``omni``'s image (built once)."""
    W, H = omni.image_size
    x, y = jnp.meshgrid(jnp.arange(W, dtype=jnp.float32), jnp.arange(H, dtype=jnp.float32))
    r, theta = omni.to_polar(x, y)
    return PixelPolar(r=r.astype(jnp.float32), theta=wrap_2pi(theta).astype(jnp.float32))


def learned_share(detector: Detector, bg: Background, support: float = 2.0 / 3.0) -> Array:
    """Share of the polar samples whose learning frames agreed with the background in at least
    ``support`` of them (:func:`~omnijax.detection.learn_background` keeps the samples within 3 sigma of
    the median; ``var_factor = 1 / kept``): certainly background. The rest were occupied for more than
    a third of the learning window; they are re-learnt when seen unoccupied (ghost repair)."""
    n = 1.0 / bg.var_factor.reshape(-1)[detector.polar.line_index]
    total = jnp.max(1.0 / bg.var_factor)
    ok = detector.polar.line_ok
    return jnp.sum(ok & (n >= support * total)) / jnp.maximum(jnp.sum(ok), 1)


def detection_regions(pixels: PixelPolar, dets: Detections, which: Bool[Array, " K"],
                      margin_rad=MARGIN_RAD, margin_share=MARGIN_SHARE) -> Bool[Array, "H W"]:
    """Pixels inside the region of any detection in ``which``: its sector widened by ``margin_rad``
    each side, its radial extent by :data:`MARGIN_PX` plus ``margin_share`` of the extent each end."""
    span = wrap_2pi(dets.theta_r - dets.theta_l) + 2 * margin_rad
    offset = wrap_2pi(pixels.theta[..., None] - dets.theta_l + margin_rad)
    extent = dets.r_out - dets.r_in
    lo = dets.r_in - MARGIN_PX - margin_share * extent
    hi = dets.r_out + MARGIN_PX + margin_share * extent
    r = pixels.r[..., None]
    return jnp.any(which & (offset <= span) & (r >= lo) & (r <= hi), axis=-1)


def repair_regions(pixels: PixelPolar, dets: Detections, repair: Bool[Array, " K"]) -> Bool[Array, "H W"]:
    """Where the detections in ``repair`` are re-learnt: their regions widened by :data:`REPAIR_MARGIN`
    of the sector's width and :data:`REPAIR_SHARE` of the extent (a ghost is the image of a whole person,
    the detection's model places it only roughly), less the regions of the other detections (a person
    walking away from their ghost is never re-learnt)."""
    width = wrap_2pi(dets.theta_r - dets.theta_l)
    wide = detection_regions(pixels, dets, dets.valid & repair, jnp.maximum(MARGIN_RAD, REPAIR_MARGIN * width),
                             REPAIR_SHARE)
    return wide & ~detection_regions(pixels, dets, dets.valid & ~repair)


def ghost_evidence(detector: Detector, frame: UInt8[Array, "H W 3"], lines: LineBackground,
                   dets: Detections) -> Float[Array, " K"]:
    """Over the changed samples of each detection, the mean of each sample's smallest d^2 against the
    samples at its image radius just outside the sector (:data:`FLANK_LINES` lines out, both sides), in
    the current frame (``inf`` without changed samples). About 1 (the least of chi-square(2) draws)
    where the current image continues what lies beside it (a ghost: floor beside floor, furniture
    beside furniture), hundreds at an object."""
    polar = detector.polar
    T = polar.n_theta
    step = 2 * jnp.pi / T
    first = jnp.round(dets.theta_l / step).astype(jnp.int32)
    width = jnp.round(wrap_2pi(dets.theta_r - dets.theta_l) / step).astype(jnp.int32)
    frac = jnp.linspace(0.0, 1.0, EVIDENCE_LINES)
    inner = (first[:, None] + jnp.round(frac[None] * width[:, None]).astype(jnp.int32)) % T  # (K, L)
    out = jnp.asarray(FLANK_LINES)
    flanks = jnp.concatenate([(first[:, None] - out) % T, (first + width)[:, None] + out], -1) % T  # (K, F)
    radial = (polar.radii[None] >= dets.r_in[:, None]) & (polar.radii[None] < dets.r_out[:, None])  # (K, R)
    frame = jnp.asarray(frame)
    cur = gather_rgb(frame, polar.line_index[inner]).astype(jnp.float32)  # (K, L, R, 3)
    ref = jax.tree.map(lambda a: a[inner], lines.ref)
    sigma = lines.sigma[inner]
    changed = (change_against(cur, ref, sigma) > CHANGED) & polar.line_ok[inner] & radial[:, None, :]
    side = gather_rgb(frame, polar.line_index[flanks]).astype(jnp.float32)  # (K, F, R, 3)
    side_ok = polar.line_ok[flanks]

    def nearest(best, f):
        d2 = change_measure(cur, side[:, f, None], 1.0, sigma)
        return jnp.minimum(best, jnp.where(side_ok[:, f, None, :], d2, jnp.inf)), None

    best, _ = jax.lax.scan(nearest, jnp.full(cur.shape[:-1], jnp.inf, jnp.float32), jnp.arange(flanks.shape[1]))
    w = changed & jnp.isfinite(best)
    n = jnp.sum(w, axis=(1, 2))
    mean = jnp.sum(jnp.where(w, best, 0.0), axis=(1, 2)) / jnp.maximum(n, 1)
    return jnp.where(dets.valid & (n > 0), mean, jnp.inf)


@jax.jit
def live_step(detector: Detector, life: BackgroundLife, frame: UInt8[Array, "H W 3"], lines: LineBackground,
              dets: Detections, repair: Bool[Array, " K"], pixels: PixelPolar, recent_rate,
              adapt_rate) -> tuple[BackgroundLife, LineBackground, Float[Array, " K"]]:
    """One frame of the background's life (see the module docstring): the ghost evidence of ``dets``
    (against the background ``lines`` they were detected with), the detections in ``repair`` re-learnt
    from ``recent``, drift elsewhere, ``recent`` updated. Returns the new life, its polar lines and
    the evidence."""
    evidence = ghost_evidence(detector, frame, lines, dets)
    bg = life.bg
    f = jnp.asarray(frame, jnp.float32)
    d2 = change_against(f, reference_terms(bg.mean, bg.var_factor), bg.sigma)
    changed = d2 > CHANGED
    fix = repair_regions(pixels, dets, repair) & changed
    still = ~changed & ~detection_regions(pixels, dets, dets.valid)
    a = jnp.where(still, jnp.asarray(adapt_rate, jnp.float32), 0.0)
    mean = jnp.where(fix[..., None], life.recent, bg.mean + a[..., None] * (f - bg.mean))
    var_factor = jnp.where(fix, life.recent_var, (1 - a) ** 2 * bg.var_factor + a * a)
    bg = Background(mean=mean, var_factor=var_factor, sigma=bg.sigma)
    rr = jnp.asarray(recent_rate, jnp.float32)
    recent = life.recent + rr * (f - life.recent)
    recent_var = jnp.minimum((1 - rr) ** 2 * life.recent_var + rr * rr, 1.0)
    return BackgroundLife(bg=bg, recent=recent, recent_var=recent_var), line_background(detector, bg), evidence
