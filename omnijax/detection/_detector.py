"""The people detector: steps 1-6 of the paper's sections 3.2.4-3.2.6 as one jitted function.

1. chromaticity of the frame at the polar samples (eq 5),
2. d^2 against the background (eq 6-7, corrected),
3. radial sums ``M(theta)`` (eq 8),
4. psi1: hysteresis sectors with thresholds from x_f and x_m (eq 9-10, corrected),
5. psi2: the windowed profile along each sector's centre line,
6. the Bayes foot estimate (eq 11-12, corrected) with ``theta_f`` (the sector's centre),
   its sigma from the sector's edges, ``sigma_r_f`` and the person's contrast.

Build a :class:`Detector` once per rig (:func:`build_detector`: thresholds and the
``sigma_r_f`` table are simulated there), sample the background at the polar
lines once per background update (:func:`line_background`), then call
:func:`detect` per frame; it never recompiles for frames of the same size.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PRNGKeyArray, UInt8

from ..camera import OmniCamera
from ..config import Rig
from ..geometry import wrap_2pi
from ._change import MEASURES, Background, ReferenceTerms, change_against, reference_terms
from ._foot import FootSigmaTable, build_foot_sigma_table, foot_estimate, foot_sigma_lookup
from ._indexing import Thresholds, build_thresholds, gather_rgb, hysteresis_sectors, window_profile
from ._polar import PolarIndex, build_polar_index


class Detector(eqx.Module):
    """Everything :func:`detect` needs besides the frame and the background."""

    omni: OmniCamera
    polar: PolarIndex
    thresholds: Thresholds
    foot_sigma: FootSigmaTable
    max_people: int = eqx.field(static=True)
    measure: str = eqx.field(static=True, default="chromaticity")

    @property
    def dof_per_sample(self) -> int:
        return MEASURES[self.measure][1]


def build_detector(rig: Rig, key: PRNGKeyArray | None = None, measure: str = "chromaticity") -> Detector:
    """Polar index, thresholds (simulated eq 9) and the sigma_r_f table for ``rig`` (seconds, once).

    ``measure`` is ``chromaticity`` (the paper's, eq 5-7) or ``grey`` (grey levels,
    for comparison: what illumination invariance buys).
    """
    if measure not in MEASURES:
        raise ValueError(f"measure must be one of {sorted(MEASURES)}, got {measure!r}")
    key = jax.random.key(0) if key is None else key
    k_th, k_foot = jax.random.split(key)
    polar = build_polar_index(rig)
    dps = MEASURES[measure][1]
    return Detector(
        omni=rig.omni, polar=polar, thresholds=build_thresholds(rig, polar, k_th, dps),
        foot_sigma=build_foot_sigma_table(polar, k_foot, rig.detection.foot_mc_profiles, dps,
                                          rig.sigmas.H_p),
        max_people=rig.detection.max_people, measure=measure,
    )


def with_zones(detector: Detector, rig: Rig, key: PRNGKeyArray | None = None) -> Detector:
    """``detector`` under ``rig``'s ``[[zones]]``: the polar index (its ignore mask) and the thresholds
    rebuilt, the ``sigma_r_f`` table kept; the same as :func:`build_detector` (same ``key``) for that
    rig, in a fraction of the time. Same shapes: the detector's compiled calls are reused."""
    key = jax.random.key(0) if key is None else key
    polar = build_polar_index(rig)
    thresholds = build_thresholds(rig, polar, jax.random.split(key)[0], detector.dof_per_sample)
    return eqx.tree_at(lambda d: (d.polar, d.thresholds), detector, (polar, thresholds))


class LineBackground(eqx.Module):
    """The background at the polar line samples (refreshed when the background changes)."""

    mean: Float[Array, "T R 3"]
    var_factor: Float[Array, "T R"]
    sigma: Float[Array, "T R"]
    ref: ReferenceTerms


@jax.jit
def line_background(detector: Detector, bg: Background) -> LineBackground:
    idx = detector.polar.line_index
    mean, var_factor = gather_rgb(bg.mean, idx), bg.var_factor.reshape(-1)[idx]
    return LineBackground(mean=mean, var_factor=var_factor, sigma=bg.sigma.reshape(-1)[idx],
                          ref=reference_terms(mean, var_factor))


