"""Uncertainty of the PTZ pointing, by four methods over the same inputs (eqs 13, 14; GUM).

The inputs are ``x = (r_f, theta_f, H_o, H_f, D_c, theta_c, r_m, H_p, R_h)`` with
independent Gaussian errors of standard deviations ``sigma`` (same order). The
outputs are ``y = (pan, tilt, sin pan, tan tilt)``; every method returns their
4 x 4 covariance as a :class:`PointingCovariance`.

- ``autodiff``: ``J Sigma_x J^T`` with ``J`` by forward-mode autodiff (``jax.jvp``, what ``jax.jacfwd``
  batches) of :func:`pointing`'s own code, by its two halves: each input feeds exactly one of
  ``(R_p, vartheta, D_c, aim)`` (``r_f, H_o, r_m`` the floor radius, ``theta_f, theta_c`` the azimuth,
  ``H_p, R_h, H_f`` the head's height over the PTZ), so ``J = J_2 J_1`` with ``J_1 Sigma_x J_1^T``
  diagonal, and the covariance is ``J_2 diag(var R_p, var vartheta, var D_c, var aim) J_2^T`` exactly:
  one tangent along each of the four through eqs 3-4 (:func:`~omnijax.geometry.pointing_from_floor`)
  and one along each of three through eq 1, the other arguments held (their zero tangents stay
  symbolic), and the ten distinct entries as scalar products. Over a floor grid most of the time
  was XLA recomputing sin and cos in every fused loop; :func:`~omnijax.geometry.sincos` computes
  them once.
- ``analytic``: the paper's closed forms, literally (eq 13, eq 14), with
  ``sigma_Rp^2`` and ``sigma_Dp^2`` from first-order propagation through eq 1 and
  eq 3 and ``sigma_vartheta^2 = sigma_theta_f^2 + sigma_theta_c^2``. They give the
  variances of ``tan tilt`` and ``sin pan`` only; pan and tilt variances follow to
  first order, and the paper has no covariance terms (zero here).
- ``second_order``: GUM (JCGM 100, 5.1.2 note) higher-order terms from
  ``jax.hessian`` and third derivatives.
- ``montecarlo``: :func:`pointing_covariance_mc`, adaptive in the manner of GUM
  Supplement 1 (JCGM 101, 7.9).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from ..camera import RadialProfile
from ..geometry import floor_radius, foveal_offsets, pointing, pointing_from_floor, wrap_pi

OUTPUT_NAMES: tuple[str, ...] = ("pan", "tilt", "sin_pan", "tan_tilt")
METHODS: tuple[str, ...] = ("autodiff", "analytic", "second_order", "montecarlo")


class PointingCovariance(eqx.Module):
    """Covariance of ``(pan, tilt, sin pan, tan tilt)`` (rad^2 and unitless), with validity."""

    cov: Float[Array, "*b 4 4"]
    valid: Bool[Array, "*b"]

    @property
    def var_pan(self) -> Array:
        return self.cov[..., 0, 0]

    @property
    def var_tilt(self) -> Array:
        return self.cov[..., 1, 1]

    @property
    def cov_pan_tilt(self) -> Array:
        return self.cov[..., 0, 1]

    @property
    def var_sin_pan(self) -> Array:
        return self.cov[..., 2, 2]

    @property
    def var_tan_tilt(self) -> Array:
        return self.cov[..., 3, 3]

    @property
    def pan_tilt(self) -> Float[Array, "*b 2 2"]:
        """The 2 x 2 covariance of (pan, tilt)."""
        return self.cov[..., :2, :2]


def pointing_outputs(x: Float[Array, "9"], profile: RadialProfile) -> Float[Array, "4"]:
    """``(pan, tilt, sin pan, tan tilt)`` of one input vector: the function every method propagates."""
    p = pointing(x, profile)
    return jnp.stack([p.pan, p.tilt, p.sin_pan, p.tan_tilt])


def _floor_outputs(R_p, vartheta, D_c, aim) -> tuple[Array, Array, Array, Array]:
    """``(pan, tilt, sin pan, tan tilt)`` of ``(R_p, vartheta, D_c, aim)``: :func:`pointing`'s second half."""
    p = pointing_from_floor(R_p, vartheta, D_c, aim)
    return p.pan, p.tilt, p.sin_pan, p.tan_tilt


def _along(f, args, i):
    """The derivative of ``f(*args)`` along its ``i``-th (scalar) argument: ``jax.jvp`` with the
    others held fixed, so their zero tangents stay symbolic and cost nothing."""
    return jax.jvp(lambda a: f(*args[:i], a, *args[i + 1:]), (args[i],), (jnp.ones_like(args[i]),))[1]


