"""Small image operations shared by the renderer and the JPEG model, and a fusion boundary."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, Float


def upsample(x: Float[Array, "*b h w"], s: int) -> Float[Array, "*b hs ws"]:
    """Bilinear upsampling by an integer factor with pixel centres aligned (edges replicated).

    Output pixel ``s i + a`` lies at ``i + (a + 0.5) / s - 0.5`` on the input grid; each
    axis is a weighted sum of the input shifted by -1, 0 and +1, broadcast over the s
    phases (one elementwise loop, no gathers or concatenations)."""
    if s == 1:
        return x
    f = (np.arange(s) + 0.5) / s - 0.5
    weights = (np.maximum(-f, 0.0), 1.0 - np.abs(f), np.maximum(f, 0.0))  # for shifts -1, 0, +1
    for axis in (-2, -1):
        n = x.shape[axis]
        pad = [(0, 0)] * x.ndim
        pad[axis] = (1, 1)
        xp = jnp.pad(x, pad, mode="edge")
        shifted = [jnp.expand_dims(lax.slice_in_dim(xp, k, k + n, axis=axis), axis % x.ndim + 1) for k in range(3)]
        shape = [1] * (x.ndim + 1)
        shape[axis % x.ndim + 1] = s
        x = sum(jnp.asarray(w, x.dtype).reshape(shape) * v for w, v in zip(weights, shifted))
        new = list(x.shape)
        ax = axis % (x.ndim - 1)
        new[ax: ax + 2] = [n * s]
        x = x.reshape(new)
    return x


def own_buffer(x, keep):
    """``x`` (a PyTree of arrays; ``keep`` must be True) computed into buffers of its own before
    its consumers run.

    XLA's CPU fusion merges a costly per-pixel computation into a consumer that updates a
    window of a larger image (``dynamic_update_slice``), and then evaluates it once per
    element of the consumer (every colour channel) in a loop it cannot vectorise: several
    times slower. A conditional whose predicate is only known at run time is a fusion
    boundary that XLA keeps; ``lax.optimization_barrier`` is not (the CPU pipeline removes it
    before fusion)."""
    return lax.cond(keep, lambda v: v, lambda v: jax.tree.map(jnp.zeros_like, v), x)
