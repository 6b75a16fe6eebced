"""Angle wrapping: both ranges, on Python floats (the loop's path) and on arrays (jitted, differentiated)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

from omnijax.geometry import wrap_2pi, wrap_pi

TAU = 2 * math.pi
angles = st.floats(-1e4, 1e4, allow_nan=False, allow_subnormal=False)  # XLA flushes subnormals to 0


@given(angles)
def test_wrap_pi_is_the_same_angle_in_range(a):
    for w in (wrap_pi(a), float(wrap_pi(jnp.asarray(a)))):
        assert -math.pi <= w < math.pi
        assert math.remainder(w - a, TAU) == pytest.approx(0.0, abs=1e-9)


@given(angles)
def test_wrap_2pi_is_the_same_angle_in_range(a):
    for w in (wrap_2pi(a), float(wrap_2pi(jnp.asarray(a)))):
        assert 0.0 <= w < TAU
        assert math.remainder(w - a, TAU) == pytest.approx(0.0, abs=1e-9)


def test_edges_and_exactness():
    assert wrap_pi(math.pi) == -math.pi and wrap_pi(-math.pi) == -math.pi
    assert float(wrap_pi(jnp.asarray(math.pi))) == -math.pi
    assert wrap_2pi(TAU) == 0.0 and wrap_2pi(-1e-300) == 0.0 and float(wrap_2pi(jnp.asarray(-1e-300))) == 0.0
    inside = np.array([-3.0, -1e-12, 0.0, 1e-12, 0.1, 3.14])
    assert np.array_equal(np.asarray(wrap_pi(inside)), inside)  # bit for bit
    assert wrap_pi(0.1) == 0.1 and wrap_2pi(1.5) == 1.5


def test_floats_stay_floats_and_arrays_jit_and_differentiate():
    assert type(wrap_pi(4.0)) is float and type(wrap_2pi(-1)) is float
    x = jnp.linspace(-20.0, 20.0, 101)
    assert np.allclose(jax.jit(wrap_pi)(x), np.asarray(wrap_pi(x)))
    for f in (wrap_pi, wrap_2pi):
        g = jax.vmap(jax.grad(f))(x)
        assert np.all(np.asarray(g) == 1.0)
