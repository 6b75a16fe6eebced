"""Zoom selection from the propagated pointing uncertainty (eq 15 and a calibrated rule).

Two rules choose the PTZ's angle of view, then the zoom factor through the lens
table, clamped to the device's zoom range:

- ``paper``: eq 15 as printed, ``gamma_v = 2 atan((R_h + f_v sigma_tan_tilt D'_p) /
  sqrt(R_h^2 + D'_p^2))`` with ``D'_p = D_p / cos(tilt)`` and ``f_v / 2 = Phi^-1((1 +
  p) / 2)`` (so ``f_v = 5.15`` at ``p = 0.99``), and its horizontal twin with
  ``sigma_sin_pan``. The zoom is the larger of the two angles' demands.
- ``calibrated``: the largest zoom for which the probability that the whole head
  disc lies inside the frame, under the joint Gaussian of the (pan, tilt) errors,
  is at least ``p_contain``. It is a root of ``P(frame) = p_contain``, found by
  false position inside a closed-form bracket; its derivatives come from the
  implicit function theorem (a ``jax.custom_jvp``), so the layout optimiser can
  differentiate the face pixels through it. (``optimistix.root_find`` was measured
  against it on 400 covariances, one core: its Newton, Chord and Bisection were 1.8
  to 9 times slower vmapped, and every derivative through ``ImplicitAdjoint`` holds a
  host callback, lineax's error check, which keeps ``omnijax optimise``'s program out
  of the persistent compilation cache: 6-7 s warm runs became 18-20 s.)

The frame is treated in normalised image coordinates of the PTZ: a pointing error
``(e_pan, e_tilt)`` moves the head centre by ``(e_pan cos(tilt), e_tilt)``, the head
disc's radius is ``R_h / sqrt(d^2 - R_h^2)`` at distance ``d``, and the frame's
half-size is ``tan(fov / 2)``.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erf, ndtri
from jaxtyping import Array, Bool, Float

from ..config import Lens
from ..config._config import ZOOM_RULES

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(64)
#: The calibrated rule's root finder stops once the containment probability's normal
#: score is within this of its target ...
_ROOT_ATOL = 1e-12
_ROOT_MAX_STEPS = 40
#: ... which sits this far above p_contain's, so that the zoom found meets p_contain
#: (by about 3e-11 in probability at p_contain = 0.99).
_ROOT_MARGIN = 1e-9


def rectangle_probability(cov: Float[Array, "2 2"], half_w, half_h) -> Array:
    """P(|X| <= half_w and |Y| <= half_h) for (X, Y) ~ N(0, cov).

    Integrates the conditional normal of X given Y over Y with 64-point
    Gauss-Legendre quadrature on ``|y| <= min(half_h, 9 sigma_y)``; exact to
    ~1e-10 for correlations up to 0.99. Zero where a half-size is not positive.
    The conditional probability is a difference of ``erf`` (absolute error
    ~1e-16, all that a sum of probabilities needs): one transcendental per bound,
    nine times faster than two ``ndtr`` (which evaluate ``erf`` and ``erfc`` each).
    """
    sx = jnp.sqrt(jnp.maximum(cov[0, 0], 1e-300))
    sy = jnp.sqrt(jnp.maximum(cov[1, 1], 1e-300))
    rho = jnp.clip(cov[0, 1] / (sx * sy), -0.999999, 0.999999)
    b = jnp.minimum(jnp.maximum(half_h, 0.0), 9.0 * sy)
    y = b * jnp.asarray(_GL_NODES)
    cond_mean = rho * sx / sy * y
    cond_sd = sx * jnp.sqrt(1.0 - rho**2)
    a = jnp.maximum(half_w, 0.0)
    k = 1.0 / (cond_sd * jnp.sqrt(2.0))
    inner = 0.5 * (erf((a - cond_mean) * k) - erf((-a - cond_mean) * k))
    dens = jnp.exp(-0.5 * (y / sy) ** 2) / (sy * jnp.sqrt(2 * jnp.pi))
    p = b * jnp.sum(jnp.asarray(_GL_WEIGHTS) * dens * inner)
    return jnp.where((half_w > 0) & (half_h > 0), jnp.clip(p, 0.0, 1.0), 0.0)


def head_half_size(slant, R_h) -> Array:
    """Radius of the head disc in normalised image coordinates, ``tan(asin(R_h / d))``."""
    return R_h / jnp.sqrt(jnp.maximum(slant**2 - R_h**2, 1e-12))


def image_covariance(cov_pan_tilt: Float[Array, "2 2"], tilt) -> Float[Array, "2 2"]:
    """Covariance of the head's offset in normalised image coordinates from (pan, tilt) errors."""
    scale = jnp.stack([jnp.cos(tilt), jnp.ones_like(tilt)])
    return cov_pan_tilt * scale[:, None] * scale[None, :]


