"""The synthetic world's records on disk: one truth line per frame, and the world's summary.

``truth.jsonl`` keeps docs/design.md section 7.3's contract: ``frame`` and ``persons`` [{``id``,
``foot_m`` [x, y], ``head_m`` [x, y, z], ``r_f``, ``theta_f``}], with more keys per person
and per frame; ``world.json`` holds what does not change from frame to frame (the true rig,
the people's sizes and colours, the sensor, the lamps, the furniture that moves and when).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from omnijax import Pointing, pointing
from omnijax.world import World, effective_sigma


def truth_line(truth) -> dict:
    """The ``truth.jsonl`` object of one frame's :class:`omnijax.Truth` (numpy or jax arrays).

    Per person: ``id``, ``foot_m``, ``head_m`` (the head's centre, H_p - R_h high),
    ``r_f`` (px) and ``theta_f`` (rad) of the true foot in the true omni camera,
    ``pixel`` (x, y) of the foot, ``r_inner`` (px, the silhouette's foot end),
    ``r_head`` (px, top of the head), ``H_p_m``, ``R_h_m``, ``in_image``,
    ``foot_visible``, ``area_px``, ``moving``. Per frame: ``time_s``, ``lamps_on``,
    ``illumination``.
    """
    t = {k: np.asarray(v) for k, v in vars(truth).items()}
    persons = []
    for i in range(t["foot"].shape[0]):
        persons.append({
            "id": i,
            "foot_m": [float(v) for v in t["foot"][i]],
            "head_m": [float(v) for v in t["head"][i]],
            "r_f": float(t["r_f"][i]),
            "theta_f": float(t["theta_f"][i]),
            "pixel": [float(v) for v in t["pixel"][i]],
            "r_inner": float(t["r_inner"][i]),
            "r_head": float(t["r_head"][i]),
            "H_p_m": float(t["H_p"][i]),
            "R_h_m": float(t["R_h"][i]),
            "in_image": bool(t["in_image"][i]),
            "foot_visible": bool(t["foot_visible"][i]),
            "area_px": int(t["area"][i]),
            "moving": bool(t["moving"][i]),
        })
    return {"frame": int(t["frame"]), "time_s": float(t["time"]), "persons": persons,
            "lamps_on": [bool(v) for v in t["lamps_on"]], "illumination": float(t["illumination"])}


def _rig_values(rig) -> dict:
    fo, om = rig.foveal, rig.omni
    return {"H_o_m": float(om.H_o), "r_m_px": float(om.r_m), "rim_px": float(om.rim),
            "center_px": [float(v) for v in om.center], "H_f_m": float(fo.H_f), "D_c_m": float(fo.D_c),
            "theta_c_rad": float(fo.theta_c), "theta_c_deg": math.degrees(float(fo.theta_c))}


def world_summary(world: World) -> dict:
    """The ``world.json`` object: scenario, seed, sensor, the true and the configured rig, the people,
    the lamps (position, intensity, spectrum) and the moved furniture (``index`` in the scenario's
    furniture, footprint centres ``from_m`` and ``to_m``, ``size_m``, ``at_s``)."""
    sc, pe = world.scenario, world.people
    contrast = np.asarray(world.clothing_contrast())
    sigma = float(sc.sensor.noise_sigma)
    people = []
    for i in range(pe.count):
        people.append({
            "id": i, "H_p_m": float(pe.H_p[i]), "R_h_m": float(pe.R_h[i]),
            "shoulder_width_m": 2 * float(pe.radius),
            "top": [float(v) for v in pe.top[i]], "bottom": [float(v) for v in pe.bottom[i]],
            "skin": [float(v) for v in pe.skin[i]], "hair": [float(v) for v in pe.hair[i]],
            "floor_like": bool(pe.floor_like[i]), "speed_m_s": float(pe.speed[i]),
            "contrast_top": float(contrast[i, 0]), "contrast_bottom": float(contrast[i, 1]),
        })
    width, height = world.true_rig.omni.image_size
    return {
        "scenario": sc.name, "seed": int(world.seed), "fps": sc.fps, "frames": world.n_frames,
        "image_size": [width, height], "camera_model": world.true_rig.omni.model,
        "sensor": {"noise_sigma": sigma, "effective_sigma": effective_sigma(sigma),
                   "jpeg_quality": sc.sensor.jpeg_quality or None, "vignetting": float(sc.sensor.vignetting),
                   "antialias": sc.sensor.antialias, "shadow_downsample": sc.sensor.shadow_downsample},
        "true_rig": _rig_values(world.true_rig), "configured_rig": _rig_values(world.rig),
        "people": people,
        "lamps": [{"position_m": [float(v) for v in p], "intensity": float(i), "spectrum": [float(v) for v in s]}
                  for p, i, s in zip(np.asarray(sc.lighting.position), np.asarray(sc.lighting.intensity),
                                     np.asarray(sc.lighting.lamp_spectrum))],
        "ambient_spectrum": [float(v) for v in np.asarray(sc.lighting.spectrum)],
        "moved_furniture": _moved_furniture(world),
        "window_px": list(world.background.window),
    }


def _moved_furniture(world: World) -> list[dict]:
    fu = world.scenario.furniture
    centres = world.moved_furniture.reshape(-1, 2, 2)
    return [{"index": i, "from_m": [float(v) for v in c[0]], "to_m": [float(v) for v in c[1]],
             "size_m": [float(v) for v in np.asarray(fu.hi[i] - fu.lo[i])], "height_m": float(fu.height[i]),
             "at_s": float(fu.move_at[i])} for i, c in zip(fu.moving, centres)]


def true_aim(world: World, person: dict) -> Pointing:
    """eq 1-4 with the world's true rig and the true person of a ``truth.jsonl`` entry: the PTZ
    pan/tilt that put this person's true head centre at the foveal image's centre."""
    rig = world.true_rig
    x = jnp.array([person["r_f"], person["theta_f"], rig.omni.H_o, rig.foveal.H_f, rig.foveal.D_c,
                   rig.foveal.theta_c, rig.omni.r_m, person["H_p_m"], person["R_h_m"]])
    return pointing(x, rig.omni.profile)
