"""Foot estimate (eq 11-12, corrected) and its uncertainty by perturbation.

Along a sector's centre line, hypothesis ``i`` puts the person's inner end at
sample ``i`` and its outer end just before ``out(i)`` (the person-extent model of the
polar index). With background d^2 ~ chi2_2 (log density -d^2/2 + const), the
maximum a posteriori hypothesis is (eq 12 with its signs corrected)

    argmax_i [ sum_{i <= r < out(i)} d2_bar(r) - sum_{r < i} d2_bar(r) - sum_{r >= out(i)} d2_bar(r) ],

evaluated for every ``i`` at once with prefix sums. ``sigma_r_f`` comes from a
vmapped Monte Carlo: profiles drawn with the measured contrast (background radii
chi2(2 w), person radii noncentral chi2(2 w, w c)) for a person whose height is
drawn from the prior (its outer end moves by ``d r_out / d H_p`` times the draw, the
derivative by autodiff), re-run through the estimator; the root mean square error
of the axis foot, with the 1-pixel quantisation of the inner end added.
Because the estimator is the same at every frame, the Monte Carlo is tabulated
once over (hypothesis, contrast) and interpolated per detection.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ._indexing import chi2_variate, noncentral_chi2_variate
from ._polar import PolarIndex


def foot_scores(profile: Float[Array, " R"], polar: PolarIndex) -> Float[Array, " R"]:
    """Eq 12 (corrected) for every hypothesis; ``-inf`` where the person would leave the sampled radii."""
    P = jnp.concatenate([jnp.zeros(1, profile.dtype), jnp.cumsum(profile)])
    inside = P[polar.hyp_out] - P[:-1]
    score = inside - (P[-1] - inside)
    return jnp.where(polar.hyp_ok, score, -jnp.inf)


def foot_sigma_mc(polar: PolarIndex, i, contrast, key: PRNGKeyArray, n_profiles: int,
                  dof_per_sample: int = 2, sigma_H_p=0.0) -> Array:
    """Root mean square error (px, of the axis foot's image radius) for a person at ``i``."""
    w = polar.window_n
    r = jnp.arange(w.shape[0])
    kb, ko, kh = jax.random.split(key, 3)
    out = jnp.round(polar.hyp_out[i] + polar.hyp_dout_dH[i] * sigma_H_p * jax.random.normal(kh, (n_profiles, 1)))
    on = (r >= i) & (r < out)
    bg = chi2_variate(kb, dof_per_sample * w, (n_profiles, w.shape[0]))
    obj = noncentral_chi2_variate(ko, dof_per_sample * w, w * contrast, (n_profiles, w.shape[0]))
    profiles = jnp.where(on, obj, bg)
    est = jax.vmap(lambda p: jnp.argmax(foot_scores(p, polar)))(profiles)
    slope = polar.hyp_r_f[jnp.minimum(i + 1, w.shape[0] - 1)] - polar.hyp_r_f[i]
    return jnp.sqrt(jnp.mean((polar.hyp_r_f[est] - polar.hyp_r_f[i]) ** 2) + slope**2 / 12)


class FootSigmaTable(eqx.Module):
    """sigma_r_f (px) over hypothesis index and log contrast, for bilinear lookup."""

    index: Float[Array, " G"]
    log_contrast: Float[Array, " C"]
    sigma: Float[Array, "G C"]


def build_foot_sigma_table(polar: PolarIndex, key: PRNGKeyArray, n_profiles: int, dof_per_sample: int = 2,
                           sigma_H_p=0.0, n_index: int = 16,
                           contrasts=(0.25, 0.5, 1, 2, 4, 8, 16, 64, 256, 1024, 4096)) -> FootSigmaTable:
    """Tabulate :func:`foot_sigma_mc` over the valid hypotheses and a range of contrasts (rendered
    and real people reach contrasts in the thousands; the lookup clamps beyond the last)."""
    valid = jnp.nonzero(polar.hyp_ok)[0]
    grid = jnp.round(jnp.linspace(valid[0], valid[-1], n_index)).astype(jnp.int32)
    c = jnp.asarray(contrasts, jnp.float64)
    ii, cc = jnp.meshgrid(grid, c, indexing="ij")
    keys = jax.random.split(key, ii.size)
    # one cell at a time (lax.map): vmapping the Gamma sampler's rejection loops over every
    # cell at once makes all of them wait for the slowest lane
    cell = lambda args: foot_sigma_mc(polar, args[0], args[1], args[2], n_profiles, dof_per_sample, sigma_H_p)
    table = jax.jit(lambda a, b, k: jax.lax.map(cell, (a, b, k)))(ii.ravel(), cc.ravel(), keys)
    return FootSigmaTable(index=grid.astype(jnp.float64), log_contrast=jnp.log(c), sigma=table.reshape(ii.shape))


def foot_sigma_lookup(table: FootSigmaTable, i, contrast) -> Array:
    """Bilinear interpolation of the table (clamped at its edges)."""
    gi = jnp.clip(jnp.interp(i, table.index, jnp.arange(table.index.shape[0])), 0, table.index.shape[0] - 1)
    lc = jnp.log(jnp.maximum(contrast, 1e-6))
    gc = jnp.clip(jnp.interp(lc, table.log_contrast, jnp.arange(table.log_contrast.shape[0])),
                  0, table.log_contrast.shape[0] - 1)
    i0, c0 = jnp.floor(gi).astype(jnp.int32), jnp.floor(gc).astype(jnp.int32)
    i1 = jnp.minimum(i0 + 1, table.index.shape[0] - 1)
    c1 = jnp.minimum(c0 + 1, table.log_contrast.shape[0] - 1)
    fi, fc = gi - i0, gc - c0
    s = table.sigma
    return ((1 - fi) * (1 - fc) * s[i0, c0] + fi * (1 - fc) * s[i1, c0]
            + (1 - fi) * fc * s[i0, c1] + fi * fc * s[i1, c1])


