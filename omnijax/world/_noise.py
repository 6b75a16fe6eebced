"""Counter-based random numbers for per-pixel work: hashed bits, uniforms, Gaussians, value noise.

The sensor needs an independent Gaussian per pixel and channel of every frame
(921,600 for one 640 x 480 RGB frame). ``jax.random``'s threefry takes about
14 ms for that on one CPU core, more than the whole frame budget, so the
renderer hashes a counter instead: two rounds of murmur3's 32-bit finaliser
(``mix32``) keyed by two words derived from the seed and the frame index give
the bits in about 0.25 ms, and ``sqrt(2) erfinv(2u - 1)`` turns 23-bit uniforms
into normals (tails to 5.3 sigma). ``tests/test_sensor.py`` checks mean,
variance, normality and the absence of correlation between neighbours and frames.

Keys are ``uint32`` pairs; every function here is pure and jittable.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, UInt32

#: 2^32 / golden ratio: the increment that spreads consecutive words over 32 bits.
GOLDEN = 0x9E3779B9


def mix32(x: UInt32[ArrayLike, "*b"]) -> UInt32[Array, "*b"]:
    """Murmur3's 32-bit finaliser: a bijection of uint32 with full avalanche."""
    x = jnp.asarray(x, jnp.uint32)
    x = x ^ (x >> 16)
    x = x * jnp.uint32(0x85EBCA6B)
    x = x ^ (x >> 13)
    x = x * jnp.uint32(0xC2B2AE35)
    return x ^ (x >> 16)


def as_u32(x: ArrayLike) -> UInt32[Array, "*b"]:
    """Integers (any sign, int32 or uint32) as uint32 bit patterns."""
    x = jnp.asarray(x)
    if x.dtype == jnp.uint32:
        return x
    return lax.bitcast_convert_type(x.astype(jnp.int32), jnp.uint32)


def derive_key(key: UInt32[ArrayLike, " 2 *k"], *words: ArrayLike) -> UInt32[Array, " 2 *b"]:
    """A new key from ``key`` and extra integers (frame index, stream id, ...); array words give
    an array of keys (stacked along the trailing axes)."""
    k0, k1 = jnp.asarray(key, jnp.uint32)[0], jnp.asarray(key, jnp.uint32)[1]
    for w in words:
        w = as_u32(w)
        k0 = mix32(k0 ^ mix32(w + jnp.uint32(GOLDEN)))
        k1 = mix32(k1 + k0 + w)
    return jnp.stack([k0, k1])


def key_from_seed(seed: int) -> UInt32[Array, "2"]:
    """The key of an integer seed (any Python int; reduced modulo 2^64)."""
    seed %= 2**64
    return derive_key(jnp.array([seed & 0xFFFFFFFF, seed >> 32], jnp.uint32), 0)


def hash_bits(key: UInt32[ArrayLike, " 2 *k"], counter: UInt32[ArrayLike, "*b"]) -> UInt32[Array, "*b"]:
    """32 random bits per counter value: ``mix32(mix32(c ^ k0) + k1)``."""
    key = jnp.asarray(key, jnp.uint32)
    return mix32(mix32(as_u32(counter) ^ key[0]) + key[1])


def uniform(bits: UInt32[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """Uniform on (0, 1) from the top 23 bits: ``(k + 0.5) / 2^23``, exact in float32 (with 24
    bits the largest value would round to 1.0), never 0 or 1."""
    hi = lax.convert_element_type(jnp.asarray(bits, jnp.uint32) >> 9, jnp.float32)
    return (hi + 0.5) * jnp.float32(2.0**-23)


def gaussian(key: UInt32[ArrayLike, "2"], shape: tuple[int, ...]) -> Float[Array, "*s"]:
    """Independent N(0, 1) samples (float32) of ``shape``: ``sqrt(2) erfinv(2u - 1)``."""
    n = math.prod(shape)
    u = uniform(hash_bits(key, lax.iota(jnp.uint32, n)))
    return (jnp.float32(math.sqrt(2.0)) * lax.erf_inv(2.0 * u - 1.0)).reshape(shape)


def lattice_uniform(key: UInt32[ArrayLike, " 2 *k"], i: ArrayLike, j: ArrayLike) -> Float[Array, "*b"]:
    """A uniform (0, 1) value attached to the integer lattice point (i, j)."""
    return uniform(hash_bits(key, mix32(as_u32(i)) ^ (as_u32(j) * jnp.uint32(GOLDEN))))


def value_noise(
    key: UInt32[ArrayLike, " 2 *k"], u: Float[ArrayLike, "*b"], v: Float[ArrayLike, "*b"]
) -> Float[Array, "*b"]:
    """Smooth noise in (-0.5, 0.5): lattice values interpolated with a smoothstep, period 1 in u and v."""
    u, v = jnp.asarray(u), jnp.asarray(v)
    fu, fv = jnp.floor(u), jnp.floor(v)
    i, j = fu.astype(jnp.int32), fv.astype(jnp.int32)
    su, sv = u - fu, v - fv
    su, sv = su * su * (3.0 - 2.0 * su), sv * sv * (3.0 - 2.0 * sv)
    a = lattice_uniform(key, i, j)
    b = lattice_uniform(key, i + 1, j)
    c = lattice_uniform(key, i, j + 1)
    d = lattice_uniform(key, i + 1, j + 1)
    top = a + (b - a) * su
    bottom = c + (d - c) * su
    return (top + (bottom - top) * sv - 0.5).astype(u.dtype)
