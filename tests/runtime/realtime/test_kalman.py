"""The tracker's jitted arithmetic: the optimal assignment against SciPy's on random gated cost
matrices, and the greedy nearest neighbour on a hand-made case."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from runtime.realtime.kalman import FORBIDDEN, greedy_assignment, optimal_assignment

_optimal = jax.jit(optimal_assignment)


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (6, 2), (8, 8), (16, 8)])
def test_optimal_assignment_matches_scipy(shape):
    """200 random matrices per shape (seed 5), about a third of the pairs forbidden: the same total
    cost over the allowed pairs as SciPy's linear_sum_assignment, and the same pairs where the
    optimum is unique (continuous random costs: always, up to the forbidden pairs)."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        cost = rng.uniform(-3.0, 14.0, shape)
        cost[rng.uniform(size=shape) < 0.35] = FORBIDDEN
        rows, cols = linear_sum_assignment(cost)
        keep = cost[rows, cols] < FORBIDDEN
        expect = dict(zip(rows[keep].tolist(), cols[keep].tolist()))
        got = np.asarray(_optimal(cost))
        pairs = {i: int(k) for i, k in enumerate(got) if k >= 0}
        assert len(set(pairs.values())) == len(pairs)
        assert all(cost[i, k] < FORBIDDEN for i, k in pairs.items())
        assert sum(cost[i, k] for i, k in pairs.items()) == pytest.approx(sum(cost[i, k] for i, k in expect.items()),
                                                                          rel=1e-12, abs=1e-9)
        assert pairs == expect


def test_greedy_takes_the_closest_pair_first():
    d = np.array([[0.55, 1.6], [0.45, 0.6], [5.0, 5.0]])
    np.testing.assert_array_equal(np.asarray(greedy_assignment(d, 0.8)), [-1, 0, -1])
    np.testing.assert_array_equal(np.asarray(greedy_assignment(d, 2.0)), [1, 0, -1])