class Detections(eqx.Module):
    """Up to K people (``valid`` marks the real ones), strongest sector first.

    ``r_f`` (px) is the image radius of the person's axis foot, ``theta_f`` (rad) the
    sector centre; ``sigma_theta_f`` the centre's error (:func:`_foot_sigmas`);
    ``contrast`` is the per-pixel non-centrality measured along the profile;
    ``r_in``/``r_out`` (px) the person's radial extent; ``theta_l``/``theta_r`` the
    sector's edges.
    """

    valid: Bool[Array, " K"]
    r_f: Float[Array, " K"]
    theta_f: Float[Array, " K"]
    sigma_r_f: Float[Array, " K"]
    sigma_theta_f: Float[Array, " K"]
    contrast: Float[Array, " K"]
    r_in: Float[Array, " K"]
    r_out: Float[Array, " K"]
    theta_l: Float[Array, " K"]
    theta_r: Float[Array, " K"]
    peak: Float[Array, " K"]


class DetectionTrace(eqx.Module):
    """Intermediate results, for overlays and characterisation."""

    M: Float[Array, " T"]
    profiles: Float[Array, "K R"]
    significant: Bool[Array, "K R"]


@jax.jit
def sector_mask(theta_map: Float[Array, "H W"], dets: Detections, margin: float = 0.035) -> Bool[Array, "H W"]:
    """Pixels whose azimuth lies inside a valid detection's sector widened by ``margin`` (rad):
    what the background must not learn from."""
    span = wrap_2pi(dets.theta_r - dets.theta_l) + 2 * margin
    offset = wrap_2pi(theta_map[..., None] - dets.theta_l + margin)
    return jnp.any(dets.valid & (offset <= span), axis=-1)


def line_change(detector: Detector, frame: UInt8[Array, "H W 3"], lines: LineBackground) -> Array:
    """Steps 1-3: d^2 at every polar sample and the radial sums ``M(theta)``."""
    cur = gather_rgb(frame, detector.polar.line_index).astype(jnp.float32)
    if detector.measure == "chromaticity":
        d2 = change_against(cur, lines.ref, lines.sigma)
    else:
        d2 = MEASURES[detector.measure][0](cur, lines.mean, lines.var_factor, lines.sigma)
    return jnp.where(detector.polar.line_ok, d2, 0.0).sum(-1)


def _other_blob(polar, i, significant) -> Array:
    """Distance (px of image radius) from hypothesis ``i``'s inner end to another blob on the same
    centre line, 0 if there is none: three consecutive significant samples (noise alone makes one
    such run in several thousand profiles at x_f = 0.01) more than :data:`BLOB_GAP` samples before
    the person, or beyond the person's outer end by more than :data:`BLOB_GAP` samples plus
    :data:`TALLER` of its extent (a taller person than the prior's mean is not a second blob). Two
    people (or a person and a ghost) at one azimuth and different radii make one sector, and the
    foot estimate may be either's."""
    n = significant.shape[-1]
    run = significant & jnp.roll(significant, -1) & jnp.roll(significant, -2)
    r = jnp.arange(n)
    run = run & (r < n - 2)
    out = polar.hyp_out[i]
    inner = run & (r < i - BLOB_GAP)
    outer = run & (r >= out + BLOB_GAP + TALLER * (out - i))
    d_in = jnp.where(inner.any(), polar.radii[i] - polar.radii[jnp.argmax(inner)], 0.0)
    d_out = jnp.where(outer.any(), polar.radii[jnp.argmax(outer)] - polar.radii[i], 0.0)
    return jnp.maximum(d_in, d_out)


#: Samples between a person's hypothesis and another blob on its centre line, and the share of the
#: person's extent a taller person may reach beyond it (:func:`_other_blob`).
BLOB_GAP, TALLER = 3, 0.2


