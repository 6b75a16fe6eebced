"""JPEG's loss in JAX: what a baseline JPEG encoder and decoder do to an 8-bit RGB image.

The lossy steps of baseline JPEG (JFIF), in the order of the IJG library with
its defaults: RGB -> YCbCr (8-bit), 4:2:0 chroma subsampling (2 x 2 means),
8 x 8 DCT of each plane less 128, quantisation with the standard luminance and
chrominance tables (Annex K of the standard) scaled by ``quality`` with the IJG
rule, and back: dequantisation, inverse DCT, rounding and clamping, the
"fancy" (bilinear) chroma upsampling, YCbCr -> RGB. The entropy coding is
lossless and omitted. ``tests/test_sensor.py`` compares it with OpenCV's
``imencode``/``imdecode`` (libjpeg-turbo, integer DCT): they agree to about one
grey level.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, UInt8

from ._image import upsample

_LUMA = np.array([
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55,
    14, 13, 16, 24, 40, 57, 69, 56, 14, 17, 22, 29, 51, 87, 80, 62,
    18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
    49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99,
], float).reshape(8, 8)
_CHROMA = np.array([
    17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99,
    24, 26, 56, 99, 99, 99, 99, 99, 47, 66, 99, 99, 99, 99, 99, 99,
] + [99] * 32, float).reshape(8, 8)


def quant_tables(quality: int) -> tuple[np.ndarray, np.ndarray]:
    """IJG scaling of the Annex K tables: ``scale = 5000 / q`` below 50, ``200 - 2 q`` above."""
    if not 1 <= quality <= 100:
        raise ValueError(f"JPEG quality must be in 1..100, got {quality}")
    scale = 5000 // quality if quality < 50 else 200 - 2 * quality
    q = lambda t: np.clip(np.floor((t * scale + 50) / 100), 1, 255)
    return q(_LUMA), q(_CHROMA)


def _dct_matrix() -> np.ndarray:
    k, n = np.arange(8)[:, None], np.arange(8)[None, :]
    c = np.sqrt(2 / 8) * np.cos((2 * n + 1) * k * np.pi / 16)
    c[0] /= np.sqrt(2)
    return c


def _blocks_roundtrip(plane, table, dct):
    """Quantise the 8 x 8 DCT of a plane (multiple of 8 in size) and transform back.

    The blocks are laid out as 64 planes (row, column, block row, block column), so each
    1-D DCT is one product of the 8 x 8 DCT matrix with a long, contiguous operand."""
    h, w = plane.shape
    x = (plane - 128.0).reshape(h // 8, 8, w // 8, 8).transpose(1, 3, 0, 2)
    hi = lax.Precision.HIGHEST
    coef = jnp.einsum("ln,knab->klab", dct, jnp.einsum("km,mnab->knab", dct, x, precision=hi), precision=hi)
    t = table[:, :, None, None]
    coef = jnp.round(coef / t) * t
    back = jnp.einsum("ln,klab->knab", dct, jnp.einsum("km,klab->mlab", dct, coef, precision=hi), precision=hi) + 128.0
    return jnp.clip(jnp.round(back.transpose(2, 0, 3, 1).reshape(h, w)), 0.0, 255.0)


def jpeg(image: UInt8[Array, "H W 3"], quality: int) -> UInt8[Array, "H W 3"]:
    """``image`` after a baseline JPEG encode/decode at ``quality`` (1..100), 4:2:0 chroma."""
    luma_t, chroma_t = (jnp.asarray(t, jnp.float32) for t in quant_tables(quality))
    dct = jnp.asarray(_dct_matrix(), jnp.float32)
    h, w, _ = image.shape
    H, W = -(-h // 16) * 16, -(-w // 16) * 16
    x = jnp.pad(image.astype(jnp.float32), ((0, H - h), (0, W - w), (0, 0)), mode="edge")
    r, g, b = x[..., 0], x[..., 1], x[..., 2]
    y = jnp.round(0.299 * r + 0.587 * g + 0.114 * b)
    cb = jnp.round(-0.168736 * r - 0.331264 * g + 0.5 * b + 128.0)
    cr = jnp.round(0.5 * r - 0.418688 * g - 0.081312 * b + 128.0)
    half = lambda p: jnp.round(0.25 * (p[0::2, 0::2] + p[1::2, 0::2] + p[0::2, 1::2] + p[1::2, 1::2]))
    y = _blocks_roundtrip(y, luma_t, dct)
    cb = upsample(_blocks_roundtrip(half(cb), chroma_t, dct), 2) - 128.0
    cr = upsample(_blocks_roundtrip(half(cr), chroma_t, dct), 2) - 128.0
    rgb = jnp.stack([y + 1.402 * cr, y - 0.344136 * cb - 0.714136 * cr, y + 1.772 * cb], axis=-1)
    return jnp.clip(jnp.round(rgb), 0, 255).astype(jnp.uint8)[:h, :w]
