"""Rig files a hostile user writes: inf, nan and absurd magnitudes in every numeric key, and finite
rigs the geometry makes impossible. Each is refused with one line naming the key (and why)."""

from __future__ import annotations

import copy
import math
import tomllib

import pytest

from omnijax import ConfigError, parse_rig
from runtime.files import load_rig
from tests.paths import CONFIGS

#: Every number of configs/paper.toml by its dotted key (lists by their first element).
NUMERIC = [
    "omni.H_o", "omni.sigma_H_o", "omni.r_m", "omni.sigma_r_m", "omni.center", "foveal.D_c", "foveal.sigma_D_c",
    "foveal.theta_c_deg", "foveal.sigma_theta_c_deg", "foveal.H_f", "foveal.sigma_H_f", "foveal.pan_limits_deg",
    "foveal.tilt_limits_deg", "foveal.zoom_range", "foveal.lens.zoom", "foveal.lens.fov_h_deg", "person.H_p",
    "person.sigma_H_p", "person.R_h", "person.sigma_R_h", "person.shoulder_width", "detection.sensor_sigma",
    "detection.x_f", "detection.x_m", "detection.sigma_r_f", "detection.sigma_theta_f_deg", "zoom.p_contain",
    "layout.D_c", "layout.H_f", "layout.grid_step", "layout.near_radius", "layout.face_target_px",
]


def paper() -> dict:
    return tomllib.loads((CONFIGS / "paper.toml").read_text())


def _set(d: dict, dotted: str, value) -> None:
    *path, last = dotted.split(".")
    for p in path:
        d = d[p]
    if value is None:
        del d[last]
    elif isinstance(d.get(last), list) and not isinstance(value, list):  # a number into a list's first place
        d[last] = [value, *d[last][1:]]
    else:
        d[last] = value


def refused(changes: dict) -> str:
    d = paper()
    for key, value in changes.items():
        _set(d, key, copy.deepcopy(value))
    with pytest.raises(ConfigError) as err:
        parse_rig(d, source="bad.toml")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("bad.toml: ")
    return msg


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan], ids=["inf", "-inf", "nan"])
@pytest.mark.parametrize("key", NUMERIC)
def test_non_finite_numbers_are_refused_naming_the_key(key, value):
    msg = refused({key: value})
    assert key.split(".")[-1] in msg


@pytest.mark.parametrize("key,expect", [
    ("omni.H_o", "expected metres in (0, 1000]"),
    ("omni.sigma_H_o", "expected metres in [0, 1000]"),
    ("omni.r_m", "expected pixels in (0, 100000]"),
    ("omni.sigma_r_m", "expected pixels in [0, 100000]"),
    ("foveal.D_c", "expected metres in [0, 1000]"),
    ("foveal.sigma_D_c", "expected metres"),
    ("foveal.theta_c_deg", "expected degrees in [-360, 360]"),
    ("foveal.sigma_theta_c_deg", "a sigma above 180 deg says nothing"),
    ("person.sigma_R_h", "expected metres"),
    ("detection.sensor_sigma", "an 8-bit image's whole range"),
    ("detection.sigma_r_f", "expected pixels"),
    ("detection.sigma_theta_f_deg", "expected degrees in (0, 180]"),
    ("detection.c_min", "a non-centrality per pixel"),
    ("detection.r_max", "expected pixels"),
    ("detection.min_floor_radius", "expected metres"),
    ("foveal.lens.zoom", "no PTZ lens magnifies more"),
])
def test_absurd_magnitudes_are_refused_with_the_unit(key, expect):
    msg = refused({key: 1e300})
    assert key.split(".")[-1] in msg and expect in msg and "1e+300" in msg


