"""The tracker's arithmetic, vectorised over tracks and detections and jittable: the constant-velocity
model, the gated assignment costs, the assignment itself (optimal for ``kalman``, the paper's greedy
nearest neighbour for ``nearest``) and the measurement update.

Written once here and used twice: by :meth:`runtime.realtime.tracker.Tracker.step` (one compiled
call per step) and inside the loop's fused per-frame kernel (:mod:`runtime.realtime.control`),
where detection, tracking and aiming are one compiled call. The bookkeeping (ids, hits, misses,
new tracks, dropping) stays in :class:`~runtime.realtime.tracker.Tracker`.

Tracks come as fixed-size slot arrays (``x`` (N, 4), ``P`` (N, 4, 4), ``t`` (N,), ``live`` (N,))
and detections as (K, 2), (K, 2, 2) with ``valid`` (K,), so that one compiled shape serves
every frame.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax import lax

#: Gate of the Kalman assignment: the chi-square(2) 99.9 % quantile of the Mahalanobis distance.
GATE = -2.0 * math.log(0.001)
#: Cost of a pair outside the gate (never assigned).
FORBIDDEN = 1e6


def constant_velocity(dt, accel_sd):
    """Transition F and process noise Q (..., 4, 4) of the constant-velocity model over ``dt`` s
    (white acceleration of sd ``accel_sd`` m/s^2), state (X, Y, vX, vY). Broadcasts over ``dt``."""
    dt = jnp.asarray(dt, float)
    o, z = jnp.ones_like(dt), jnp.zeros_like(dt)
    F = jnp.stack([jnp.stack([o, z, dt, z], -1), jnp.stack([z, o, z, dt], -1),
                   jnp.stack([z, z, o, z], -1), jnp.stack([z, z, z, o], -1)], -2)
    a2 = jnp.asarray(accel_sd, float) ** 2
    q11, q12, q22 = a2 * dt**4 / 4, a2 * dt**3 / 2, a2 * dt**2
    Q = jnp.stack([jnp.stack([q11, z, q12, z], -1), jnp.stack([z, q11, z, q12], -1),
                   jnp.stack([q12, z, q22, z], -1), jnp.stack([z, q12, z, q22], -1)], -2)
    return F, Q


def predict(x, P, dt, accel_sd):
    """States (..., 4) and covariances (..., 4, 4) predicted ``dt`` (...,) seconds ahead."""
    F, Q = constant_velocity(dt, accel_sd)
    return (F @ x[..., None])[..., 0], F @ P @ jnp.swapaxes(F, -1, -2) + Q


def kalman_costs(xp, Pp, live, z, R, valid):
    """Assignment costs (N, K) of predicted tracks against detections: the Mahalanobis distance of the
    innovation plus the log-determinant of its covariance, :data:`FORBIDDEN` beyond :data:`GATE`."""
    S = Pp[:, None, :2, :2] + R[None]  # (N, K, 2, 2)
    d = z[None] - xp[:, None, :2]
    m = jnp.einsum("nka,nkab,nkb->nk", d, jnp.linalg.inv(S), d)
    ok = (m <= GATE) & live[:, None] & valid[None]
    return jnp.where(ok, m + jnp.log(jnp.linalg.det(S)), FORBIDDEN)


def optimal_assignment(cost):
    """The assignment of rows to columns of least total cost (SciPy's ``linear_sum_assignment``
    semantics: min(N, K) pairs) by the Hungarian method with potentials and shortest augmenting
    paths, over the shorter side (O(min^2 max)). Returns each row's column (N,), -1 where it has
    none or only a :data:`FORBIDDEN` one. Jittable: fixed shapes, ``lax`` loops."""
    N, K = cost.shape
    if N <= K:
        col = _rows_to_columns(cost)
    else:
        col = jnp.full(N, -1, jnp.int32).at[_rows_to_columns(cost.T)].set(jnp.arange(K, dtype=jnp.int32))
    ok = (col >= 0) & (cost[jnp.arange(N), jnp.clip(col, 0, K - 1)] < FORBIDDEN)
    return jnp.where(ok, col, -1)


def _rows_to_columns(cost):
    """Each row's column (n,) in the least-cost assignment of all n rows to m >= n columns."""
    n, m = cost.shape
    a = jnp.zeros((n + 1, m + 1), cost.dtype).at[1:, 1:].set(cost)
    inf = jnp.asarray(jnp.inf, cost.dtype)

    def add_row(i, state):
        u, v, p, way = state
        p = p.at[0].set(i)

        def grow(c):  # one step of Dijkstra over the columns with reduced costs
            u, v, p, way, minv, used, j0 = c
            used = used.at[j0].set(True)
            i0 = p[j0]
            cur = a[i0] - u[i0] - v
            better = ~used & (cur < minv)
            minv = jnp.where(better, cur, minv)
            way = jnp.where(better, j0, way)
            free = jnp.where(used, inf, minv)
            j1 = jnp.argmin(free).astype(jnp.int32)
            delta = free[j1]
            u = u.at[p].add(jnp.where(used, delta, 0.0))
            v = jnp.where(used, v - delta, v)
            minv = jnp.where(used, minv, minv - delta)
            return u, v, p, way, minv, used, j1

        c = grow((u, v, p, way, jnp.full(m + 1, inf, cost.dtype), jnp.zeros(m + 1, bool), jnp.int32(0)))
        u, v, p, way, _, _, j0 = lax.while_loop(lambda c: c[2][c[6]] != 0, grow, c)

        def augment(c):
            p, j0 = c
            j1 = way[j0]
            return p.at[j0].set(p[j1]), j1

        p, _ = lax.while_loop(lambda c: c[1] != 0, augment, (p, j0))
        return u, v, p, way

    ints = jnp.zeros(m + 1, jnp.int32)
    state = (jnp.zeros(n + 1, cost.dtype), jnp.zeros(m + 1, cost.dtype), ints, ints)
    _, _, p, _ = lax.fori_loop(1, n + 1, add_row, state)
    # p[j]: the row (1-based) holding column j; columns nobody holds point at row 0 (dropped)
    return jnp.zeros(n + 1, jnp.int32).at[p].set(jnp.arange(m + 1, dtype=jnp.int32))[1:] - 1


