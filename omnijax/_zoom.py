"""Zoom selection from the propagated pointing uncertainty (eq 15 and a calibrated rule).

Two rules choose the PTZ's angle of view, then the zoom factor through the lens
table, clamped to the device's zoom range:

- ``paper``: eq 15 as printed, ``gamma_v = 2 atan((R_h + f_v sigma_tan_tilt D'_p) /
  sqrt(R_h^2 + D'_p^2))`` with ``D'_p = D_p / cos(tilt)`` and ``f_v / 2 = Phi^-1((1 +
  p) / 2)`` (so ``f_v = 5.15`` at ``p = 0.99``), and its horizontal twin with
  ``sigma_sin_pan``. The zoom is the larger of the two angles' demands.
- ``calibrated``: the largest zoom for which the probability that the whole head
  disc lies inside the frame, under the joint Gaussian of the (pan, tilt) errors,
  is at least ``p_contain``.

The frame is treated in normalised image coordinates of the PTZ: a pointing error
``(e_pan, e_tilt)`` moves the head centre by ``(e_pan cos(tilt), e_tilt)``, the head
disc's radius is ``R_h / sqrt(d^2 - R_h^2)`` at distance ``d``, and the frame's
half-size is ``tan(fov / 2)``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import ndtr, ndtri
from jaxtyping import Array, Bool, Float

from ._config import Lens

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(64)
_BISECTION_STEPS = 48


def rectangle_probability(cov: Float[Array, "2 2"], half_w, half_h) -> Array:
    """P(|X| <= half_w and |Y| <= half_h) for (X, Y) ~ N(0, cov).

    Integrates the conditional normal of X given Y over Y with 64-point
    Gauss-Legendre quadrature on ``|y| <= min(half_h, 9 sigma_y)``; exact to
    ~1e-10 for correlations up to 0.99. Zero where a half-size is not positive.
    """
    sx = jnp.sqrt(jnp.maximum(cov[0, 0], 1e-300))
    sy = jnp.sqrt(jnp.maximum(cov[1, 1], 1e-300))
    rho = jnp.clip(cov[0, 1] / (sx * sy), -0.999999, 0.999999)
    b = jnp.minimum(jnp.maximum(half_h, 0.0), 9.0 * sy)
    y = b * jnp.asarray(_GL_NODES)
    cond_mean = rho * sx / sy * y
    cond_sd = sx * jnp.sqrt(1.0 - rho**2)
    a = jnp.maximum(half_w, 0.0)
    inner = ndtr((a - cond_mean) / cond_sd) - ndtr((-a - cond_mean) / cond_sd)
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


def _choose_calibrated(lens, cov4, tilt, slant, R_h, p_contain):
    prob = lambda z: containment_probability(lens, z, cov4[:2, :2], tilt, slant, R_h)  # noqa: E731
    lo, hi = jnp.log(lens.zoom_range[0]), jnp.log(lens.zoom_range[1])

    def step(_, bounds):
        a, b = bounds
        mid = 0.5 * (a + b)
        ok = prob(jnp.exp(mid)) >= p_contain
        return jnp.where(ok, mid, a), jnp.where(ok, b, mid)

    a, _ = jax.lax.fori_loop(0, _BISECTION_STEPS, step, (lo, hi))
    return jnp.where(prob(jnp.exp(hi)) >= p_contain, jnp.exp(hi), jnp.exp(a))


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
        raise ValueError(f"zoom rule must be 'paper' or 'calibrated', got {rule!r}")
    fov_h, fov_v = lens.fov(zoom)
    prob = containment_probability(lens, zoom, cov4[:2, :2], tilt, slant, R_h)
    return ZoomChoice(zoom=zoom, fov_h=fov_h, fov_v=fov_v, probability=prob, feasible=prob >= p_contain)
