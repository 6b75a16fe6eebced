"""Scenario files: the shipped ones load; a bad file fails with one line naming the key."""

from __future__ import annotations

import copy
import tomllib

import pytest

from omnijax import ConfigError
from omnijax.world import parse_scenario
from runtime.cli import main
from runtime.files import load_scenario
from tests.paths import CONFIGS

SCENARIOS = sorted((CONFIGS / "scenarios").glob("*.toml"))


def test_the_six_scenarios_exist():
    names = {p.stem for p in SCENARIOS}
    assert names == {"empty_room", "one_person", "three_people", "six_people", "lamps_switching", "fisheye_office"}


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
    if value is _DELETE:
        del node[last]
    else:
        node[last] = value
    return d


BAD = [
    ("room.height", _DELETE, "room.height: missing key"),
    ("room.floor.colour", [0.5, 0.5, 1.5], "room.floor.colour.2"),
    ("room.floor.colour", [0.5, 0.5], "room.floor.colour"),
    ("room.walls.shine", 1.0, "room.walls.shine: unknown key"),
    ("room.height", 2.5, "room.height"),
    ("people.count", -1, "people.count"),
    ("people.count", "3", "people.count"),
    ("people.speed", [1.4, 0.8], "people: speed must be [low, high]"),
    ("lighting.spectrum", [1.0, 0.0, 0.5], "lighting.spectrum.1"),
    ("lighting.lamps.0.position", [-2.4, -1.2, 3.5], "lighting.lamps.0.position"),
    ("lighting.lamps.0.position", [9.0, 0.0, 2.9], "lighting.lamps.0.position"),
    ("lighting.lamps.0.switch", [3.0, 1.0], "lighting.lamps.0: switch times must increase"),
    ("furniture.0.corner_max", [-4.0, 2.0], "furniture.0"),
    ("furniture.1.height", 3.5, "furniture.1.height"),
    ("sensor.jpeg_quality", 0, "sensor.jpeg_quality"),
    ("sensor.antialias", 9, "sensor.antialias"),
    ("fps", 0.0, "fps"),
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