def _weighted_outer(cols, v) -> Float[Array, "m m"]:
    """``J diag(v) J^T = sum_k v_k c_k c_k^T`` from the columns ``c_k`` of ``J`` (m scalars each), its
    m (m + 1) / 2 distinct entries as scalar products: a batched dot or reduction over blocks this
    small is slow on XLA's CPU."""
    m = len(cols[0])
    e = {}
    for a in range(m):
        for b in range(a, m):
            e[a, b] = e[b, a] = sum(vk * c[a] * c[b] for vk, c in zip(v, cols))
    return jnp.stack([e[a, b] for a in range(m) for b in range(m)]).reshape(m, m)


def _autodiff_one(x, sigma, profile):
    r_f, theta_f, H_o, H_f, D_c, theta_c, r_m, H_p, R_h = x
    v_rf, v_thf, v_Ho, v_Hf, v_Dc, v_thc, v_rm, v_Hp, v_Rh = sigma**2
    radius = lambda r_f, H_o, r_m: floor_radius(r_f, r_m, H_o, profile)[0]
    a = (r_f, H_o, r_m)
    g_rf, g_Ho, g_rm = (_along(radius, a, i) for i in range(3))
    q = (radius(*a), theta_f - theta_c, D_c, H_p - R_h - H_f)
    var_q = (g_rf**2 * v_rf + g_Ho**2 * v_Ho + g_rm**2 * v_rm, v_thf + v_thc, v_Dc, v_Hp + v_Rh + v_Hf)
    return _weighted_outer([_along(_floor_outputs, q, k) for k in range(4)], var_q)


def gum_second_order(f, x: Float[Array, " n"], sigma: Float[Array, " n"]) -> Float[Array, "m m"]:
    """Covariance of ``f(x)`` for independent Gaussian inputs, to GUM's higher order.

    JCGM 100, 5.1.2 note, extended to a covariance: ``cov(a, b) = J_a Sigma J_b^T +
    sum_ij [H_a,ij H_b,ij / 2 + (J_a,i T_b,ijj + J_b,i T_a,ijj) / 2] sigma_i^2 sigma_j^2``,
    with ``H`` from ``jax.hessian``. Exact for quadratic ``f``.

    The third derivatives enter only as ``sum_ij J_a,i v_i T_b,ijj v_j``: the derivative of
    the variance-weighted Laplacian ``L_b = sum_j v_j d^2 f_b / dx_j^2`` along the direction
    ``J_a diag(v)``. So ``L`` is built from one second-order jvp per input and differentiated
    along the m output directions only (m n third-order passes instead of the full
    ``m n^3`` tensor of ``jacfwd(hessian)``, which was most of the time).
    """
    v = sigma**2
    J = jax.jacfwd(f)(x)
    H = jax.hessian(f)(x)
    eye = jnp.eye(x.shape[0], dtype=x.dtype)

    def laplacian(y):
        d2 = jax.vmap(lambda e: jax.jvp(lambda z: jax.jvp(f, (z,), (e,))[1], (y,), (e,))[1])(eye)  # (n, m)
        return (v[:, None] * d2).sum(0)

    third = jax.vmap(lambda w: jax.jvp(laplacian, (x,), (w,))[1])(J * v)  # (m, m): [a, b]
    Hv = H * v[None, :, None] * v[None, None, :]
    second = 0.5 * (H[:, None] * Hv[None, :]).sum((-1, -2))
    return _weighted_outer(list(J.T), v) + second + 0.5 * (third + third.T)


def _second_order_one(x, sigma, profile):
    return gum_second_order(lambda x: pointing_outputs(x, profile), x, sigma)


def _analytic_one(x, sigma, profile):
    """Eq 13 and eq 14 as printed (docs/design.md section 4.10)."""
    r_f, theta_f, H_o, H_f, D_c, theta_c, r_m, H_p, R_h = x
    v = sigma**2
    v_rf, v_thf, v_Ho, v_Hf, v_Dc, v_thc, v_rm, v_Hp, v_Rh = v

    radius = lambda r_f, H_o, r_m: floor_radius(r_f, r_m, H_o, profile)[0]
    R_p = radius(r_f, H_o, r_m)
    g_rf, g_Ho, g_rm = jax.grad(radius, argnums=(0, 1, 2))(r_f, H_o, r_m)
    var_R = g_rf**2 * v_rf + g_Ho**2 * v_Ho + g_rm**2 * v_rm

    vt = theta_f - theta_c
    var_vt = v_thf + v_thc
    distance = lambda R, vt, D_c: foveal_offsets(R, vt, D_c)[2]
    D_p = distance(R_p, vt, D_c)
    d_R, d_vt, d_Dc = jax.grad(distance, argnums=(0, 1, 2))(R_p, vt, D_c)
    var_D = d_R**2 * var_R + d_vt**2 * var_vt + d_Dc**2 * v_Dc

    aim = H_p - R_h - H_f
    var_aim = v_Hp + v_Rh + v_Hf
    var_tan_tilt = var_D / D_p**4 * (aim**2 + var_aim) + var_aim / D_p**2  # eq 13
    cos2, sin2 = jnp.cos(vt) ** 2, jnp.sin(vt) ** 2
    var_sin_pan = R_p**2 * var_vt * cos2 / D_p**2 + (sin2 + var_vt * cos2) * (  # eq 14
        R_p**2 * var_D / D_p**4 + var_R / D_p**2 + var_R * var_D / D_p**4
    )

    p = pointing(x, profile)
    var_pan = var_sin_pan / jnp.maximum(jnp.cos(p.pan) ** 2, 1e-12)  # d sin(pan) = cos(pan) d pan
    var_tilt = var_tan_tilt * jnp.cos(p.tilt) ** 4  # d tan(tilt) = d tilt / cos^2(tilt)
    return jnp.diag(jnp.stack([var_pan, var_tilt, var_sin_pan, var_tan_tilt]))


