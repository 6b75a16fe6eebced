"""The pictures of the synthetic world in docs/world.md (docs/world/*.png), from the scenarios in configs/scenarios.

Omni frames are cropped to the image circle; the fisheye frame is shown at half size (area
averaging) to keep the files small. The foveal view aims the true PTZ at one person's true
head (eq 1-4 with the true rig) at zoom 2. Run: `.venv/bin/python docs/make_world_images.py`.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import cv2
import jax
import numpy as np

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs

from omnijax.world import build_world, render_foveal
from runtime.files import load_scenario
from runtime.validation.truth import true_aim, truth_line

OUT = ROOT / "docs" / "world"
SCENARIOS = ROOT / "configs" / "scenarios"


def circle(world, image: np.ndarray) -> np.ndarray:
    """``image`` cropped to the square around the omni camera's image circle."""
    om = world.true_rig.omni
    (cx, cy), rim = (float(v) for v in om.center), float(om.rim)
    H, W = image.shape[:2]
    r0, r1 = max(0, int(cy - rim) - 2), min(H, int(np.ceil(cy + rim)) + 3)
    c0, c1 = max(0, int(cx - rim) - 2), min(W, int(np.ceil(cx + rim)) + 3)
    return image[r0:r1, c0:c1]


def save(name: str, rgb: np.ndarray) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(OUT / name), np.ascontiguousarray(np.asarray(rgb)[..., ::-1]), [cv2.IMWRITE_PNG_COMPRESSION, 9])


def main() -> None:
    rig, sc = load_scenario(SCENARIOS / "six_people.toml")
    t = 50
    six = build_world(rig, sc, n_frames=t + 1)
    frame = six.frame(t)
    save("six_people.png", circle(six, np.asarray(frame.image)))
    truth = truth_line(frame.truth)
    person = max(truth["persons"], key=lambda p: p["area_px"])
    aim = true_aim(six, person)
    save("foveal.png", render_foveal(six, t, aim.pan, aim.tilt, 2.0, size=(320, 240)))

    rig, sc = load_scenario(SCENARIOS / "lamps_switching.toml")
    t = int(5.0 * sc.fps)  # lamp 0 off (4 s .. 10 s), lamp 2 on again (after 6 s: not yet)
    lamps = build_world(rig, sc, n_frames=t + 1)
    save("lamps_switching.png", circle(lamps, np.asarray(lamps.frame(t).image)))

    rig, sc = load_scenario(SCENARIOS / "fisheye_office.toml")
    fisheye = build_world(rig, sc, n_frames=1)
    image = circle(fisheye, np.asarray(fisheye.frame(0).image))
    half = (image.shape[1] // 2, image.shape[0] // 2)
    save("fisheye_office.png", cv2.resize(image, half, interpolation=cv2.INTER_AREA))


if __name__ == "__main__":
    main()