def containment_probability(lens: Lens, zoom, cov_pan_tilt, tilt, slant, R_h) -> Array:
    """Probability that the whole head disc is inside the PTZ frame at ``zoom``."""
    fov_h, fov_v = lens.fov(zoom)
    rho = head_half_size(slant, R_h)
    cov = image_covariance(cov_pan_tilt, tilt)
    return rectangle_probability(cov, jnp.tan(0.5 * fov_h) - rho, jnp.tan(0.5 * fov_v) - rho)


def face_pixels(lens: Lens, zoom, slant, R_h) -> Array:
    """Width of the head (its diameter) in foveal pixels at ``zoom`` and distance ``slant``."""
    fov_h, _ = lens.fov(zoom)
    return lens.image_size[0] * head_half_size(slant, R_h) / jnp.tan(0.5 * fov_h)


class ZoomChoice(eqx.Module):
    """The chosen zoom, its angles of view (rad), the containment probability it gives
    under the Gaussian model, and whether ``p_contain`` is met within the zoom range."""

    zoom: Float[Array, ""]
    fov_h: Float[Array, ""]
    fov_v: Float[Array, ""]
    probability: Float[Array, ""]
    feasible: Bool[Array, ""]


def paper_fov(var_sin_pan, var_tan_tilt, distance, tilt, R_h, p_contain) -> tuple[Array, Array]:
    """Eq 15 as printed and its horizontal twin: ``(gamma_h, gamma_v)`` in rad."""
    f = 2.0 * ndtri(0.5 * (1.0 + p_contain))
    d_prime = distance / jnp.cos(tilt)
    denom = jnp.sqrt(R_h**2 + d_prime**2)
    gamma_v = 2.0 * jnp.arctan((R_h + f * jnp.sqrt(var_tan_tilt) * d_prime) / denom)
    gamma_h = 2.0 * jnp.arctan((R_h + f * jnp.sqrt(var_sin_pan) * d_prime) / denom)
    return gamma_h, gamma_v


def _choose_paper(lens, cov4, distance, tilt, R_h, p_contain):
    gamma_h, gamma_v = paper_fov(cov4[2, 2], cov4[3, 3], distance, tilt, R_h, p_contain)
    t_h = jnp.maximum(jnp.tan(0.5 * gamma_h), jnp.tan(0.5 * gamma_v) / lens.aspect)
    return lens.clamp(lens.zoom_for_tan_half_fov_h(t_h))


def _frame_probability(t, cov, rho, aspect) -> Array:
    """Containment probability with the frame's half-width ``tan(fov_h / 2) = t`` (height ``aspect t``)."""
    return rectangle_probability(cov, t - rho, aspect * t - rho)


def _frame_bracket(cov, rho, aspect, p_contain) -> tuple[Array, Array]:
    """Half-widths ``t_lo <= t* <= t_hi`` around the one where the containment probability is ``p_contain``.

    The rectangle's probability is at most either axis' own (so at ``t_lo``, where
    the tighter axis alone holds ``p_contain``, it is at most ``p_contain``) and at
    least their sum minus one (Bonferroni: at ``t_hi``, where each axis holds
    ``(1 + p_contain) / 2``, it is at least ``p_contain``). ``t_hi / t_lo`` is about 1.1.
    """
    sx, sy = jnp.sqrt(jnp.maximum(cov[0, 0], 0.0)), jnp.sqrt(jnp.maximum(cov[1, 1], 0.0))
    need = lambda k: jnp.maximum(rho + k * sx, (rho + k * sy) / aspect)
    return need(ndtri(0.5 * (1.0 + p_contain))), need(ndtri(1.0 - 0.25 * (1.0 - p_contain)))


def _score_excess(t, cov, rho, aspect, target) -> Array:
    """Normal score ``Phi^-1((1 + P) / 2)`` of the containment probability at half-width ``t``, minus ``target``.

    The score is linear in ``t`` when one axis dominates (it is then ``(t - rho) /
    sigma``) and nearly so otherwise, which is what the root finder wants.
    """
    return ndtri(0.5 * (1.0 + _frame_probability(t, cov, rho, aspect))) - target


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _frame_root(aspect, cov, rho, target, a, b, g_a, g_b, solve, t_safe):
    """Root of :func:`_score_excess` in ``[a, b]`` (``g_a < 0 <= g_b``) by false position (Illinois).

    Lanes with ``solve`` False return ``a`` untouched. Derivatives (w.r.t. ``cov``,
    ``rho``, ``target``) follow from the implicit function theorem; lanes not solved
    evaluate them at ``t_safe``, where the score is finite, and get zero.
    """
    g = functools.partial(_score_excess, cov=cov, rho=rho, aspect=aspect, target=target)

    def step(state):
        a, b, g_a, g_b, _, _, side, k = state
        t = jnp.clip(b - g_b * (b - a) / (g_b - g_a), a, b)
        g_t = g(t)
        up = g_t >= 0  # the root lies in [a, t]: t replaces b
        return (jnp.where(up, a, t), jnp.where(up, t, b),
                jnp.where(up, g_a * jnp.where(side > 0, 0.5, 1.0), g_t),
                jnp.where(up, g_t, g_b * jnp.where(side < 0, 0.5, 1.0)),
                t, g_t, jnp.where(up, 1, -1), k + 1)

    def unfinished(state):
        return (jnp.abs(state[5]) > _ROOT_ATOL) & (state[7] < _ROOT_MAX_STEPS)

    start = (a, b, g_a, g_b, a, jnp.where(solve, jnp.inf, 0.0), 0, 0)
    return jax.lax.while_loop(unfinished, step, start)[4]


