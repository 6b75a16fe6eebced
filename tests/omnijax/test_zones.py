"""``[[zones]]`` of a rig: parsed and checked (one line naming the key), and the ignore zones in the
detector's polar index, so that a person painted inside one is never detected while one outside is."""

from __future__ import annotations

import dataclasses
import math
import tomllib

import jax.numpy as jnp
import numpy as np
import pytest

from omnijax import detect, learn_background, line_background
from omnijax.config import ConfigError, Zone, parse_rig, parse_zones, zone_mask
from omnijax.detection import build_polar_index, with_zones
from tests.omnijax.test_detection import _noisy, _paint_person, _textured
from tests.paths import CONFIGS

SQUARE = [[100, 100], [200, 100], [200, 200], [100, 200]]


def test_zones_parse_from_the_rig_file():
    data = tomllib.loads((CONFIGS / "paper.toml").read_text())
    data["zones"] = [{"kind": "ignore", "points": SQUARE, "name": "screen"},
                     {"kind": "priority", "points": [[300, 300], [400, 300], [350, 400]]}]
    rig = parse_rig(data, source="rig.toml")
    assert rig.zones == (Zone("ignore", tuple(map(tuple, map(lambda p: map(float, p), SQUARE))), "screen"),
                         Zone("priority", ((300.0, 300.0), (400.0, 300.0), (350.0, 400.0))))
    assert rig.zones[0].as_dict() == {"kind": "ignore", "points": SQUARE, "name": "screen"}
    assert parse_rig(tomllib.loads((CONFIGS / "paper.toml").read_text())).zones == ()


@pytest.mark.parametrize("zone, expected", [
    ({"kind": "ignore", "points": [[1, 1], [5, 5]]}, "zones.0.points: List should have at least 3 items"),
    ({"kind": "hide", "points": SQUARE}, "zones.0.kind:"),
    ({"kind": "ignore", "points": [[0, 0], [100, 100], [100, 0], [0, 100]]}, "edges 0-1 and 2-3 cross"),
    ({"kind": "ignore", "points": [[0, 0], [50, 50], [100, 100]]}, "corners not all on one line"),
    ({"kind": "ignore", "points": [[600, 400], [700, 400], [650, 470]]}, "point 1 (700, 400) lies outside the 640x480"),
    ({"kind": "ignore", "points": SQUARE, "colour": "red"}, "zones.0.colour: unknown key"),
    ({"kind": "ignore", "points": [[1, "a"], [5, 5], [9, 1]]}, "zones.0.points.0.1:"),
])
def test_bad_zones_are_one_line_naming_the_key(zone, expected):
    data = tomllib.loads((CONFIGS / "paper.toml").read_text())
    data["zones"] = [zone]
    with pytest.raises(ConfigError) as err:
        parse_rig(data, source="rig.toml")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("rig.toml: zones.0.") and expected in msg
    with pytest.raises(ConfigError, match="zones.0."):  # the console's path: the same checks
        parse_zones([zone], (640, 480), "POST /api/zones")


def test_zone_mask_is_the_polygon():
    tri = Zone("ignore", ((10.0, 10.0), (30.0, 10.0), (10.0, 30.0)))
    mask = zone_mask((tri, Zone("priority", ((0.0, 0.0), (5.0, 0.0), (0.0, 5.0)))), "ignore", (40, 40))
    yy, xx = np.mgrid[:40, :40]
    assert mask[(xx > 10.5) & (yy > 10.5) & (xx + yy < 39.5)].all()  # away from the edges, where rounding
    assert not mask[(xx < 9.5) | (yy < 9.5) | (xx + yy > 40.5)].any()  # decides
    assert not mask[:5, :5].any()  # the priority zone is not an ignore zone


@pytest.fixture(scope="module")
def scene(paper_detector):
    rng = np.random.default_rng(7)
    base = _textured(rng, 480, 640)
    bg = learn_background(np.stack([_noisy(rng, base) for _ in range(30)]))
    return rng, base, bg


def _wedge(detector, theta, r0, r1, half):
    cx, cy = np.asarray(detector.omni.center)
    a = np.linspace(theta - half, theta + half, 8)
    outer = np.stack([cx + r1 * np.cos(a), cy + r1 * np.sin(a)], -1)
    inner = np.stack([cx + r0 * np.cos(a[::-1]), cy + r0 * np.sin(a[::-1])], -1)
    return tuple(map(tuple, np.concatenate([outer, inner]).tolist()))


def test_ignore_zone_is_not_computed_and_hides_who_stands_there(paper_rig, paper_detector, scene):
    rng, base, bg = scene
    polar = paper_detector.polar
    i = int(np.argmin(np.abs(np.asarray(polar.radii) - 80.0)))
    r0, r1 = float(polar.radii[0]) - 2, float(polar.radii[-1]) + 2
    zone = Zone("ignore", _wedge(paper_detector, 1.0, r0, r1, 0.25), "screen")
    rig = dataclasses.replace(paper_rig, zones=(zone,))
    masked = with_zones(paper_detector, rig)
    # nothing sampled inside: lines wholly inside have no samples and thresholds that never fire
    ok = np.asarray(masked.polar.line_ok)
    idx = np.asarray(masked.polar.line_index)
    H, W = 480, 640
    inside = zone_mask(rig.zones, "ignore", (W, H)).reshape(-1)
    assert not inside[idx[ok]].any() and inside[idx[np.asarray(polar.line_ok)]].any()
    theta = np.asarray(polar.theta)
    hidden = np.abs(np.angle(np.exp(1j * (theta - 1.0)))) < 0.15
    assert (np.asarray(masked.polar.samples)[hidden] == 0).all()
    assert np.isinf(np.asarray(masked.thresholds.lower)[hidden]).all()
    # the same as building the detector for that rig from scratch (polar index, thresholds)
    assert np.array_equal(np.asarray(build_polar_index(rig).line_ok), ok)
    # a person painted in the zone is found without it and not with it; one outside is found by both
    for theta_p, seen_masked in ((1.0, False), (-2.0, True)):
        frame = jnp.asarray(_noisy(rng, _paint_person(rng, base, paper_detector, i, theta_p)))
        for det, expect in ((paper_detector, True), (masked, seen_masked)):
            d, _ = detect(det, frame, bg, line_background(det, bg))
            found = [float(t) for t, v in zip(np.asarray(d.theta_f), np.asarray(d.valid)) if v]
            near = [t for t in found if abs(math.remainder(t - theta_p, 2 * math.pi)) < 0.1]
            assert bool(near) == expect, (theta_p, found)
