"""The camera's sensor: Gaussian noise per channel, 8-bit quantisation, optional JPEG.

The paper's noise model (section 3.2.1): i.i.d. zero-mean Gaussian noise of
standard deviation sigma in each colour band. Rounding to 8 bits adds the
quantisation error (variance 1/12 grey level^2 where the signal's fraction is
uniform), so the measured per-channel noise is ``sqrt(sigma^2 + 1/12)``
(:func:`effective_sigma`); pixels at 0 or 255 are clipped.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, Float, UInt8, UInt32

from ._image import own_buffer
from ._jpeg import jpeg
from ._noise import gaussian


def quantise(image: Float[Array, "*b"]) -> UInt8[Array, "*b"]:
    """Round grey levels to the nearest integer and clip to 0..255."""
    return jnp.clip(jnp.floor(image + 0.5), 0.0, 255.0).astype(jnp.uint8)


def draw_sensor_noise(sigma, key: UInt32[Array, "2"], shape: tuple[int, ...]) -> Float[Array, "*s"]:
    """``sigma N(0, 1)`` per pixel and channel (float32, grey levels), independent across pixels,
    channels and keys."""
    return jnp.asarray(sigma, jnp.float32) * gaussian(key, shape)


def digitise(image: Float[Array, "H W 3"], jpeg_quality: int = 0, keep=True) -> UInt8[Array, "H W 3"]:
    """Quantise a (noisy) image to 8 bits and JPEG-compress it if ``jpeg_quality`` (1..100) is given.

    Pass ``keep``, a run-time True (e.g. ``t >= 0`` of a traced frame index), to quantise
    into a buffer of its own before the JPEG model reads it (:func:`own_buffer`); else XLA
    fuses the noise into the JPEG's block transposes and evaluates it many times over."""
    out = quantise(image)
    return jpeg(own_buffer(out, keep), jpeg_quality) if jpeg_quality else out


def expose(
    linear: Float[Array, "H W 3"], sigma, key: UInt32[Array, "2"], jpeg_quality: int = 0
) -> UInt8[Array, "H W 3"]:
    """The 8-bit RGB frame of a noise-free image in grey levels: :func:`draw_sensor_noise` added,
    quantised, JPEG-compressed if ``jpeg_quality`` (1..100) is given."""
    return digitise(linear + draw_sensor_noise(sigma, key, linear.shape), jpeg_quality)


def effective_sigma(sigma: float) -> float:
    """Per-channel noise after 8-bit rounding, ``sqrt(sigma^2 + 1/12)`` (grey levels)."""
    return math.sqrt(sigma**2 + 1.0 / 12.0)
