"""The synthetic world's accuracy figures (issue 3): truth against the camera model, and the sensor noise.

- Truth foot vs the camera model: for every person of sampled frames of several seeds, the
  ``pixel`` / ``r_f`` written to ``truth.jsonl`` against the foundation's ``world_to_image``
  of the true world foot (max error, px); the renderer's own ray through that pixel
  (``omni_rays``, the inverse mapping) against the foot (miss on the floor in px, at the
  local scale); and the drawn silhouette's foot end (first
  labelled pixel walking out along the radial line through the foot, 0.05 px steps) against
  ``r_inner`` (the body's nearest floor point) and against ``r_f``.
- Noise: the empty room's per-pixel standard deviation over 200 frames (200 x 200 pixels
  inside the image circle, 3 channels) against the configured sigma and against
  ``sqrt(sigma^2 + 1/12)`` (the configured sigma after 8-bit rounding).

Run: `.venv/bin/python benchmarks/measure_world.py` (prints JSON; a few minutes).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import jax

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
import numpy as np

from omnijax import world_to_image
from omnijax.world import build_world, effective_sigma, omni_rays
from runtime.files import load_scenario

SCENARIOS = ROOT / "configs" / "scenarios"


def silhouette_start(world, labels, truth, i) -> float | None:
    """Image radius (px) of the first pixel labelled ``i`` along the radial line through the foot."""
    om = world.true_rig.omni
    rs = np.arange(0.0, truth.r_f[i] + 20.0, 0.05)
    px, py = (np.rint(np.asarray(v)).astype(int) for v in om.to_pixel(rs, truth.theta_f[i]))
    ok = (px >= 0) & (px < labels.shape[1]) & (py >= 0) & (py < labels.shape[0])
    hit = np.zeros(rs.shape, bool)
    hit[ok] = labels[py[ok], px[ok]] == i
    return float(rs[np.argmax(hit)]) if hit.any() else None


def foot_figures(name: str, seeds, frames) -> dict:
    rig, sc = load_scenario(SCENARIOS / f"{name}.toml")
    pixel_err, r_err, ray_err, start_vs_inner, start_vs_rf, people = [], [], [], [], [], 0
    for seed in seeds:
        world = build_world(rig, sc, seed=seed, n_frames=max(frames) + 1)
        om = world.true_rig.omni
        for t in frames:
            f = world.frame(t)
            tr, labels = jax.tree.map(np.asarray, f.truth), np.asarray(f.labels)
            x, y = (np.asarray(v) for v in world_to_image(om, tr.foot[:, 0], tr.foot[:, 1], 0.0))
            r, _ = om.to_polar(x, y)
            pixel_err.append(np.hypot(x - tr.pixel[:, 0], y - tr.pixel[:, 1]))
            r_err.append(np.abs(np.asarray(r) - tr.r_f))
            d = np.asarray(omni_rays(om, tr.pixel[:, 0], tr.pixel[:, 1])[0])
            reach = float(om.H_o) / -d[:, 2]
            miss_m = np.hypot(reach * d[:, 0] - tr.foot[:, 0], reach * d[:, 1] - tr.foot[:, 1])
            px_per_m = np.abs(np.asarray(world_to_image(om, tr.foot[:, 0] + 1e-3, tr.foot[:, 1], 0.0)[0]) - x) / 1e-3
            ray_err.append(miss_m * px_per_m)
            people += len(x)
            for i in np.flatnonzero(tr.in_image & tr.foot_visible):
                start = silhouette_start(world, labels, tr, i)
                if start is not None:
                    start_vs_inner.append(start - tr.r_inner[i])
                    start_vs_rf.append(tr.r_f[i] - start)
    pixel_err, r_err, ray_err = np.concatenate(pixel_err), np.concatenate(r_err), np.concatenate(ray_err)
    s_in, s_rf = np.asarray(start_vs_inner), np.asarray(start_vs_rf)
    return {
        "camera_model": str(world.true_rig.omni.model), "seeds": list(seeds), "person_frames": people,
        "truth_pixel_vs_projection_max_px": float(pixel_err.max()),
        "truth_r_f_vs_projection_max_px": float(r_err.max()),
        "renderer_ray_through_truth_pixel_misses_foot_max_px": float(ray_err.max()),
        "silhouettes": len(s_in),
        "silhouette_start_minus_r_inner_px": {"max_abs": float(np.abs(s_in).max()), "mean": float(s_in.mean())},
        "r_f_minus_silhouette_start_px": {"min": float(s_rf.min()), "median": float(np.median(s_rf)),
                                          "max": float(s_rf.max())},
    }


def noise_figures(n_frames: int = 200) -> dict:
    rig, sc = load_scenario(SCENARIOS / "empty_room.toml")
    world = build_world(rig, sc, n_frames=n_frames)
    crop = (slice(140, 340), slice(220, 420))
    frames = np.stack([np.asarray(world.frame(t).image[crop], float) for t in range(n_frames)])
    std = frames.std(axis=0, ddof=1)
    sigma = float(sc.sensor.noise_sigma)
    return {"frames": n_frames, "pixels": int(std[..., 0].size), "configured_sigma": sigma,
            "expected_after_rounding": effective_sigma(sigma), "measured_std_rms": float(np.sqrt((std**2).mean())),
            "measured_std_median": float(np.median(std)),
            "measured_std_per_channel": [float(np.sqrt((std[..., c] ** 2).mean())) for c in range(3)]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.parse_args()
    frames = list(range(0, 400, 20))
    result = {"six_people": foot_figures("six_people", (6, 7, 8), frames),
              "fisheye_office": foot_figures("fisheye_office", (0, 1), frames[:10]),
              "noise_empty_room": noise_figures()}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
