"""The omni image's usable circle from one frame: mirror rim or fisheye image circle.

The paper (section 3.2.3) has the image centre ``p(x_c, y_c)`` and the mirror
radius ``r_m`` "initialised during calibration". Here they are measured: along
``n_rays`` rays from a centre guess the radial brightness profile is smoothed and
differentiated, and its outermost strong drop (bright image inside, dark outside)
is the rim point of that ray (sub-pixel by a parabola through the peak). A circle is
fitted to those points by iteratively reweighted geometric least squares
(optimistix Levenberg-Marquardt) with Cauchy weights and a MAD scale, so that
rays that miss the rim (the disc leaves the frame, something covers it, a
stronger edge inside) do not pull it. The covariance of ``(x_c, y_c, radius)`` is
``s^2 (J^T W J)^-1`` from the Jacobian at the solution and the weighted residual
scale ``s``: it is the statistical error of the edge points only (a mirror whose
rim is not a circle about the optical axis is a systematic error on top).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.scipy.ndimage import map_coordinates
from jaxtyping import Array, ArrayLike, Bool, Float, Real

#: Cauchy weight constant (95 % efficiency at Gaussian errors), in units of the residual scale.
CAUCHY_C = 2.3849
#: Reweighting rounds of the robust fit.
IRLS_ROUNDS = 10
#: Standard deviation (px) of the Gaussian that smooths a radial profile before differentiating,
#: when locating the edge (pass 2); pass 1 looks at a coarser scale, a fraction of the radius.
SMOOTH_PX = 1.5
COARSE_SMOOTH = 0.01
#: On each ray the rim is the outermost drop at least this fraction of the ray's strongest drop
#: (beyond the rim there is no image, so no drop as large; inside, edges of the scene may be sharper).
OUTERMOST_FRACTION = 0.5
#: A ray whose rim drop is weaker than this fraction of the median ray's did not see the rim.
WEAK_FRACTION = 0.2


class RimEdges(eqx.Module):
    """The rim's radial brightness drop on each ray: its pixel (x, y), its strength
    (grey levels per px) and whether the ray had image all around it."""

    points: Float[Array, "n 2"]
    strength: Float[Array, " n"]
    ok: Bool[Array, " n"]


class RimFit(eqx.Module):
    """A robust circle fit: centre (x_c, y_c) and radius (px), covariance of the three,
    residual scale (px), the final Cauchy weights and how many points count as inliers
    (|residual| < 3 scales)."""

    center: Float[Array, "2"]
    radius: Float[Array, ""]
    cov: Float[Array, "3 3"]
    scale: Float[Array, ""]
    weights: Float[Array, " n"]
    residuals: Float[Array, " n"]
    inliers: Array
    converged: Bool[Array, ""]


def _gaussian_derivative(step: float, smooth: float) -> Array:
    """Taps of the derivative of a Gaussian (sigma ``smooth`` px) for samples ``step`` px apart, per px."""
    sd = smooth / step
    half = int(math.ceil(3 * sd))
    t = jnp.arange(-half, half + 1, dtype=jnp.float32)
    g = jnp.exp(-0.5 * (t / sd) ** 2)
    dg = -t * g / (sd**2 * jnp.sum(g))
    return dg / step  # jnp.convolve(f, dg) is f * g', the smoothed derivative


@eqx.filter_jit
def rim_edges(
    gray: Real[ArrayLike, "H W"], center: Float[ArrayLike, "2"], r_start: Float[ArrayLike, ""],
    step: float, n_r: int, n_rays: int, smooth: float = SMOOTH_PX, whole_rays: bool = False,
) -> RimEdges:
    """The rim's brightness drop along ``n_rays`` rays from ``center`` (px): on each ray the
    outermost drop that is at least ``OUTERMOST_FRACTION`` of the ray's strongest.

    Each ray is sampled (bilinear) at ``n_r`` radii ``r_start + step * i`` (px); a
    ray counts (``ok``) where the smoothing kernel around its edge lies inside the
    image, its drop is at least ``WEAK_FRACTION`` of the median ray's, and, with
    ``whole_rays``, every sample of the ray is inside the image (a rim that leaves
    the frame is then not mistaken for an edge inside it). The profile is smoothed
    by a Gaussian of ``smooth`` px before it is differentiated. ``step``,
    ``smooth``, ``whole_rays`` and the counts are static.
    """
    gray = jnp.asarray(gray, jnp.float32)
    center = jnp.asarray(center, jnp.float32)
    radii = jnp.asarray(r_start, jnp.float32) + step * jnp.arange(n_r, dtype=jnp.float32)
    kernel = _gaussian_derivative(step, smooth)
    half = (kernel.shape[0] - 1) // 2
    angles = jnp.arange(n_rays, dtype=jnp.float32) * (2 * math.pi / n_rays)
    cos_a, sin_a = jnp.cos(angles)[:, None], jnp.sin(angles)[:, None]
    xs = center[0] + radii[None, :] * cos_a
    ys = center[1] + radii[None, :] * sin_a
    h, w = gray.shape
    inside = (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    samples = map_coordinates(gray, [ys.ravel(), xs.ravel()], order=1, mode="nearest").reshape(xs.shape)
    deriv = jax.vmap(lambda row: jnp.convolve(row, kernel, mode="same"))(samples)
    # Only where the whole kernel sees image pixels; the first and last `half` samples are padding.
    support = jax.vmap(lambda row: jnp.convolve(row.astype(jnp.float32), jnp.ones(2 * half + 1), mode="same"))(inside)
    usable = support > 2 * half + 0.5
    idx = jnp.arange(radii.shape[0])
    usable = usable & (idx >= half)[None, :] & (idx < radii.shape[0] - half)[None, :]
    drop = jnp.where(usable, -deriv, -jnp.inf)
    strong = drop >= OUTERMOST_FRACTION * jnp.max(drop, axis=1, keepdims=True)
    k_out = jnp.max(jnp.where(strong, idx[None, :], 0), axis=1)
    # the peak of that outermost strong drop lies within one kernel width inward
    window = (idx[None, :] <= k_out[:, None]) & (idx[None, :] >= k_out[:, None] - 2 * half)
    k = jnp.argmax(jnp.where(window, drop, -jnp.inf), axis=1)
    k_in = jnp.clip(k, 1, radii.shape[0] - 2)
    take = lambda a, i: jnp.take_along_axis(a, i[:, None], axis=1)[:, 0]
    d0, dm, dp = take(drop, k_in), take(drop, k_in - 1), take(drop, k_in + 1)
    finite = jnp.isfinite(dm) & jnp.isfinite(dp)
    denom = jnp.where(finite, dm - 2 * d0 + dp, -1.0)
    shift = jnp.where(finite & (denom < 0), jnp.clip(0.5 * (dm - dp) / denom, -0.5, 0.5), 0.0)
    r_edge = radii[0] + (k_in + shift) * step
    strength = take(drop, k)
    ok = jnp.isfinite(strength) & (strength > 0) & (k == k_in)
    if whole_rays:
        ok = ok & jnp.all(inside, axis=1)
    ok = ok & (strength >= WEAK_FRACTION * jnp.nanmedian(jnp.where(ok, strength, jnp.nan)))
    points = jnp.stack([center[0] + r_edge * cos_a[:, 0], center[1] + r_edge * sin_a[:, 0]], axis=-1)
    return RimEdges(points=points, strength=jnp.where(ok, strength, 0.0), ok=ok)


def _circle_residuals(c: Float[Array, "3"], points: Float[Array, "n 2"]) -> Float[Array, " n"]:
    """Geometric distance of each point from the circle (x_c, y_c, radius), px."""
    return jnp.hypot(points[:, 0] - c[0], points[:, 1] - c[1]) - c[2]


def _mad_scale(e: Array, ok: Array) -> Array:
    """1.4826 median absolute residual over the usable points (robust sigma), at least 1e-3 px."""
    med = jnp.nanmedian(jnp.where(ok, jnp.abs(e), jnp.nan))
    return jnp.maximum(1.4826 * med, 1e-3)


@eqx.filter_jit
def fit_circle(points: Float[ArrayLike, "n 2"], ok: Bool[ArrayLike, " n"], init: Float[ArrayLike, "3"]) -> RimFit:
    """Robust geometric circle fit (Cauchy IRLS, optimistix Levenberg-Marquardt) from ``init`` = (x_c, y_c, r).

    Each round recomputes the scale (MAD of the residuals) and the Cauchy weights
    ``1 / (1 + (e / (c s))^2)`` and solves the weighted least squares. The
    covariance is ``s_w^2 (J^T W J)^-1`` with ``s_w^2 = sum w e^2 / (sum w - 3)``.
    """
    points = jnp.asarray(points, float)
    ok = jnp.asarray(ok)
    solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)

    def weighted(c, w):
        return jnp.sqrt(w) * jnp.where(ok, _circle_residuals(c, points), 0.0)

    def weights_at(c):
        e = _circle_residuals(c, points)
        s = _mad_scale(e, ok)
        return jnp.where(ok, 1.0 / (1.0 + (e / (CAUCHY_C * s)) ** 2), 0.0)

    def round_(_, carry):
        c, _ = carry
        sol = optx.least_squares(weighted, solver, c, args=weights_at(c), max_steps=100, throw=False)
        return sol.value, sol.result == optx.RESULTS.successful

    c, converged = jax.lax.fori_loop(0, IRLS_ROUNDS, round_, (jnp.asarray(init, float), jnp.array(True)))
    w = weights_at(c)
    e = jnp.where(ok, _circle_residuals(c, points), 0.0)
    J = jax.jacfwd(weighted)(c, w)
    s2 = jnp.sum(w * e**2) / jnp.maximum(jnp.sum(w) - 3.0, 1.0)
    cov = s2 * jnp.linalg.inv(J.T @ J)
    scale = _mad_scale(e, ok)
    inliers = jnp.sum(ok & (jnp.abs(e) < 3 * scale))
    return RimFit(center=c[:2], radius=c[2], cov=cov, scale=scale, weights=w, residuals=e,
                  inliers=inliers, converged=converged)


def fit_rim(
    gray: Real[ArrayLike, "H W"], center: tuple[float, float], radius: float, search: float = 0.25,
    n_rays: int = 720, step: float = 0.5,
) -> tuple[RimFit, RimEdges]:
    """The rim circle of one grey frame, from a guess of its centre and radius (px).

    Pass 1 looks for the edge within ``radius * (1 +- search)`` along rays from the
    guess, at a coarse scale (profiles smoothed over 1 % of the radius, so that
    the rim's large brightness drop beats sharp but weaker edges inside the
    image); pass 2 looks again within 3 % (at least 8 px) of the pass-1 circle,
    along rays from its centre, at the fine scale, using only rays that stay inside
    the frame over that window, and fits once more. Returns the final fit and its
    edge points.
    """
    fit = None
    lo, hi = radius * (1 - search), radius * (1 + search)
    c0 = jnp.asarray(center, float)
    init = jnp.array([center[0], center[1], radius], float)
    for smooth, whole in ((max(SMOOTH_PX, COARSE_SMOOTH * radius), False), (SMOOTH_PX, True)):
        lo = max(lo, 2 * smooth)
        edges = rim_edges(gray, c0, jnp.asarray(lo), step, int((hi - lo) / step), n_rays, smooth, whole)
        fit = fit_circle(edges.points, edges.ok, init)
        r1 = float(fit.radius)
        margin = max(0.03 * r1, 8.0)
        lo, hi = r1 - margin, r1 + margin
        c0 = fit.center
        init = jnp.concatenate([fit.center, fit.radius[None]])
    return fit, edges