_KERNELS = {"autodiff": _autodiff_one, "analytic": _analytic_one, "second_order": _second_order_one}
#: The methods of :func:`pointing_covariance` (:data:`METHODS` less Monte Carlo, which is
#: :func:`pointing_covariance_mc`).
PROPAGATION_METHODS: tuple[str, ...] = tuple(_KERNELS)


@jax.jit
def pointing_covariance_full(x: Float[Array, "*b 9"], input_cov: Float[Array, "*b 9 9"],
                             profile: RadialProfile) -> PointingCovariance:
    """``autodiff`` with a full input covariance ``J Sigma_x J^T`` (e.g. a tracked foot's
    correlated (r_f, theta_f) beside the calibration's independent sigmas)."""
    batch = x.shape[:-1]
    xf, cf = x.reshape(-1, 9), jnp.broadcast_to(input_cov, (*batch, 9, 9)).reshape(-1, 9, 9)

    def one(xi, ci):
        J = jax.jacfwd(pointing_outputs)(xi, profile)
        return J @ ci @ J.T

    cov = jax.vmap(one)(xf, cf)
    return PointingCovariance(cov=cov.reshape(*batch, 4, 4), valid=pointing(xf, profile).valid.reshape(batch))


@eqx.filter_jit
def _covariance(x, sigma, profile, method):
    kernel = _KERNELS[method]
    batch = x.shape[:-1]
    xf, sf = x.reshape(-1, x.shape[-1]), jnp.broadcast_to(sigma, x.shape).reshape(-1, x.shape[-1])
    cov = jax.vmap(kernel, in_axes=(0, 0, None))(xf, sf, profile)
    valid = jax.vmap(lambda xi: pointing(xi, profile).valid)(xf)  # per point as the kernels: XLA shares their trig
    return PointingCovariance(cov=cov.reshape(*batch, 4, 4), valid=valid.reshape(batch))


def pointing_covariance(
    x: Float[Array, "*b 9"],
    sigma: Float[Array, "*#b 9"],
    profile: RadialProfile,
    method: Literal["autodiff", "analytic", "second_order"] = "autodiff",
) -> PointingCovariance:
    """Covariance of ``(pan, tilt, sin pan, tan tilt)`` at every input vector of ``x`` (jitted).

    ``x`` and ``sigma`` broadcast together; ``method`` is ``autodiff``, ``analytic``
    or ``second_order`` (for Monte Carlo see :func:`pointing_covariance_mc`).
    """
    if method not in _KERNELS:
        raise ValueError(f"method must be one of {sorted(_KERNELS)}, got {method!r}")
    x = jnp.asarray(x, float)
    return _covariance(x, jnp.asarray(sigma, float), profile, method)


class MonteCarloCovariance(eqx.Module):
    """Monte Carlo result: the covariance, trials used, and the tolerance reached.

    ``tolerance`` is the largest over the valid points and the four variances of
    ``2 s / sqrt(h) / mean``, with ``s`` the standard deviation of the ``h`` batch
    estimates: the relative half-width of a 95 % interval of the reported variance.
    ``mean`` is the Monte Carlo mean of the outputs.
    """

    covariance: PointingCovariance
    mean: Float[Array, "*b 4"]
    trials: int = eqx.field(static=True)
    batches: int = eqx.field(static=True)
    tolerance: float = eqx.field(static=True)


_PAIRS = tuple((a, b) for a in range(4) for b in range(a, 4))


