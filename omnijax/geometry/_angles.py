"""Angle wrapping: the two ranges omnijax uses, each written once.

- :func:`wrap_pi`: differences of angles (pan errors, residuals, azimuth offsets), into [-pi, pi);
- :func:`wrap_2pi`: azimuths in the omni image (sector edges), into [0, 2 pi).

Both take JAX or NumPy arrays (traced or not; the result is a JAX array whose
derivative is 1 everywhere) and Python floats, which stay Python floats through
``math`` so that the real-time loop's per-frame scalar code pays no array overhead.
An angle already in range comes back unchanged, bit for bit.
"""

from __future__ import annotations

import math
from math import pi, remainder

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike

TAU = 2 * math.pi


def wrap_pi(a: float | ArrayLike) -> float | Array:
    """``a`` (rad) wrapped into [-pi, pi)."""
    if type(a) is float or isinstance(a, float | int):  # the cheap test first: the loop's per-frame path
        r = remainder(a, TAU)  # exact, in [-pi, pi]
        return r if r < pi else r - TAU
    a = jnp.asarray(a)
    w = jnp.mod(a + jnp.pi, TAU) - jnp.pi
    w = jnp.where(w < jnp.pi, w, w - TAU)  # mod may round up to 2 pi
    return jnp.where((a >= -jnp.pi) & (a < jnp.pi), a, w)


def wrap_2pi(a: float | ArrayLike) -> float | Array:
    """``a`` (rad) wrapped into [0, 2 pi)."""
    if type(a) is float or isinstance(a, float | int):
        r = a % TAU
        return r if r < TAU else 0.0
    r = jnp.mod(a, TAU)
    return jnp.where(r < TAU, r, 0.0)  # a tiny negative angle rounds up to 2 pi