def _foot_sigmas(detector: Detector, i, contrast, width, other=0.0) -> tuple[Array, Array]:
    """``(sigma_r_f, sigma_theta_f)`` of a detection whose foot hypothesis is ``i``.

    One upright person's image is symmetric about the foot's azimuth, so the sector's
    centre is unbiased and its error is where the two edges fall inside their lines'
    bins of width ``step``: uniform, ``step^2 / 12`` each, a quarter of their sum for the
    mean. (The paper's alternative, the sector width as a 99 % interval, overstates it
    about tenfold in the synthetic world: docs/detection.md.) The failure modes, by the
    sector's width against one person's there (a vertical cylinder spans ``2 asin(rho / R)``):

    - wider (two people side by side, a person and a ghost or a shadow): the person sits at
      one end of the sector, its centre off by half the excess width either way
      (``excess^2 / 4``; a uniform spread over the excess, ``excess^2 / 12``, is what the
      synthetic world's merged sectors break: docs/detection.md, "Honest sigmas");
    - narrower (partly hidden, or only part of a low-contrast person over the threshold):
      the visible part is anywhere along the person (``deficit^2 / 12``);
    - either way the centre line may miss the person's axis, so the foot's radius takes a
      share ``min((excess + deficit) / width_1, 1)`` of a uniform spread over the person's
      extent on top of the Monte Carlo ``sigma_r_f``; the whole of it when the foot
      hypothesis is the first or last possible one (the person reaches past the sampled
      radii: the image's edge or the blind centre).
    """
    polar = detector.polar
    step = 2 * jnp.pi / polar.n_theta
    one = polar.hyp_width[i]
    excess = jnp.maximum(width - one - step, 0.0)
    deficit = jnp.maximum(one - width - step, 0.0)
    sigma_theta = jnp.sqrt(step**2 / 24 + excess**2 / 4 + deficit**2 / 12 + jnp.where(other > 0, width**2 / 12, 0.0))
    extent = (polar.hyp_out[i] - i).astype(jnp.float64)
    ok = polar.hyp_ok
    first, last = jnp.argmax(ok), ok.shape[0] - 1 - jnp.argmax(ok[::-1])
    edge = (i <= first) | (i >= last)
    share = jnp.where(edge, 1.0, jnp.minimum((excess + deficit) / one, 1.0))
    sigma_r = jnp.sqrt(foot_sigma_lookup(detector.foot_sigma, i, contrast) ** 2 + share * extent**2 / 12
                       + other**2)
    return sigma_r, sigma_theta


def _sector_angles(detector: Detector, sectors):
    T = detector.polar.n_theta
    step = 2 * jnp.pi / T
    theta_l = sectors.first * step
    theta_r = sectors.last * step
    centre = wrap_2pi(0.5 * (theta_l + theta_r))
    width = (sectors.last - sectors.first + 1) * step
    return wrap_2pi(theta_l), wrap_2pi(theta_r), centre, width


def find_sectors(detector: Detector, M: Float[Array, " T"]):
    """Step 4 (psi1): hysteresis sectors of ``M`` and their edges, centres and widths (rad)."""
    sectors = hysteresis_sectors(M, detector.thresholds.lower, detector.thresholds.upper, detector.max_people)
    return (sectors, *_sector_angles(detector, sectors))


def locate_feet(detector: Detector, frame: UInt8[Array, "H W 3"], bg: Background,
                found) -> tuple[Detections, Array, Array]:
    """Steps 5-6 for the sectors ``found`` by :func:`find_sectors`: psi2 profiles and the Bayes foot.

    Returns the detections, the profiles and where they are significant.
    """
    polar, th = detector.polar, detector.thresholds
    sectors, theta_l, theta_r, theta_f, width = found
    def profile(args):
        theta, ok = args
        empty = jnp.zeros(polar.n_r, jnp.float32)
        # one sector at a time, and only the sectors that exist: most frames fill few of the K
        return jax.lax.cond(ok, lambda: window_profile(frame, bg.mean, bg.var_factor, bg.sigma, detector.omni,
                                                       polar, theta, detector.measure), lambda: (empty, empty))

    profiles, pixels = jax.lax.map(profile, (theta_f, sectors.valid))
    i, contrast = jax.vmap(lambda p, n: foot_estimate(p, n, polar, detector.dof_per_sample))(profiles, pixels)
    out = polar.hyp_out[i]
    r = jnp.arange(polar.n_r)
    significant = profiles > th.window
    on = (r[None] >= i[:, None]) & (r[None] < out[:, None])
    valid = sectors.valid & jnp.any(significant & on, axis=-1)
    other = jax.vmap(lambda k, sig: _other_blob(polar, k, sig))(i, significant)
    sigma_r, sigma_theta = _foot_sigmas(detector, i, contrast, width, other)
    dets = Detections(
        valid=valid,
        r_f=polar.hyp_r_f[i],
        theta_f=theta_f,
        sigma_r_f=sigma_r,
        sigma_theta_f=sigma_theta,
        contrast=contrast,
        r_in=polar.radii[i],
        r_out=polar.radii[0] + out,
        theta_l=theta_l,
        theta_r=theta_r,
        peak=sectors.peak,
    )
    return dets, profiles, significant


@jax.jit
def detect(detector: Detector, frame: UInt8[Array, "H W 3"], bg: Background,
           lines: LineBackground) -> tuple[Detections, DetectionTrace]:
    """Steps 1-6 for one frame: every person's foot (r_f, theta_f) with its sigmas."""
    M = line_change(detector, frame, lines)
    dets, profiles, significant = locate_feet(detector, frame, bg, find_sectors(detector, M))
    return dets, DetectionTrace(M=M, profiles=profiles, significant=significant)
