"""Scenario files: the shipped ones load; a bad file fails with one line naming the key."""

from __future__ import annotations

import copy
import tomllib

import numpy as np
import pytest

from omnijax import ConfigError
from omnijax.world import parse_scenario
from runtime.cli import main
from runtime.files import load_scenario
from tests.paths import CONFIGS

SCENARIOS = sorted((CONFIGS / "scenarios").glob("*.toml"))


def test_the_eleven_scenarios_exist():
    names = {p.stem for p in SCENARIOS}
    assert names == {"empty_room", "one_person", "three_people", "six_people", "lamps_switching", "fisheye_office",
                     "standing_start", "stops_a_minute", "chair_moved", "two_spectra", "flickering_screen"}


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_scenarios_load(path):
    rig, sc = load_scenario(path)
    assert sc.name and sc.fps > 0
    assert sc.lighting.count >= 1
    assert float(sc.height) > float(rig.omni.H_o)


def test_fisheye_scenario_uses_the_fisheye_rig():
    rig, sc = load_scenario(CONFIGS / "scenarios" / "fisheye_office.toml")
    assert rig.omni.model == "equidistant" and rig.omni.image_size == (1280, 960)
    assert sc.sensor.jpeg_quality == 90


def test_lamp_switching_times():
    _, sc = load_scenario(CONFIGS / "scenarios" / "lamps_switching.toml")
    li = sc.lighting
    assert [bool(v) for v in li.lamp_on(0.0)] == [True, True, False]
    assert [bool(v) for v in li.lamp_on(5.0)] == [False, True, False]
    assert [bool(v) for v in li.lamp_on(7.0)] == [False, True, True]
    assert [bool(v) for v in li.lamp_on(10.0)] == [True, True, True]


def test_first_pause_and_stops():
    _, sc = load_scenario(CONFIGS / "scenarios" / "stops_a_minute.toml")
    assert [float(v) for v in sc.crowd.first_pause] == [0.0, 0.0]
    assert sc.crowd.stop_start.shape == (3, 1)
    assert float(sc.crowd.stop_start[0, 0]) == 6.0 and float(sc.crowd.stop_end[0, 0]) == 72.0
    assert np.all(np.isinf(np.asarray(sc.crowd.stop_start[1:])))
    _, sc = load_scenario(CONFIGS / "scenarios" / "standing_start.toml")
    assert [float(v) for v in sc.crowd.first_pause] == [4.0, 12.0] and sc.crowd.stop_start.shape == (3, 0)


def test_moving_furniture():
    _, sc = load_scenario(CONFIGS / "scenarios" / "chair_moved.toml")
    fu = sc.furniture
    assert fu.moving == (3,) and fu.arrangements == 2
    assert float(fu.move_at[3]) == 8.0 and np.all(np.isinf(np.asarray(fu.move_at[:3])))
    np.testing.assert_allclose(np.asarray(fu.moved_lo[3]), [-0.9, 0.8])
    assert [int(fu.arrangement(t)) for t in (0.0, 7.99, 8.0, 60.0)] == [0, 0, 1, 1]
    lo, hi = fu.placed(1)
    np.testing.assert_allclose(np.asarray(hi[3] - lo[3]), [0.5, 0.5])
    assert fu.footprints()[0].shape == (5, 2)
    np.testing.assert_allclose(np.asarray(fu.moved_centres()), [[0.85, 1.05], [-0.65, 1.05]])


def test_lamp_spectra_default_to_the_shared_one():
    _, sc = load_scenario(CONFIGS / "scenarios" / "three_people.toml")
    np.testing.assert_array_equal(np.asarray(sc.lighting.lamp_spectrum), np.tile(sc.lighting.spectrum, (3, 1)))
    _, sc = load_scenario(CONFIGS / "scenarios" / "two_spectra.toml")
    np.testing.assert_allclose(np.asarray(sc.lighting.lamp_spectrum),
                               [[0.80, 0.90, 1.0], [1.0, 0.85, 0.65], [1.0, 0.85, 0.65]])


def test_a_screen_shows_its_colours_in_turn():
    _, sc = load_scenario(CONFIGS / "scenarios" / "flickering_screen.toml")
    screens = sc.screens
    assert screens.size == 1 and int(screens.wall[0]) == 0 and int(screens.count[0]) == 4
    np.testing.assert_allclose(np.asarray(screens.along[0]), [3.2, 4.4])
    colours = np.asarray(screens.colours[0])
    for t, j in ((0.0, 0), (0.49, 0), (0.5, 1), (1.2, 2), (1.99, 3), (2.0, 0), (61.3, 2)):
        np.testing.assert_array_equal(np.asarray(screens.shown(t))[0], colours[j], err_msg=str(t))
    _, sc = load_scenario(CONFIGS / "scenarios" / "three_people.toml")
    assert sc.screens.size == 0 and sc.screens.shown(1.0).shape == (0, 3)


def test_noise_sigma_defaults_to_the_rigs(paper_rig):
    _, sc = load_scenario(CONFIGS / "scenarios" / "one_person.toml")
    assert float(sc.sensor.noise_sigma) == float(paper_rig.detection.sensor_sigma)


def _data() -> dict:
    return tomllib.loads((CONFIGS / "scenarios" / "one_person.toml").read_text())


_DELETE = object()


def _edit(d: dict, dotted: str, value) -> dict:
    d = copy.deepcopy(d)
    node = d
    *path, last = dotted.split(".")
    for p in path:
        node = node[int(p)] if isinstance(node, list) else node[p]
    key = int(last) if isinstance(node, list) else last
    if value is _DELETE:
        del node[key]
    else:
        node[key] = value
    return d