def greedy_assignment(dist, gate):
    """The paper's nearest neighbour: the closest (track, detection) pair first, then the closest
    among the rest, until the closest is beyond ``gate``. Returns each row's column (N,) or -1."""
    N, K = dist.shape

    def pick(_, c):
        d, out = c
        flat = jnp.argmin(d).astype(jnp.int32)
        i, k = flat // K, flat % K
        take = d[i, k] <= gate
        out = jnp.where(take, out.at[i].set(k), out)
        d = jnp.where(take, d.at[i, :].set(jnp.inf).at[:, k].set(jnp.inf), d)
        return d, out

    _, out = lax.fori_loop(0, min(N, K), pick, (dist, jnp.full(N, -1, jnp.int32)))
    return out


def step(mode: str, accel_sd, nearest_gate_m, x, P, t_tracks, live, t, z, R, valid):
    """One tracker step's arithmetic (``mode`` static): each slot's detection (N,) (-1: none) and its
    state and covariance after the step (predicted and updated where it has a detection; as it was
    otherwise, its time unchanged)."""
    if mode == "nearest":
        dist = jnp.linalg.norm(x[:, None, :2] - z[None], axis=-1)
        dist = jnp.where(live[:, None] & valid[None], dist, jnp.inf)
        assign = greedy_assignment(dist, nearest_gate_m)
        k = jnp.clip(assign, 0, None)
        x_new = jnp.concatenate([z[k], jnp.zeros_like(z[k])], -1)
        P_new = jnp.zeros_like(P).at[:, :2, :2].set(R[k])
    else:
        xp, Pp = predict(x, P, t - t_tracks, accel_sd)
        assign = optimal_assignment(kalman_costs(xp, Pp, live, z, R, valid))
        k = jnp.clip(assign, 0, None)
        S = Pp[:, :2, :2] + R[k]
        gain = Pp[:, :, :2] @ jnp.linalg.inv(S)  # P H^T S^-1, (N, 4, 2)
        x_new = xp + (gain @ (z[k] - xp[:, :2])[..., None])[..., 0]
        P_new = Pp - gain @ Pp[:, :2, :]  # (I - K H) P
    has = assign >= 0
    return assign, jnp.where(has[:, None], x_new, x), jnp.where(has[:, None, None], P_new, P)


step_jit = jax.jit(step, static_argnums=0)
