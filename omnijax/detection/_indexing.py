"""Indexing (eq 8-10, corrected eq 9): thresholds, psi1 hysteresis over theta, psi2 window profiles.

- Background radial sums ``M(theta)`` are chi-square with ``dof(theta)`` = the line's
  samples times the measure's dof per sample (2 for chromaticity; eq 8; the polar
  index keeps a line's samples distinct so that this holds).
- The lower threshold ``T_l`` is its ``1 - x_f`` quantile (eq 10).
- The upper threshold ``T_u`` (a sector's seed) is the ``x_m`` quantile of a person's
  line sum: eq 9 corrected, ``chi2(dof - 2k) + noncentral chi2(2k, k c_min)``, with ``k``
  the person's samples on the line simulated from the person priors over the room. If ``T_u``
  falls below ``T_l``, ``c_min`` is too low for both rates; the seed is then raised to ``T_l``
  and ``feasible`` is False.
- psi1: sectors are the circular runs of ``M > T_l`` that hold an ``M > T_u`` seed.
- psi2 (:mod:`omnijax.detection._blobs`): at a line, ``d2_bar(r)`` sums d^2 over the window of a
  person's width across the line (``window_n`` samples); its background is chi-square with 2 x
  ``window_n`` degrees of freedom, whose ``1 - x_f`` quantile is the profile's significance threshold.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray, Shaped

from ..config import Rig
from ..geometry import person_image_extent
from ._polar import PolarIndex, body_radius


class Thresholds(eqx.Module):
    """Per-line lower and upper thresholds of ``M(theta)``, per-radius psi2 thresholds, and the
    smallest contrast the rates are promised for (``c_min``: a person's contrast must reach
    :data:`~omnijax.detection._blobs.CONTRAST_FACTOR` times it)."""

    lower: Float[Array, " T"]
    upper: Float[Array, " T"]
    window: Float[Array, " R"]
    feasible: Bool[Array, ""]
    seed_false_alarm: Float[Array, ""]
    c_min: Float[Array, ""]


def person_line_lengths(rig: Rig, polar: PolarIndex, key: PRNGKeyArray, n: int) -> Array:
    """Samples ``k`` (px) that a person covers on its centre line, from the priors.

    Positions are uniform over the room's floor (outline minus excluded zones),
    heights from N(H_p, sigma_H_p); lengths are clipped to the sampled radii.
    """
    k_pos, k_h = jax.random.split(key)
    poly = rig.room.outline
    lo, hi = poly.min(0), poly.max(0)
    pts = jax.random.uniform(k_pos, (4 * n, 2), minval=lo, maxval=hi)
    inside = rig.room.contains(pts[:, 0], pts[:, 1])
    order = jnp.argsort(~inside, stable=True)[:n]  # the first n points inside the room
    R = jnp.hypot(pts[order, 0], pts[order, 1])
    H_p = rig.person.H_p + rig.sigmas.H_p * jax.random.normal(k_h, (n,))
    r_in, r_out = person_image_extent(R, rig.omni, H_p, rig.person.R_h, body_radius(rig))
    r0, r1 = polar.radii[0], polar.radii[-1] + 1
    return jnp.clip(r_out, r0, r1) - jnp.clip(r_in, r0, r1)


def upper_threshold(dof: float, k: np.ndarray, c_min: float, x_m: float) -> float:
    """The ``x_m`` quantile of a person's line sum over the prior of its length ``k`` (eq 9, corrected).

    Given ``k`` samples on the person, ``chi2(dof - 2k) + noncentral chi2(2k, k c)``
    (2 dof per chromaticity sample) is exactly ``noncentral chi2(dof, k c)``; the
    mixture over the simulated ``k`` is solved for its quantile with SciPy.
    """
    from scipy.optimize import brentq
    from scipy.stats import chi2, ncx2

    ks, counts = np.unique(np.round(k), return_counts=True)
    w = counts / counts.sum()
    cdf = lambda t: float(np.sum(w * ncx2.cdf(t, dof, np.maximum(ks, 1.0) * c_min)))
    lo, hi = chi2.ppf(1e-9, dof), ncx2.ppf(1 - 1e-9, dof, ks.max() * c_min)
    return brentq(lambda t: cdf(t) - x_m, lo, hi, xtol=1e-6 * hi)


def build_thresholds(rig: Rig, polar: PolarIndex, key: PRNGKeyArray, dof_per_sample: int = 2,
                     n_sim: int = 20_000) -> Thresholds:
    """Thresholds for the rig's ``x_f``, ``x_m`` and ``c_min`` (built once, outside jit)."""
    from scipy.stats import chi2

    det = rig.detection
    x_f, x_m, c_min = float(det.x_f), float(det.x_m), float(det.c_min)
    dof = dof_per_sample * np.asarray(polar.samples)
    seen = dof > 0  # a line wholly inside ignore zones has no samples: it never fires
    lower = np.where(seen, chi2.ppf(1 - x_f, np.maximum(dof, 1)), np.inf)
    k_line = np.asarray(jax.jit(person_line_lengths, static_argnums=3)(rig, polar, key, n_sim))
    distinct, inverse = np.unique(dof[seen], return_inverse=True)
    frac = distinct / (dof_per_sample * polar.n_r)  # share of a line's samples that are distinct
    upper = np.full_like(lower, np.inf)
    upper[seen] = np.array([upper_threshold(d, k_line * f, c_min, x_m) for d, f in zip(distinct, frac)])[inverse]
    feasible = bool(np.all(upper[seen] >= lower[seen]))
    upper = np.maximum(upper, lower)
    window = chi2.ppf(1 - x_f, dof_per_sample * np.asarray(polar.window_n))
    seed_fa = float(np.sum(chi2.sf(upper[seen], dof[seen])))
    return Thresholds(lower=jnp.asarray(lower), upper=jnp.asarray(upper), window=jnp.asarray(window),
                      feasible=jnp.asarray(feasible), seed_false_alarm=jnp.asarray(seed_fa),
                      c_min=jnp.asarray(c_min))


