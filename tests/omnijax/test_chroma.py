"""Eq 5: the closed form against J sigma^2 I J^T, and against Monte Carlo; dark pixels stay finite."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

from omnijax import chromaticity, chromaticity_covariance

level = st.floats(0.0, 255.0)


@given(R=level, G=level, B=level, sigma=st.floats(0.1, 5.0))
def test_eq5_is_J_sigma2_JT(R, G, B, sigma):
    rgb = jnp.array([R, G, B])
    if float(rgb.sum()) < 1.0:  # below S_MIN the sum is floored: eq 5 and the Jacobian differ there
        return
    J = jax.jacfwd(chromaticity)(rgb)
    ref = np.asarray(sigma**2 * J @ J.T)
    ours = np.asarray(chromaticity_covariance(rgb, sigma))
    np.testing.assert_allclose(ours, ref, rtol=1e-13, atol=1e-15 * np.abs(ref).max())


def test_eq5_against_monte_carlo():
    """n = 400000 noisy samples per colour, fixed seed; sampling error of a variance ~ 0.22 %."""
    rng = np.random.default_rng(0)
    for rgb in ([200.0, 30.0, 50.0], [10.0, 10.0, 50.0], [120.0, 240.0, 50.0]):
        rgb = np.asarray(rgb)
        noisy = rgb + rng.normal(0, 1.0, (400_000, 3))
        c = np.cov(np.asarray(chromaticity(noisy)).T)
        ref = np.asarray(chromaticity_covariance(rgb, 1.0))
        assert np.linalg.norm(c - ref) / np.linalg.norm(ref) < 0.02


def test_dark_pixels_are_finite():
    rgb = jnp.zeros((4, 3)).at[1].set(jnp.array([0.2, 0.1, 0.0]))
    c = chromaticity_covariance(rgb, 1.0)
    assert bool(jnp.all(jnp.isfinite(c)))
    g = jax.grad(lambda x: chromaticity(x).sum())(jnp.zeros(3))
    assert bool(jnp.all(jnp.isfinite(g)))
    assert float(c[0, 0, 0]) == pytest.approx(1.0)  # sigma^2 / S_MIN^2: huge next to a lit pixel's 1e-5
