"""Builders for calibration tests: observation files from simulated problems, synthetic rim frames."""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erf


def observations_json(problem, decimals_px: int = 2, decimals_deg: int = 3, comment: str | None = None) -> dict:
    """The OBS.json mapping of a simulated :class:`CalibrationProblem` (readings rounded like a device's)."""
    o = problem.obs
    positions = []
    for k in range(o.r_f.shape[0]):
        aims = [{"height_m": float(o.height[a]), "pan_deg": round(math.degrees(float(o.pan[a])), decimals_deg),
                 "tilt_deg": round(math.degrees(float(o.tilt[a])), decimals_deg)}
                for a in np.flatnonzero(np.asarray(o.position) == k)]
        positions.append({"label": f"P{k + 1}", "r_f": round(float(o.r_f[k]), decimals_px),
                          "theta_f": round(float(o.theta_f[k]), 5), "aims": aims})
    data = {"sigma_pan_deg": math.degrees(float(o.sigma_pan[0])),
            "sigma_tilt_deg": math.degrees(float(o.sigma_tilt[0])),
            "sigma_height_m": float(o.sigma_height), "positions": positions}
    return {"comment": comment, **data} if comment else data


def disc_frame(size=(640, 480), center=(321.3, 238.7), radius=220.4, blur=1.0, noise=3.0, seed=0,
               occluder=True) -> np.ndarray:
    """A grey omni frame: a bright textured disc (the mirror) on a dark ground, blurred, noisy, 8-bit;
    with ``occluder`` a dark bar covers part of the rim."""
    rng = np.random.default_rng(seed)
    w, h = size
    yy, xx = np.mgrid[:h, :w].astype(float)
    d = np.hypot(xx - center[0], yy - center[1]) - radius
    inside = 0.5 * (1 - erf(d / (math.sqrt(2) * blur)))
    texture = 1 + 0.25 * np.sin(xx / 7.0) * np.cos(yy / 11.0)
    img = 25 + 150 * inside * texture
    if occluder:
        img[int(center[1]) + 40:, int(center[0]) + 40:int(center[0]) + 100] = 20.0
    return np.clip(np.round(img + rng.normal(0, noise, img.shape)), 0, 255).astype(np.uint8)