@_frame_root.defjvp
def _frame_root_jvp(aspect, primals, tangents):
    """Implicit function theorem: ``dt = -(dg/dcov dcov + dg/drho drho + dg/dtarget dtarget) / (dg/dt)``.

    The partial derivatives come from one reverse pass over the primal values, so
    they are computed once however many tangents are pushed through (jacfwd).
    """
    cov, rho, target, *_, solve, t_safe = primals
    d_cov, d_rho, d_target = tangents[:3]
    t = _frame_root(aspect, *primals)
    at = jnp.where(solve, t, t_safe)
    g_t, g_cov, g_rho, g_target = jax.grad(_score_excess, argnums=(0, 1, 2, 4))(at, cov, rho, aspect, target)
    dg = jnp.sum(g_cov * d_cov) + g_rho * d_rho + g_target * d_target
    return t, jnp.where(solve, -dg / jnp.where(solve, g_t, 1.0), 0.0)


def _choose_calibrated(lens, cov4, tilt, slant, R_h, p_contain):
    """Largest zoom in the device's range whose containment probability is at least ``p_contain``.

    Solved for the frame's half-width ``t = tan(fov_h / 2)``, on which the
    probability rises: :func:`_frame_bracket` clipped to the zoom range gives
    ``[a, b]``; if ``P(a) >= p_contain`` with ``a`` the longest zoom's half-width,
    that zoom is chosen; if ``P(b) < p_contain`` with ``b`` the widest zoom's, the
    widest (infeasible); otherwise false position on the normal score (at most
    about 6 evaluations of ``P`` without derivatives) finds the root, aiming
    ``_ROOT_MARGIN`` above ``p_contain`` so that the zoom returned is feasible.
    Derivatives: implicit function theorem; zero in the clamped cases.
    """
    rho = head_half_size(slant, R_h)
    cov = image_covariance(cov4[:2, :2], tilt)
    t_min = jnp.tan(0.5 * lens.fov(lens.zoom_range[1])[0])
    t_max = jnp.tan(0.5 * lens.fov(lens.zoom_range[0])[0])
    t_lo, t_hi = _frame_bracket(cov, rho, lens.aspect, p_contain)
    a, b = jnp.clip(t_lo, t_min, t_max), jnp.clip(t_hi, t_min, t_max)
    p_a = _frame_probability(a, cov, rho, lens.aspect)
    p_b = _frame_probability(b, cov, rho, lens.aspect)
    longest_ok = (a <= t_min) & (p_a >= p_contain)
    widest_fails = p_b < p_contain
    solve = ~longest_ok & ~widest_fails
    target = ndtri(0.5 * (1.0 + p_contain)) + _ROOT_MARGIN
    score = lambda p: ndtri(0.5 * (1.0 + p)) - target
    t = _frame_root(lens.aspect, cov, rho, target, a, b, score(p_a), score(p_b), solve, t_lo)
    zoom = lens.clamp(lens.zoom_for_tan_half_fov_h(t))
    return jnp.where(longest_ok, lens.zoom_range[1], jnp.where(widest_fails, lens.zoom_range[0], zoom))


def choose_zoom(lens: Lens, rule: str, cov4: Float[Array, "4 4"], distance, tilt, slant, R_h, p_contain) -> ZoomChoice:
    """Zoom for one person from the 4 x 4 pointing covariance (see the module docstring).

    ``distance`` is D_p and ``slant`` D'_p (m); the result is clamped to the zoom
    range, and ``feasible`` says whether ``p_contain`` is met there (Gaussian model).
    """
    if rule == "paper":
        zoom = _choose_paper(lens, cov4, distance, tilt, R_h, p_contain)
    elif rule == "calibrated":
        zoom = _choose_calibrated(lens, cov4, tilt, slant, R_h, p_contain)
    else:
        raise ValueError(f"zoom rule must be one of {ZOOM_RULES}, got {rule!r}")
    fov_h, fov_v = lens.fov(zoom)
    prob = containment_probability(lens, zoom, cov4[:2, :2], tilt, slant, R_h)
    return ZoomChoice(zoom=zoom, fov_h=fov_h, fov_v=fov_v, probability=prob, feasible=prob >= p_contain)
