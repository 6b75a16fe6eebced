"""Characterisation runs behind ``omnijax validate``: each returns a JSON-able summary and maps.

- :func:`chroma_check`: eq 5 against Monte Carlo on the paper's B = 50 grid (figure 9).
- :func:`ptz_check`: pan/tilt variances over the floor by the four methods, in
  omni-image coordinates (figure 10), with their relative differences.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from omnijax import (
    Rig,
    chromaticity,
    chromaticity_covariance,
    image_to_floor,
    pointing,
    pointing_covariance,
    pointing_covariance_mc,
)
from omnijax.uncertainty import PROPAGATION_METHODS

Progress = Callable[[str, float], None]


def _frobenius_rel(a, b):
    return np.linalg.norm(a - b, axis=(-2, -1)) / np.linalg.norm(b, axis=(-2, -1))


@functools.partial(jax.jit, static_argnames=("n_chunks", "chunk"))
def _chroma_moments(key, rgb, sigma, n_chunks: int, chunk: int):
    """Sample mean and covariance of (r, g) under N(rgb, sigma^2 I) noise, chunked."""

    def step(carry, k):
        noisy = rgb[None] + sigma * jax.random.normal(k, (chunk, *rgb.shape), rgb.dtype)
        c = chromaticity(noisy) - chromaticity(rgb)[None]
        return (carry[0] + c.sum(0), carry[1] + jnp.einsum("n...a,n...b->...ab", c, c)), None

    init = (jnp.zeros(rgb.shape[:-1] + (2,)), jnp.zeros(rgb.shape[:-1] + (2, 2)))
    (s1, s2), _ = jax.lax.scan(step, init, jax.random.split(key, n_chunks))
    n = n_chunks * chunk
    m = s1 / n
    return (s2 - n * m[..., :, None] * m[..., None, :]) / (n - 1)


def chroma_check(sensor_sigma: float, *, blue: float = 50.0, step: int = 8, samples: int = 100_000,
                 seed: int = 0) -> tuple[dict, dict]:
    """Eq 5 against ``J sigma^2 I J^T`` (jax.jacfwd) and against Monte Carlo, R and G over 0..255.

    Relative differences are Frobenius norms of the 2 x 2 covariance difference over
    the norm of eq 5's. The Monte Carlo one carries sampling error of about
    ``sqrt(2 / samples)`` per cell (reported as ``expected_sampling_rel``).
    """
    levels = np.arange(0, 256, step, dtype=float)
    R, G = np.meshgrid(levels, levels, indexing="xy")
    rgb = jnp.asarray(np.stack([R, G, np.full_like(R, blue)], -1))
    eq5 = np.asarray(chromaticity_covariance(rgb, sensor_sigma))
    J = jax.vmap(jax.jacfwd(chromaticity))(rgb.reshape(-1, 3))
    jac = np.asarray(sensor_sigma**2 * J @ jnp.swapaxes(J, -1, -2)).reshape(eq5.shape)
    chunk = 1000
    mc = np.asarray(_chroma_moments(jax.random.key(seed), rgb, sensor_sigma, max(1, samples // chunk), chunk))
    rel_mc = _frobenius_rel(mc, eq5)
    summary = {
        "max_rel_diff": float(rel_mc.max()),
        "mean_rel_diff": float(rel_mc.mean()),
        "eq5_vs_jacobian_max_rel": float(_frobenius_rel(jac, eq5).max()),
        "samples": int(max(1, samples // chunk) * chunk),
        "expected_sampling_rel": math.sqrt(2.0 / samples),
        "blue": blue,
        "grid": {"levels": len(levels), "step": step},
        "sensor_sigma": sensor_sigma,
    }
    fig9 = lambda c: c[..., 0, 0] + c[..., 1, 1] + c[..., 0, 1]
    maps = {"levels": levels, "eq5": fig9(eq5), "mc_minus_eq5": fig9(mc) - fig9(eq5), "rel": rel_mc}
    return summary, maps


QUANTITIES = ("sin_pan", "tan_tilt", "pan", "tilt")
PAPER_QUANTITIES = ("sin_pan", "tan_tilt")  # what eq 13 and 14 give
ANGLE_QUANTITIES = ("pan", "tilt")  # what the PTZ is driven with


@dataclass
class PtzMaps:
    """Per-pixel results on the omni-image grid: variances by method, masks, positions."""

    x: np.ndarray
    y: np.ndarray
    region: np.ndarray  # valid floor point inside the room
    compared: np.ndarray  # region and at least min_distance from the PTZ
    distance: np.ndarray
    var: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)


def _variances(cov) -> dict[str, np.ndarray]:
    return {
        "sin_pan": np.asarray(cov.var_sin_pan), "tan_tilt": np.asarray(cov.var_tan_tilt),
        "pan": np.asarray(cov.var_pan), "tilt": np.asarray(cov.var_tilt),
    }


def _rel(a, ref):
    return np.abs(a - ref) / np.abs(ref)


def _worst(rel: np.ndarray, mask: np.ndarray, maps: PtzMaps) -> dict:
    """Largest relative difference inside ``mask``, and where it is (pixel and floor metres)."""
    if not mask.any():
        return {"max_rel": None, "at_px": None}
    r = np.where(mask, rel, -np.inf)
    i = np.unravel_index(np.argmax(r), r.shape)
    return {"max_rel": float(r[i]), "at_px": [float(maps.x[i]), float(maps.y[i])],
            "distance_m": float(maps.distance[i])}


def ptz_check(rig: Rig, *, step_px: float = 8.0, min_distance: float = 1.0, rel_tol: float = 0.01,
              max_trials: int = 400_000, seed: int = 0, progress: Progress | None = None) -> tuple[dict, PtzMaps]:
    """Variances of (sin pan, tan tilt, pan, tilt) over the floor by all four methods.

    The grid samples the omni image every ``step_px`` pixels (the paper's figure
    10 is drawn in omni-image coordinates); ``region`` keeps valid floor points
    inside the room, ``compared`` those at least ``min_distance`` (m) from the PTZ's
    foot, where the Monte Carlo comparisons are summarised. ``*_max_rel`` keys take
    the largest relative difference over sin pan and tan tilt (eq 13/14's
    quantities) for the analytic comparisons and over pan and tilt for the others
    (``headline_quantities`` says why); ``per_quantity`` has all four.
    """
    omni = rig.omni
    W, H = omni.image_size
    ys, xs = np.mgrid[step_px / 2:H:step_px, step_px / 2:W:step_px]
    r, theta = (np.asarray(v) for v in omni.to_polar(xs, ys))
    X, Y, on_floor = image_to_floor(omni, xs, ys)
    x = rig.input_mean(r, theta)
    sigma = rig.input_sigma()
    p = pointing(x, omni.profile)
    region = np.asarray(on_floor & p.valid & rig.room.contains(X, Y))
    distance = np.asarray(p.distance)
    maps = PtzMaps(x=xs, y=ys, region=region, compared=region & (distance >= min_distance), distance=distance)

    for method in PROPAGATION_METHODS:
        if progress:
            progress(method, 0.0)
        maps.var[method] = _variances(pointing_covariance(x, sigma, omni.profile, method))

    def mc_progress(trials, tol):
        if progress:
            progress("montecarlo", min(1.0, trials / max_trials))

    mc = pointing_covariance_mc(x[region], sigma, omni.profile, jax.random.key(seed), rel_tol=rel_tol,
                                max_trials=max_trials, where=maps.compared[region], callback=mc_progress)
    maps.var["montecarlo"] = {}
    for q, v in _variances(mc.covariance).items():
        full = np.full(region.shape, np.nan)
        full[region] = v
        maps.var["montecarlo"][q] = full

    ref_ad, ref_mc = maps.var["autodiff"], maps.var["montecarlo"]
    per_q = {}
    for q in QUANTITIES:
        first_rel = _rel(ref_ad[q], ref_mc[q])
        first_off = first_rel > 0.03
        bad = region & ~(first_rel <= 0.03)
        per_q[q] = {
            "autodiff_within_3pct_of_mc_beyond_m": float(distance[bad].max()) if bad.any() else 0.0,
            "second_order_vs_mc_where_first_order_off_3pct_beyond_min_distance": _worst(
                _rel(maps.var["second_order"][q], ref_mc[q]), maps.compared & first_off, maps),
            "second_order_negative_points": int((region & (maps.var["second_order"][q] <= 0)).sum()),
            "autodiff_vs_analytic": _worst(_rel(maps.var["analytic"][q], ref_ad[q]), region, maps),
            "autodiff_vs_mc": _worst(_rel(ref_ad[q], ref_mc[q]), maps.compared, maps),
            "analytic_vs_mc": _worst(_rel(maps.var["analytic"][q], ref_mc[q]), maps.compared, maps),
            "second_order_vs_mc": _worst(_rel(maps.var["second_order"][q], ref_mc[q]), maps.compared, maps),
            "second_order_vs_mc_where_first_order_off_3pct": _worst(
                _rel(maps.var["second_order"][q], ref_mc[q]), region & first_off, maps),
            "first_order_off_3pct_points": int((region & first_off).sum()),
        }

    def headline(key, quantities):
        vals = [per_q[q][key]["max_rel"] for q in quantities if per_q[q][key]["max_rel"] is not None]
        return max(vals) if vals else None

    summary = {
        "autodiff_vs_analytic_max_rel": headline("autodiff_vs_analytic", PAPER_QUANTITIES),
        "autodiff_vs_mc_max_rel": headline("autodiff_vs_mc", ANGLE_QUANTITIES),
        "analytic_vs_mc_max_rel": headline("analytic_vs_mc", PAPER_QUANTITIES),
        "second_order_vs_mc_max_rel": headline("second_order_vs_mc", ANGLE_QUANTITIES),
        "second_order_vs_mc_where_first_order_off_3pct_max_rel": headline(
            "second_order_vs_mc_where_first_order_off_3pct", ANGLE_QUANTITIES),
        "second_order_vs_mc_where_first_order_off_3pct_beyond_min_distance_max_rel": headline(
            "second_order_vs_mc_where_first_order_off_3pct_beyond_min_distance", ANGLE_QUANTITIES),
        "autodiff_within_3pct_of_mc_beyond_m": max(
            per_q[q]["autodiff_within_3pct_of_mc_beyond_m"] for q in ANGLE_QUANTITIES),
        "headline_quantities": {
            "analytic comparisons": list(PAPER_QUANTITIES),
            "autodiff and second order vs montecarlo": list(ANGLE_QUANTITIES),
            "why": "eq 13/14 give var(sin pan) and var(tan tilt) only; the PTZ is driven by pan and "
                   "tilt, and var(sin pan) vanishes to first order at pan = +-90 deg (d sin pan = "
                   "cos pan d pan), where any first-order method's relative error is unbounded",
        },
        "min_distance_m": min_distance,
        "grid_step_px": step_px,
        "points": int(region.sum()),
        "points_compared": int(maps.compared.sum()),
        "montecarlo": {"trials": mc.trials, "batches": mc.batches, "tolerance": mc.tolerance,
                       "rel_tol": rel_tol, "seed": seed},
        "per_quantity": per_q,
    }
    return summary, maps