class Sectors(eqx.Module):
    """Up to K sectors of significant change: first and last line, peak M, validity."""

    first: Int[Array, " K"]
    last: Int[Array, " K"]
    peak: Float[Array, " K"]
    valid: Bool[Array, " K"]


def hysteresis_sectors(M: Float[Array, " T"], lower: Float[Array, " T"], upper: Float[Array, " T"],
                       max_sectors: int) -> Sectors:
    """psi1: Canny's hysteresis on the circle of lines, vectorised.

    Runs of ``M > lower`` (wrapping around theta = 0) that contain a line with
    ``M > upper``; the ``max_sectors`` with the largest peaks. ``last`` may exceed
    ``T - 1`` for a run that wraps; take it modulo T. Every line above ``lower`` is one
    run of the whole circle, from its weakest line (someone under the camera is in every
    line: six_people 9050 had no sector, so no detection of anyone, for 36 frames).
    """
    T = M.shape[0]
    above = M > lower
    every = jnp.all(above)
    # start after a line below the lower threshold, or, when there is none, at the weakest line
    shift = jnp.where(every, jnp.argmin(M), jnp.argmin(above))
    a = jnp.roll(above, -shift)
    seed = jnp.roll(M > upper, -shift)
    m = jnp.roll(M, -shift)
    start = a & ~jnp.roll(a, 1)
    start = start.at[0].set(start[0] | every)  # the whole circle: one run from the weakest line
    run = jnp.where(a, jnp.cumsum(start) - 1, T)
    idx = jnp.arange(T)
    seeded = jax.ops.segment_max(seed.astype(jnp.int32), run, num_segments=T + 1)[:T] > 0
    first = jax.ops.segment_min(idx, run, num_segments=T + 1)[:T]
    last = jax.ops.segment_max(idx, run, num_segments=T + 1)[:T]
    peak = jax.ops.segment_max(m, run, num_segments=T + 1)[:T]
    ok = seeded & (first <= last)
    top, which = jax.lax.top_k(jnp.where(ok, peak, -jnp.inf), max_sectors)
    return Sectors(first=first[which] + shift, last=last[which] + shift, peak=top, valid=ok[which])


def gather_rgb(image: Shaped[Array, "H W 3"], flat: Int[Array, "*b"]) -> Shaped[Array, "*b 3"]:
    """``image``'s colours at flat pixel indices, as three single-channel gathers (XLA's CPU
    gather of 3-element rows is several times slower)."""
    data, idx = image.reshape(-1), 3 * flat
    return jnp.stack([data[idx], data[idx + 1], data[idx + 2]], -1)
