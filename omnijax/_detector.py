"""The people detector: steps 1-6 of the paper's sections 3.2.4-3.2.6 as one jitted function.

1. chromaticity of the frame at the polar samples (eq 5),
2. d^2 against the background (eq 6-7, corrected),
3. radial sums ``M(theta)`` (eq 8),
4. psi1: hysteresis sectors with thresholds from x_f and x_m (eq 9-10, corrected),
5. psi2: the windowed profile along each sector's centre line,
6. the Bayes foot estimate (eq 11-12, corrected) with ``theta_f``, its sigma from the
   sector width, ``sigma_r_f`` and the person's contrast.

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

from ._camera import OmniCamera
from ._change import MEASURES, Background
from ._config import Rig
from ._foot import FootSigmaTable, build_foot_sigma_table, foot_estimate, foot_sigma_lookup
from ._indexing import Z99, Thresholds, build_thresholds, hysteresis_sectors, window_profile
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
        foot_sigma=build_foot_sigma_table(polar, k_foot, rig.detection.foot_mc_profiles, dps),
        max_people=rig.detection.max_people, measure=measure,
    )


class LineBackground(eqx.Module):
    """The background at the polar line samples (refreshed when the background changes)."""

    mean: Float[Array, "T R 3"]
    var_factor: Float[Array, "T R"]
    sigma: Float[Array, "T R"]


@jax.jit
def line_background(detector: Detector, bg: Background) -> LineBackground:
    idx = detector.polar.line_index
    return LineBackground(mean=bg.mean.reshape(-1, 3)[idx], var_factor=bg.var_factor.reshape(-1)[idx],
                          sigma=bg.sigma.reshape(-1)[idx])


class Detections(eqx.Module):
    """Up to K people (``valid`` marks the real ones), strongest sector first.

    ``r_f`` (px) is the image radius of the person's axis foot, ``theta_f`` (rad) the
    sector centre; ``sigma_theta_f`` takes the sector width as the 99 % interval;
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
    span = jnp.mod(dets.theta_r - dets.theta_l, 2 * jnp.pi) + 2 * margin
    offset = jnp.mod(theta_map[..., None] - dets.theta_l + margin, 2 * jnp.pi)
    return jnp.any(dets.valid & (offset <= span), axis=-1)


def line_change(detector: Detector, frame: UInt8[Array, "H W 3"], lines: LineBackground) -> Array:
    """Steps 1-3: d^2 at every polar sample and the radial sums ``M(theta)``."""
    idx = detector.polar.line_index
    cur = frame.reshape(-1, 3)[idx].astype(jnp.float32)
    d2 = MEASURES[detector.measure][0](cur, lines.mean, lines.var_factor, lines.sigma)
    return jnp.where(detector.polar.line_ok, d2, 0.0).sum(-1)


def _sector_angles(detector: Detector, sectors):
    T = detector.polar.n_theta
    step = 2 * jnp.pi / T
    theta_l = sectors.first * step
    theta_r = sectors.last * step
    centre = jnp.mod(0.5 * (theta_l + theta_r), 2 * jnp.pi)
    width = (sectors.last - sectors.first + 1) * step
    return jnp.mod(theta_l, 2 * jnp.pi), jnp.mod(theta_r, 2 * jnp.pi), centre, width


@jax.jit
def detect(detector: Detector, frame: UInt8[Array, "H W 3"], bg: Background,
           lines: LineBackground) -> tuple[Detections, DetectionTrace]:
    """Steps 1-6 for one frame: every person's foot (r_f, theta_f) with its sigmas."""
    polar, th = detector.polar, detector.thresholds
    M = line_change(detector, frame, lines)
    sectors = hysteresis_sectors(M, th.lower, th.upper, detector.max_people)
    theta_l, theta_r, theta_f, width = _sector_angles(detector, sectors)
    profiles, pixels = jax.vmap(
        lambda t: window_profile(frame, bg.mean, bg.var_factor, bg.sigma, detector.omni, polar, t,
                                 detector.measure))(theta_f)
    i, contrast = jax.vmap(lambda p, n: foot_estimate(p, n, polar, detector.dof_per_sample))(profiles, pixels)
    out = polar.hyp_out[i]
    r = jnp.arange(polar.n_r)
    significant = profiles > th.window
    on = (r[None] >= i[:, None]) & (r[None] < out[:, None])
    valid = sectors.valid & jnp.any(significant & on, axis=-1)
    dets = Detections(
        valid=valid,
        r_f=polar.hyp_r_f[i],
        theta_f=theta_f,
        sigma_r_f=foot_sigma_lookup(detector.foot_sigma, i, contrast),
        sigma_theta_f=width / (2 * Z99),
        contrast=contrast,
        r_in=polar.radii[i],
        r_out=polar.radii[0] + out,
        theta_l=theta_l,
        theta_r=theta_r,
        peak=sectors.peak,
    )
    return dets, DetectionTrace(M=M, profiles=profiles, significant=significant)
