"""Foot estimate (eq 11-12, corrected) and its uncertainty by perturbation.

Along a sector's centre line, hypothesis ``i`` puts the person's inner end at
sample ``i`` and its outer end just before ``out(i)`` (the person-extent model of the
polar index). With background d^2 ~ chi2_2 (log density -d^2/2 + const), the
maximum a posteriori hypothesis is (eq 12 with its signs corrected)

    argmax_i [ sum_{i <= r < out(i)} d2_bar(r) - sum_{r < i} d2_bar(r) - sum_{r >= out(i)} d2_bar(r) ],

evaluated for every ``i`` at once with prefix sums. ``sigma_r_f`` comes from a
Monte Carlo: profiles drawn (NumPy's exact samplers) with the measured contrast (background
radii chi2(2 w), person radii noncentral chi2(2 w, w c)) for a person whose height is
drawn from the prior (its outer end moves by ``d r_out / d H_p`` times the draw, the
derivative by autodiff), re-run through the estimator (vmapped, one compiled call per
hypothesis); the root mean square error
of the axis foot, with the 1-pixel quantisation of the inner end added.
Because the estimator is the same at every frame, the Monte Carlo is tabulated
once over (hypothesis, contrast) and interpolated per detection.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ._polar import PolarIndex


def foot_scores(profile: Float[Array, " R"], polar: PolarIndex) -> Float[Array, " R"]:
    """Eq 12 (corrected) for every hypothesis; ``-inf`` where the person would leave the sampled radii."""
    P = jnp.concatenate([jnp.zeros(1, profile.dtype), jnp.cumsum(profile)])
    inside = P[polar.hyp_out] - P[:-1]
    score = inside - (P[-1] - inside)
    return jnp.where(polar.hyp_ok, score, -jnp.inf)


def foot_sigma_mc(polar: PolarIndex, i: int, contrast, rng: np.random.Generator, n_profiles: int,
                  dof_per_sample: int = 2, sigma_H_p=0.0) -> Array:
    """Root mean square error (px, of the axis foot's image radius) for a person at hypothesis ``i``,
    one per ``contrast`` (a number or an array of them): ``n_profiles`` profiles drawn with NumPy's
    samplers (``rng``; exact, and about 20 times faster than JAX's rejection samplers on a CPU,
    which made this table 9 s of every command's start), the estimator run on them in one compiled call."""
    w = np.asarray(polar.window_n, np.float64)
    dof = dof_per_sample * w
    c = np.atleast_1d(np.asarray(contrast, np.float64))
    shape = (c.size, n_profiles, w.size)
    bg = rng.chisquare(dof, shape)
    obj = rng.noncentral_chisquare(dof, w * c[:, None, None], shape)
    # the person's outer end moves with their height, drawn from the prior
    out = np.round(float(polar.hyp_out[i]) + float(polar.hyp_dout_dH[i]) * float(sigma_H_p)
                   * rng.standard_normal((c.size, n_profiles, 1)))
    rms = _foot_rms(polar, jnp.asarray(i), jnp.asarray(bg), jnp.asarray(obj), jnp.asarray(out))
    return rms if np.ndim(contrast) else rms[0]


@jax.jit
def _foot_rms(polar: PolarIndex, i, bg, obj, out) -> Array:
    """:func:`foot_sigma_mc`'s estimator: the person's samples ``obj`` over ``[i, out)``, ``bg`` elsewhere,
    eq 12's foot of each profile; RMS error per contrast (leading axis), the inner end's 1-pixel
    quantisation added."""
    r = jnp.arange(bg.shape[-1])
    profiles = jnp.where((r >= i) & (r < out), obj, bg)
    est = jax.vmap(jax.vmap(lambda p: jnp.argmax(foot_scores(p, polar))))(profiles)
    R = bg.shape[-1]
    slope = polar.hyp_r_f[jnp.minimum(i + 1, R - 1)] - polar.hyp_r_f[i]
    return jnp.sqrt(jnp.mean((polar.hyp_r_f[est] - polar.hyp_r_f[i]) ** 2, axis=-1) + slope**2 / 12)


class FootSigmaTable(eqx.Module):
    """sigma_r_f (px) over hypothesis index and log contrast, for bilinear lookup."""

    index: Float[Array, " G"]
    log_contrast: Float[Array, " C"]
    sigma: Float[Array, "G C"]


def build_foot_sigma_table(polar: PolarIndex, key: PRNGKeyArray, n_profiles: int, dof_per_sample: int = 2,
                           sigma_H_p=0.0, n_index: int = 16,
                           contrasts=(0.25, 0.5, 1, 2, 4, 8, 16, 64, 256, 1024, 4096)) -> FootSigmaTable:
    """Tabulate :func:`foot_sigma_mc` over the valid hypotheses and a range of contrasts (rendered
    and real people reach contrasts in the thousands; the lookup clamps beyond the last). ``key``
    seeds the draws: the same key, the same table."""
    rng = np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel().tolist())
    valid = np.flatnonzero(np.asarray(polar.hyp_ok))
    grid = np.round(np.linspace(valid[0], valid[-1], n_index)).astype(np.int32)
    c = np.asarray(contrasts, np.float64)
    table = np.stack([np.asarray(foot_sigma_mc(polar, int(i), c, rng, n_profiles, dof_per_sample, sigma_H_p))
                      for i in grid])
    return FootSigmaTable(index=jnp.asarray(grid, jnp.float64), log_contrast=jnp.asarray(np.log(c)),
                          sigma=jnp.asarray(table))


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