@eqx.filter_jit
def _mc_batch(key, x, sigma, profile, n_chunks: int, chunk: int):
    """Sums of the output deviations and of their pairwise products over ``n_chunks * chunk`` trials.

    Deviations are taken from the outputs at the mean input, with pan wrapped to
    (-pi, pi], so that sums stay well conditioned and a pan near +-180 deg does not
    jump. The same normal draws serve every point (common random numbers).
    """
    p0 = pointing(x, profile)
    y0 = jnp.stack([p0.pan, p0.tilt, p0.sin_pan, p0.tan_tilt])  # (4, P)

    def step(carry, k):
        z = jax.random.normal(k, (chunk, x.shape[-1]), dtype=x.dtype)
        p = pointing(x[None] + sigma[None] * z[:, None], profile)
        d = jnp.stack([p.pan, p.tilt, p.sin_pan, p.tan_tilt]) - y0[:, None]  # (4, chunk, P)
        d = d.at[0].set(d[0] - 2 * jnp.pi * jnp.round(d[0] / (2 * jnp.pi)))
        s1 = d.sum(1)
        s2 = jnp.stack([(d[a] * d[b]).sum(0) for a, b in _PAIRS])
        return (carry[0] + s1, carry[1] + s2), None

    P = x.shape[0]
    init = (jnp.zeros((4, P), x.dtype), jnp.zeros((len(_PAIRS), P), x.dtype))
    (s1, s2), _ = jax.lax.scan(step, init, jax.random.split(key, n_chunks))
    idx = np.zeros((4, 4), int)
    for k, (a, b) in enumerate(_PAIRS):
        idx[a, b] = idx[b, a] = k
    return y0.T, s1.T, jnp.moveaxis(s2[idx], -1, 0)


def pointing_covariance_mc(
    x: Float[Array, "*b 9"],
    sigma: Float[Array, "*#b 9"],
    profile: RadialProfile,
    key: PRNGKeyArray,
    *,
    rel_tol: float = 0.01,
    batch: int = 2_000,
    min_batches: int = 10,
    max_trials: int = 1_000_000,
    chunk: int = 500,
    where=None,
    callback: Callable[[int, float], None] | None = None,
) -> MonteCarloCovariance:
    """Monte Carlo covariance of the pointing, adaptive as in GUM Supplement 1, 7.9.4.

    Batches of ``batch`` trials are drawn until, for every valid point and each of
    the four variances, twice the standard deviation of the ``h`` batch estimates
    divided by ``sqrt(h)`` is at most ``rel_tol`` times their mean, or ``max_trials``
    is spent. At least ``min_batches`` batches are drawn so that the spread itself
    is estimated with some confidence (GUM S1 allows two; with two, a lucky pair
    stops far too early). The reported covariance pools all trials.
    ``where`` (a mask of x's batch shape) limits the stopping rule to some points;
    ``callback(trials, tolerance)`` is called after every batch (for progress bars).
    """
    x = jnp.asarray(x, float)
    sigma = jnp.broadcast_to(jnp.asarray(sigma, float), x.shape)
    shape = x.shape[:-1]
    xf, sf = x.reshape(-1, x.shape[-1]), sigma.reshape(-1, x.shape[-1])
    valid = np.asarray(pointing(xf, profile).valid)
    watched = valid if where is None else valid & np.broadcast_to(np.asarray(where), shape).reshape(-1)
    chunk = min(chunk, batch)
    n_chunks = max(1, batch // chunk)
    per_batch = n_chunks * chunk
    sums1, sums2, batch_vars = 0.0, 0.0, []
    tol = math.inf
    h = 0
    while h * per_batch < max_trials:
        key, sub = jax.random.split(key)
        y0, s1, s2 = _mc_batch(sub, xf, sf, profile, n_chunks, chunk)
        s1, s2 = np.asarray(s1), np.asarray(s2)
        sums1, sums2 = sums1 + s1, sums2 + s2
        m = s1 / per_batch
        batch_vars.append(np.diagonal(s2 / per_batch, axis1=-2, axis2=-1) - m**2)
        h += 1
        if h >= max(2, min_batches):
            bv = np.stack(batch_vars)  # (h, P, 4)
            rel = 2 * bv.std(axis=0, ddof=1) / math.sqrt(h) / np.maximum(bv.mean(axis=0), 1e-300)
            tol = float(rel[watched].max()) if watched.any() else 0.0
        if callback is not None:
            callback(h * per_batch, tol)
        if tol <= rel_tol:
            break
    n = h * per_batch
    mean_dev = sums1 / n
    cov = (sums2 - n * np.einsum("pa,pb->pab", mean_dev, mean_dev)) / (n - 1)
    mean = np.asarray(y0) + mean_dev
    mean[:, 0] = np.asarray(wrap_pi(mean[:, 0]))  # pan back into [-pi, pi)
    return MonteCarloCovariance(
        covariance=PointingCovariance(cov=jnp.asarray(cov.reshape(*shape, 4, 4)),
                                      valid=jnp.asarray(valid.reshape(shape))),
        mean=jnp.asarray(mean.reshape(*shape, 4)),
        trials=n,
        batches=h,
        tolerance=tol,
    )
