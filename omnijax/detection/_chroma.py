"""Normalised colour (chromaticity) and its covariance under sensor noise: eq 5.

``r = R / S``, ``g = G / S`` with ``S = R + G + B``. With i.i.d. Gaussian noise of
standard deviation ``sigma`` on each channel, first-order propagation gives eq 5,
which is exactly ``J sigma^2 I J^T`` for the Jacobian of ``(r, g)``. Dark pixels
(``S -> 0``) get a huge but finite variance, never NaN.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

#: Sums below this (grey levels) are treated as this: chromaticity is undefined in the dark.
S_MIN = 1.0


def chromaticity(rgb: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 2"]:
    """``(r, g) = (R, G) / (R + G + B)``; at ``S < S_MIN`` the sum is taken as ``S_MIN``."""
    rgb = jnp.asarray(rgb)
    r, g = chromaticity_planes(rgb[..., 0], rgb[..., 1], rgb[..., 2])[:2]
    return jnp.stack([r, g], -1)


def chromaticity_covariance(rgb: Float[ArrayLike, "*b 3"], sigma) -> Float[Array, "*b 2 2"]:
    """Eq 5: covariance of ``(r, g)`` for mean colour ``rgb`` and per-channel noise ``sigma``.

    ``Sigma = sigma^2 / S^2 [[1 - 2R/S + 3R^2/S^2, -(R+G)/S + 3RG/S^2],
    [., 1 - 2G/S + 3G^2/S^2]]``, with ``S`` floored at ``S_MIN``.
    """
    rgb = jnp.asarray(rgb)
    _, _, rr, rg, gg = chromaticity_planes(rgb[..., 0], rgb[..., 1], rgb[..., 2])
    k = jnp.asarray(sigma) ** 2
    return k[..., None, None] * jnp.stack([jnp.stack([rr, rg], -1), jnp.stack([rg, gg], -1)], -2)


def chromaticity_planes(R: Float[ArrayLike, "*b"], G: Float[ArrayLike, "*b"], B: Float[ArrayLike, "*b"]):
    """``(r, g)`` and eq 5's covariance entries per unit noise variance, ``(r, g, rr, rg, gg)``.

    Channel planes in, planes out: the elementwise form the per-pixel kernels use
    (arrays with a trailing axis of 3 vectorise poorly on the CPU).
    """
    S = jnp.maximum(R + G + B, S_MIN)
    inv = 1.0 / S
    r, g = R * inv, G * inv
    k = inv * inv
    return r, g, k * (1 - 2 * r + 3 * r * r), k * (-(r + g) + 3 * r * g), k * (1 - 2 * g + 3 * g * g)
