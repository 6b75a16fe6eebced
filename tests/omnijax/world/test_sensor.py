"""The sensor model: counter-based Gaussian noise, quantisation, the JPEG model, image helpers."""

from __future__ import annotations

import math

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from omnijax.world import (
    derive_key,
    effective_sigma,
    gaussian,
    jpeg,
    key_from_seed,
    own_buffer,
    quantise,
    uniform,
    upsample,
    value_noise,
)


def test_uniform_never_reaches_0_or_1():
    u = np.asarray(uniform(jnp.array([0, 1, 2**31, 2**32 - 1], jnp.uint32)))
    assert np.all((u > 0) & (u < 1))
    assert np.all(np.isfinite(np.asarray(gaussian(key_from_seed(0), (4,)))))


def test_gaussian_moments_and_shape():
    """n = 2e6 samples: mean within 4 / sqrt(n), variance within 4 sqrt(2 / n), skewness and
    kurtosis within 4 standard errors, Kolmogorov-Smirnov p > 1e-4 (false failure ~1e-4)."""
    n = 2_000_000
    g = np.asarray(gaussian(key_from_seed(3), (n,)), float)
    assert abs(g.mean()) < 4 / math.sqrt(n)
    assert abs(g.var() - 1) < 4 * math.sqrt(2 / n)
    assert abs(stats.skew(g)) < 4 * math.sqrt(6 / n)
    assert abs(stats.kurtosis(g)) < 4 * math.sqrt(24 / n)
    assert stats.kstest(g, "norm").pvalue > 1e-4
    assert np.abs(g).max() < 5.5


def test_gaussian_streams_are_independent():
    """Different frame keys: the same counters give uncorrelated samples (|r| < 4 / sqrt(n));
    every key's samples are finite (200 keys x 3e5 samples)."""
    base = key_from_seed(11)
    draw = jax.jit(lambda t: gaussian(derive_key(base, t), (480, 640)))
    samples = [np.asarray(draw(t)).ravel() for t in range(200)]
    assert all(np.isfinite(s).all() for s in samples)
    n = samples[0].size
    r = [np.corrcoef(samples[t], samples[t + 1])[0, 1] for t in range(0, 199, 20)]
    assert max(abs(v) for v in r) < 4 / math.sqrt(n)
    neighbour = np.corrcoef(samples[0][:-1], samples[0][1:])[0, 1]
    assert abs(neighbour) < 4 / math.sqrt(n)


def test_value_noise_is_smooth_and_bounded():
    u = jnp.linspace(0.0, 10.0, 2001)
    v = np.asarray(value_noise(key_from_seed(2), u, 0.3 * u))
    assert np.all(np.abs(v) < 0.5) and v.std() > 0.05
    assert np.abs(np.diff(v)).max() < 0.02  # step 0.005 in u


def test_quantise_rounds_and_clips():
    x = jnp.array([-3.0, 0.49, 0.5, 127.4, 254.6, 300.0])
    assert np.asarray(quantise(x)).tolist() == [0, 0, 1, 127, 255, 255]
    assert effective_sigma(1.0) == pytest.approx(math.sqrt(1 + 1 / 12))


def test_upsample_matches_jax_image_resize():
    x = jax.random.uniform(jax.random.key(0), (2, 7, 9))
    for s in (2, 4):
        ref = jax.image.resize(x, (2, 7 * s, 9 * s), "linear")
        np.testing.assert_allclose(np.asarray(upsample(x, s)), np.asarray(ref), atol=1e-6)


def test_own_buffer_is_the_identity():
    x = (jnp.arange(6.0), jnp.ones((2, 2), jnp.uint8))
    y = jax.jit(lambda v, k: own_buffer(v, k >= 0))(x, jnp.int32(3))
    assert all(np.array_equal(np.asarray(a), np.asarray(b)) for a, b in zip(x, y))


@pytest.mark.parametrize("quality", [90, 50])
def test_jpeg_model_matches_opencv(quality):
    """A textured, noisy image through our JPEG model and through OpenCV's libjpeg (imencode /
    imdecode, same quality, 4:2:0): both lose the same (mean error against the original within
    5 % of each other), and they differ by under one grey level on average, 99 % within 5 (libjpeg
    rounds its integer DCT and its chroma resampling differently)."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:240, 0:320]
    img = np.stack([120 + 80 * np.sin(xx / 9.0), 100 + 60 * np.cos(yy / 7.0), 90 + 40 * np.sin((xx + yy) / 13.0)], -1)
    img = np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8)
    ours = np.asarray(jax.jit(lambda v: jpeg(v, quality))(jnp.asarray(img))).astype(int)
    ok, buf = cv2.imencode(".jpg", img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
    ref = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].astype(int)
    diff = np.abs(ours - ref)
    assert diff.mean() < 1.0 and np.percentile(diff, 99) <= 5
    assert np.abs(ours - img).mean() == pytest.approx(np.abs(ref - img).mean(), rel=0.05)
