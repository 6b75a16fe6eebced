"""Foot estimate (eq 11-12, corrected) and its uncertainty by perturbation.

Along a line's windowed profile ``Q(r)`` (psi2: the sum of d^2 over the ``n(r)`` samples across
the line), hypothesis ``i`` puts the person's inner end at sample ``i``. The paper's eq 12 (its
signs corrected) takes the outer end from the prior's height, ``out(i)``, and maximises
``sum_{i <= r < out(i)} Q - sum_{outside} Q``: the log density of the samples outside the person
under the background (d^2 ~ chi2, log density ``-d^2 / 2``), with the person's own samples given
a flat density and then dropped. Two corrections, both measured (docs/detection.md, "The foot
of a person of another height"):

- the person's samples keep their side of the likelihood ratio: against a person of the least
  contrast ``c_min`` the detector is promised for, a window sample's log ratio is, to first
  order, ``(c_min / (2 dof)) (Q - m n)`` with ``m = dof + c_min / 2`` the midpoint of the two
  means, so a window that reaches past the person pays for every background sample it holds;
- the height is an unknown with its prior: the outer end is the end of a person of height
  ``H_p + z sigma_H_p`` for ``z`` on :data:`~omnijax.detection._polar.HEIGHT_SIGMAS`, each at
  its log prior ``-z^2 / 2`` (in the window's units, ``2 dof / c_min`` times it), and each
  hypothesis takes its best height.

Without them a person shorter than the prior, far out (where the head's image radius moves
about 10 px per 5 cm of height), left the prior's window longer than their image, every
hypothesis whose window covered the image scored alike, and the foot fell anywhere up to the
window's excess short of the person (0.4-0.8 m at the room's far end, seed 8901). Both are
prefix-sum gathers, for every ``i`` at once. ``sigma_r_f`` comes from a vmapped Monte Carlo:
profiles drawn with the measured contrast (background radii chi2(dof n), person radii
noncentral chi2(dof n, n c)) for a person whose height is drawn from the prior (its outer end
moves by ``d r_out / d H_p`` times the draw, the derivative by autodiff), re-run through the
estimator; the root mean square error of the axis foot, with the 1-pixel quantisation of the
inner end added. Because the estimator is the same at every frame, the Monte Carlo is
tabulated once over (hypothesis, contrast) and interpolated per detection.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ._indexing import chi2_variate, noncentral_chi2_variate
from ._polar import PolarIndex


def foot_scores_prefix(G: Float[Array, "... Rp1"], polar: PolarIndex, prior_weight) -> Float[Array, "... R"]:
    """Every hypothesis's score from ``G``, the prefix sums (a leading 0) of the profile less its
    midpoint, ``Q - m n``; ``prior_weight`` scales the height's log prior into the profile's units.
    ``-inf`` where the prior's person would leave the sampled radii."""
    inside = jnp.take(G, polar.hyp_out_h, axis=-1) - G[..., None, :-1]  # (..., heights, R)
    score = jnp.max(inside - prior_weight * 0.5 * polar.height_z[:, None] ** 2, axis=-2)
    return jnp.where(polar.hyp_ok, score, -jnp.inf)


def midpoint(dof_per_sample, c_min):
    """Per window sample: ``(m, w)``, the midpoint between the background's and the least person's
    mean d^2, and the weight of the height's log prior in the profile's units."""
    return dof_per_sample + 0.5 * c_min, 2.0 * dof_per_sample / c_min


def foot_scores(profile: Float[Array, " R"], n: Float[Array, " R"], polar: PolarIndex,
                dof_per_sample, c_min) -> Float[Array, " R"]:
    """Eq 12 (corrected, height among the unknowns) for every hypothesis of one profile ``Q``
    whose window holds ``n`` samples at each radius."""
    m, w = midpoint(dof_per_sample, c_min)
    G = jnp.concatenate([jnp.zeros(1, profile.dtype), jnp.cumsum(profile - m * n)])
    return foot_scores_prefix(G, polar, w)


def foot_sigma_mc(polar: PolarIndex, i, contrast, key: PRNGKeyArray, n_profiles: int,
                  dof_per_sample: int = 2, sigma_H_p=0.0, c_min=4.0) -> Array:
    """Root mean square error (px, of the axis foot's image radius) for a person at ``i``."""
    w = polar.window_n
    r = jnp.arange(w.shape[0])
    kb, ko, kh = jax.random.split(key, 3)
    out = jnp.round(polar.hyp_out[i] + polar.hyp_dout_dH[i] * sigma_H_p * jax.random.normal(kh, (n_profiles, 1)))
    on = (r >= i) & (r < out)
    bg = chi2_variate(kb, dof_per_sample * w, (n_profiles, w.shape[0]))
    obj = noncentral_chi2_variate(ko, dof_per_sample * w, w * contrast, (n_profiles, w.shape[0]))
    profiles = jnp.where(on, obj, bg)
    est = jax.vmap(lambda p: jnp.argmax(foot_scores(p, w, polar, dof_per_sample, c_min)))(profiles)
    slope = polar.hyp_r_f[jnp.minimum(i + 1, w.shape[0] - 1)] - polar.hyp_r_f[i]
    return jnp.sqrt(jnp.mean((polar.hyp_r_f[est] - polar.hyp_r_f[i]) ** 2) + slope**2 / 12)


class FootSigmaTable(eqx.Module):
    """sigma_r_f (px) over hypothesis index and log contrast, for bilinear lookup."""

    index: Float[Array, " G"]
    log_contrast: Float[Array, " C"]
    sigma: Float[Array, "G C"]


def build_foot_sigma_table(polar: PolarIndex, key: PRNGKeyArray, n_profiles: int, dof_per_sample: int = 2,
                           sigma_H_p=0.0, c_min=4.0, n_index: int = 16,
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
    cell = lambda args: foot_sigma_mc(polar, args[0], args[1], args[2], n_profiles, dof_per_sample, sigma_H_p,
                                      c_min)
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


