"""Derivatives three ways: forward mode, reverse mode and central differences (as `brentyi/jaxlie`
`tests/test_autodiff.py` does). Directional checks use `jax.test_util.check_grads` directly."""

from __future__ import annotations

import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from tests.tolerances import EXACT, FINITE_DIFF


@functools.cache
def cached_jit(f: Callable, transform: Callable | None = None):
    """One compilation per function (and per input shape) however many examples a test draws."""
    return jax.jit(f if transform is None else transform(f))


def numerical_jacobian(f: Callable, x, step, args=()) -> np.ndarray:
    """Central differences of ``f(x, *args)`` in ``x`` (a vector), one column per coordinate; ``step``
    is a scalar or one step per coordinate."""
    x = np.asarray(x, float)
    steps = np.broadcast_to(np.asarray(step, float), x.shape)
    f = cached_jit(f, None)
    cols = []
    for i, h in enumerate(steps):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((np.asarray(f(jnp.asarray(x + e), *args)) - np.asarray(f(jnp.asarray(x - e), *args))) / (2 * h))
    return np.stack(cols, axis=-1)


def assert_jacobians_close(f: Callable, x, *, step, args=(), rtol: float = FINITE_DIFF, floor: float = 0.0,
                           atol=0.0, modes: tuple[str, ...] = ("fwd", "rev")) -> np.ndarray:
    """``jacfwd`` equals ``jacrev`` (to float64 rounding) and both match central differences:
    ``|J - J_num| <= rtol max(|J_num|, floor max|J_num|) + atol``: entries below ``floor`` times the
    largest are compared on its scale, and ``atol`` broadcasts against the Jacobian (e.g. one value
    per output row). Derivatives are in ``x``; ``args`` are further inputs, traced, so that one
    compilation serves every case of a parametrised test. ``modes`` may leave out "rev". Returns
    the Jacobian of the first mode."""
    xj = jnp.asarray(x, float)
    jacs = {m: np.asarray(cached_jit(f, {"fwd": jax.jacfwd, "rev": jax.jacrev}[m])(xj, *args)) for m in modes}
    first = jacs[modes[0]]
    for m in modes[1:]:
        np.testing.assert_allclose(jacs[m], first, rtol=EXACT[np.float64], atol=1e-15 * np.abs(first).max(),
                                   err_msg=f"jac{m} vs jac{modes[0]}")
    num = numerical_jacobian(f, x, step, args)
    bound = rtol * np.maximum(np.abs(num), floor * np.abs(num).max()) + atol
    assert np.all(np.abs(first - num) <= bound), (
        f"autodiff vs central differences: worst excess {np.max(np.abs(first - num) - bound):.3g}\n"
        f"autodiff:\n{first}\nnumerical:\n{num}")
    return first