SCREEN = {"wall": 0, "along_m": [3.2, 4.4], "height_m": [0.8, 1.5], "colours": [[200.0, 70.0, 50.0]],
          "period_s": 2.0}
BAD = [
    ("room.height", _DELETE, "room.height: missing key"),
    ("room.floor.colour", [0.5, 0.5, 1.5], "room.floor.colour.2"),
    ("room.floor.colour", [0.5, 0.5], "room.floor.colour"),
    ("room.walls.shine", 1.0, "room.walls.shine: unknown key"),
    ("room.height", 2.5, "room.height"),
    ("people.count", -1, "people.count"),
    ("people.count", "3", "people.count"),
    ("people.speed", [1.4, 0.8], "people: speed must be [low, high]"),
    ("people.first_pause", [12.0, 4.0], "people: first_pause must be [low, high]"),
    ("people.first_pause", [-1.0, 4.0], "people.first_pause.0"),
    ("people.stops", [{"person": 1, "at_s": 1.0, "seconds": 2.0}], "people.stops.0.person: 1 is not a person"),
    ("people.stops", [{"person": 0, "at_s": 1.0, "seconds": 0.0}], "people.stops.0.seconds"),
    ("people.stops", [{"person": 0, "at_s": 1.0}], "people.stops.0.seconds: missing key"),
    ("people.stops", [{"person": 0, "at_s": 1.0, "seconds": 5.0}, {"person": 0, "at_s": 3.0, "seconds": 1.0}],
     "people.stops.1: overlaps people.stops.0"),
    ("lighting.lamps.0.spectrum", [1.0, 0.0, 0.5], "lighting.lamps.0.spectrum.1"),
    ("lighting.lamps.0.spectrum", [1.0, 0.9], "lighting.lamps.0.spectrum"),
    ("furniture.2.move_at_s", 8.0, "furniture.2: move_at_s and moved_to go together"),
    ("furniture.2.moved_to", [0.0, 1.0], "furniture.2: move_at_s and moved_to go together"),
    ("furniture.2", {"corner_min": [-2.6, -0.9], "corner_max": [-1.6, 0.3], "height": 0.74,
                     "colour": [0.5, 0.5, 0.5], "move_at_s": 8.0, "moved_to": [2.9, 0.0]},
     "furniture.2.moved_to"),
    ("furniture.2.move_at_s", -1.0, "furniture.2.move_at_s"),
    ("lighting.spectrum", [1.0, 0.0, 0.5], "lighting.spectrum.1"),
    ("lighting.lamps.0.position", [-2.4, -1.2, 3.5], "lighting.lamps.0.position"),
    ("lighting.lamps.0.position", [9.0, 0.0, 2.9], "lighting.lamps.0.position"),
    ("lighting.lamps.0.switch", [3.0, 1.0], "lighting.lamps.0: switch times must increase"),
    ("furniture.0.corner_max", [-4.0, 2.0], "furniture.0"),
    ("furniture.1.height", 3.5, "furniture.1.height"),
    ("sensor.jpeg_quality", 0, "sensor.jpeg_quality"),
    ("sensor.antialias", 9, "sensor.antialias"),
    ("fps", 0.0, "fps"),
    ("screens", [{**SCREEN, "wall": 7}], "screens.0.wall: 7 is not an edge of the rig's room.outline (0 .. 3)"),
    ("screens", [{**SCREEN, "along_m": [7.0, 9.0]}], "screens.0.along_m: [7.0, 9.0] must lie within the wall's 7.8 m"),
    ("screens", [{**SCREEN, "along_m": [2.0, 1.0]}], "screens.0: along_m must be [from, to]"),
    ("screens", [{**SCREEN, "height_m": [1.0, 3.5]}], "screens.0.height_m"),
    ("screens", [{**SCREEN, "colours": []}], "screens.0.colours"),
    ("screens", [{**SCREEN, "colours": [[1.0, 2.0]]}], "screens.0.colours.0"),
    ("screens", [{**SCREEN, "period_s": 0.0}], "screens.0.period_s"),
    ("screens", [{k: v for k, v in SCREEN.items() if k != "wall"}], "screens.0.wall: missing key"),
]


@pytest.mark.parametrize("key,value,expect", BAD, ids=[b[0] + "-" + str(i) for i, b in enumerate(BAD)])
def test_bad_scenario_one_line(paper_rig, key, value, expect):
    with pytest.raises(ConfigError) as e:
        parse_scenario(_edit(_data(), key, value), paper_rig, source="s.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("s.toml: ") and expect in msg, msg


def _write(tmp_path, text: str):
    path = tmp_path / "scenarios" / "bad.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


@pytest.mark.parametrize("edit,expect", [
    (lambda t: t.replace('rig = "../paper.toml"', 'rig = "../nowhere.toml"'), "rig: no such rig file"),
    (lambda t: t.replace("[people]", "[people]\nheight = 2"), "people.height: unknown key"),
    (lambda t: t.replace("count = 1", "count = 12").replace("gap = 0.10", "gap = 2.5"), "not everybody fits"),
    (lambda t: t + "\n[[[", "not valid TOML"),
], ids=["missing-rig", "unknown-key", "too-many-people", "toml-syntax"])
def test_render_with_bad_scenario_exits_2(tmp_path, capsys, edit, expect):
    (tmp_path / "paper.toml").write_text((CONFIGS / "paper.toml").read_text())
    path = _write(tmp_path, edit((CONFIGS / "scenarios" / "one_person.toml").read_text()))
    out = tmp_path / "out"
    code = main(["render", "--scenario", str(path), "--frames", "2", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 2 and expect in captured.err and captured.err.count("\n") == 1, captured.err
    assert not out.exists() and not list(tmp_path.glob(".out.partial*"))