@pytest.mark.parametrize("changes,expect", [
    ({"omni.center": [1e9, 240.0]}, "omni.center: (1e+09, 240) px lies outside the 640x480 image"),
    ({"omni.center": [-5.0, 240.0]}, "lies outside the 640x480 image"),
    ({"omni.image_size": [10_000_000_000, 480]}, "omni.image_size.0: expected pixels in [1, 32768]"),
    ({"foveal.H_f": 3.5}, "foveal.H_f = 3.5 m is above the omni camera (omni.H_o = 2.7 m)"),
    ({"layout.H_f": [1.15, 30.0]}, "layout.H_f bounds [1.15, 30.0] reach above the omni camera"),
    ({"foveal.tilt_limits_deg": [-200.0, 200.0]}, "foveal.tilt_limits_deg.0: expected degrees in [-90, 90]"),
    ({"foveal.pan_limits_deg": [-200.0, 200.0]}, "span more than one turn"),
    ({"room.outline": [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]}, "room: outline encloses 0 m^2 of floor"),
    ({"room.outline": [[-2e6, 0.0], [1.0, 0.0], [2.0, 1.0]]}, "room.outline.0.0: expected metres in [-1000, 1000]"),
    ({"person.shoulder_width": 2.0}, "shoulder_width = 2 m must be less than H_p = 1.75 m"),
    ({"layout.face_target_px": 5000.0}, "wider than the PTZ's image (foveal.image_size 640 px)"),
    ({"foveal.D_c": 1000.0}, "puts the PTZ 997 m outside the room's outline"),
    ({"foveal.D_c": 4.2}, "puts the PTZ 0.9 m outside the room's outline"),
    ({"room.outline": [[10.0, 10.0], [20.0, 10.0], [20.0, 20.0], [10.0, 20.0]], "room.exclude": []},
     "the omni camera's axis (the origin of room.outline) lies 14.1 m outside"),
])
def test_impossible_but_finite_rigs_say_why(changes, expect):
    assert expect in refused(changes)


@pytest.mark.parametrize("changes,expect", [
    ({"omni.r_m": 1e5}, "images between radii"),  # the floor is far outside the image
    ({"omni.r_m": 2.0}, "images between radii"),  # the whole room on a few pixels
    ({"omni.H_o": 1000.0}, "images between radii"),  # a camera on a tower over a room
    ({"detection.min_floor_radius": 100.0}, "from detection.min_floor_radius (100 m)"),
])
def test_a_rig_that_cannot_see_its_room_is_refused_on_loading(tmp_path, changes, expect):
    import tomlkit

    doc = tomlkit.parse((CONFIGS / "paper.toml").read_text())
    for dotted, value in changes.items():
        section, key = dotted.split(".")
        doc[section][key] = value
    path = tmp_path / "rig.toml"
    path.write_text(tomlkit.dumps(doc))
    with pytest.raises(ConfigError) as err:
        load_rig(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: ") and expect in msg and "nobody could be detected" in msg


def test_cameras_on_a_wall_are_allowed():
    d = paper()
    d["foveal"]["D_c"] = 3.6  # 0.3 m beyond the outline at x = 3.3: on the wall
    parse_rig(d, source="wall.toml")


def test_sigma_r_m_is_required_and_exclude_and_rule_are_optional():
    """The comments and the schema agree: every sigma is required; room.exclude and zoom.rule have defaults."""
    assert refused({"omni.sigma_r_m": None}) == "bad.toml: omni.sigma_r_m: missing key"
    d = paper()
    del d["room"]["exclude"], d["zoom"]["rule"]
    rig = parse_rig(d, source="ok.toml")
    assert rig.room.exclude == () and rig.zoom_rule == "calibrated"
    text = (CONFIGS / "paper.toml").read_text()
    for key in ("rule = ", "exclude = "):
        line = next(s for s in text.splitlines() if s.startswith(key))
        assert "optional, default" in line


@pytest.mark.parametrize("name", ["paper", "corridor", "l_room", "office_fisheye"])
def test_shipped_rigs_pass_every_check(name):
    load_rig(CONFIGS / f"{name}.toml")
