"""Rig files: the shipped ones load; every kind of bad file fails with one line naming the key."""

from __future__ import annotations

import copy
import math
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from omnijax import ConfigError, parse_rig
from runtime.cli import main
from runtime.files import load_rig
from tests.paths import CONFIGS


def paper_dict() -> dict:
    return tomllib.loads((CONFIGS / "paper.toml").read_text())


def test_paper_rig_has_the_papers_sigmas(paper_rig):
    s, d = paper_rig.sigmas, paper_rig.detection
    assert float(s.H_o) == 0.01 and float(s.H_f) == 0.01 and float(s.D_c) == 0.10
    assert float(s.H_p) == 0.05
    assert float(d.sensor_sigma) == 1.0
    vartheta = math.hypot(float(d.sigma_theta_f), float(s.theta_c))
    assert vartheta == pytest.approx(math.radians(1.0))
    assert paper_rig.omni.model == "paraboloid"


def test_fisheye_rig_loads(fisheye_rig):
    assert fisheye_rig.omni.model == "equidistant"
    assert float(fisheye_rig.omni.rim) == pytest.approx(440.0)  # 180 deg fisheye: rim at phi = 90 deg


def test_degrees_become_radians(paper_rig):
    np.testing.assert_allclose(np.degrees(paper_rig.foveal.lens.fov_h[0]), 48.0)
    assert float(paper_rig.detection.sigma_theta_f) == pytest.approx(math.radians(1.0))


def _set(d, dotted, value):
    *path, last = dotted.split(".")
    for p in path:
        d = d[p]
    if value is _DELETE:
        del d[last]
    else:
        d[last] = value


_DELETE = object()

BAD = [
    ("omni.H_o", _DELETE, "omni.H_o: missing key"),
    ("omni.H_o", "2.7", "omni.H_o"),
    ("omni.H_o", -1.0, "omni.H_o"),
    ("foveal.D_c", -0.5, "foveal.D_c"),
    ("person.H_p", 3.0, "person.H_p = 3.0 m must be below omni.H_o"),
    ("omni.colour", "red", "omni.colour: unknown key"),
    ("omni.model", "pinhole", "omni.model"),
    ("foveal.lens.fov_h_deg", [48.0, 50.0, 12.9, 6.5, 4.4, 2.7], "fov_h_deg must decrease"),
    ("foveal.zoom_range", [1.0, 40.0], "zoom_range"),
    ("detection.x_f", 1.5, "detection.x_f"),
    ("zoom.rule", "widest", "zoom.rule"),
    ("room.outline", [[0.0, 0.0], [1.0, 0.0]], "room.outline"),
    ("omni.center", [320.0], "omni.center"),
    ("detection.light_axis", [0.5, 0.5, 0.5], "light_axis must change the light's colour"),
    ("detection.light_axis", [1.0, -1.0], "detection.light_axis"),
]


@pytest.mark.parametrize("key,value,expect", BAD, ids=[f"{k}={'<missing>' if v is _DELETE else v}" for k, v, _ in BAD])
def test_bad_config_names_the_key(key, value, expect):
    d = paper_dict()
    _set(d, key, value if value is _DELETE else copy.deepcopy(value))
    with pytest.raises(ConfigError) as err:
        parse_rig(d, source="bad.toml")
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith("bad.toml: ")
    assert expect in msg


def test_cli_bad_config_exits_2_with_one_line(tmp_path, capsys):
    d = (CONFIGS / "paper.toml").read_text().replace("H_o = 2.70", "H_o = -2.70")
    bad = tmp_path / "bad.toml"
    bad.write_text(d)
    code = main(["variance", "--config", str(bad), "--foot", "100", "0.5", "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "omni.H_o" in lines[0] and "expected metres in (0, 1000]" in lines[0]


@pytest.mark.parametrize("content,expect", [
    (None, "no such config file"),
    ("[omni\nmodel = 1", "not valid TOML"),
])
def test_missing_or_malformed_file(tmp_path, content, expect):
    path = tmp_path / "rig.toml"
    if content is not None:
        path.write_text(content)
    with pytest.raises(ConfigError, match=expect):
        load_rig(path)


def test_console_script_exit_code(tmp_path):
    """The installed entry point itself exits 2 on a missing file, nothing on stdout."""
    proc = subprocess.run(
        [sys.executable, "-m", "runtime.cli", "variance", "--config", str(tmp_path / "none.toml"),
         "--foot", "1", "0"], capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.strip().count("\n") == 0 and "no such config file" in proc.stderr


def test_ocamcalib_rig_reads_its_calibration(tmp_path):
    from tests.paths import shared_data

    calib = shared_data("catadioptric_office", "calib_results.txt")
    d = paper_dict()
    d["omni"] = {"model": "ocamcalib", "calib_file": str(calib), "H_o": 2.7, "sigma_H_o": 0.01,
                  "sigma_r_m": 0.5}
    rig = parse_rig(d, source="ocam.toml", read_text=lambda p: open(p).read())
    assert rig.omni.image_size == (1920, 1080)  # 1300 wide plus the 300 + 320 cropped columns
    np.testing.assert_allclose(np.asarray(rig.omni.center), [674.318875 + 300, 545.872616])
    assert float(rig.omni.rim) == 600.0


def test_ocamcalib_missing_file_is_one_line(tmp_path):
    d = paper_dict()
    d["omni"] = {"model": "ocamcalib", "calib_file": "nowhere.txt", "H_o": 2.7, "sigma_H_o": 0.01,
                  "sigma_r_m": 0.5}

    def read_text(p):
        return (tmp_path / p).read_text()

    with pytest.raises(ConfigError, match="omni.calib_file: cannot read 'nowhere.txt'"):
        parse_rig(d, source="ocam.toml", read_text=read_text)


# ---------------------------------------------------------------------------------------------
# Several PTZs: [[foveal]] tables


def _two_ptz_dict() -> dict:
    d = paper_dict()
    second = {**copy.deepcopy(d["foveal"]), "D_c": 4.0, "theta_c_deg": 180.0, "sigma_D_c": 0.2,
              "profile": "sony_evi_d70"}
    d["foveal"] = [d["foveal"], second]
    return d


def test_foveal_tables_give_one_rig_per_ptz(paper_rig):
    import jax

    rig = parse_rig(_two_ptz_dict(), source="two.toml")
    assert rig.ptz_count == 2 and paper_rig.ptz_count == 1
    assert rig.ptz_profiles == (None, "sony_evi_d70") and paper_rig.ptz_profiles == (None,)
    first, second = rig.ptz(0), rig.ptz(1)
    assert float(first.foveal.D_c) == 3.0 and float(first.sigmas.D_c) == 0.10
    assert float(second.foveal.D_c) == 4.0 and float(second.sigmas.D_c) == 0.20
    assert float(second.foveal.theta_c) == pytest.approx(math.pi)
    assert float(second.sigmas.H_o) == float(first.sigmas.H_o)  # the omni camera's are shared
    # one structure: the PTZs stack for jax.vmap, and a [foveal] rig's PTZ 0 is the same kind of rig
    assert jax.tree.structure(first) == jax.tree.structure(second) == jax.tree.structure(paper_rig.ptz(0))
    with pytest.raises(ValueError, match="PTZ 2 of a rig with 2"):
        rig.ptz(2)


@pytest.mark.parametrize("change,expect", [
    ({"D_c": -1.0}, "two.toml: foveal.1.D_c: expected metres in [0, 1000]"),
    ({"H_f": 3.5}, "two.toml: foveal.1.H_f = 3.5 m is above the omni camera"),
    ({"D_c": 9.0}, "two.toml: foveal.1.D_c = 9 m at theta_c_deg = 180 puts the PTZ 4.5 m outside"),
    ({"zoom": 2.0}, "two.toml: foveal.1.zoom: unknown key"),
    ({"profile": 3}, "two.toml: foveal.1.profile"),
])
def test_bad_foveal_table_is_one_line_naming_it(change, expect):
    d = _two_ptz_dict()
    d["foveal"][1].update(change)
    with pytest.raises(ConfigError) as err:
        parse_rig(d, source="two.toml")
    assert "\n" not in str(err.value) and str(err.value).startswith(expect)


@pytest.mark.parametrize("count", [0, 9])
def test_foveal_table_count_is_bounded(count):
    d = paper_dict()
    d["foveal"] = [copy.deepcopy(d["foveal"]) for _ in range(count)]
    with pytest.raises(ConfigError, match=r"^bad.toml: foveal: expected 1 to 8 \[\[foveal\]\] tables"):
        parse_rig(d, source="bad.toml")


def test_a_rig_file_extends_another_key_by_key(tmp_path):
    """``extends``: the base's tables, this file's keys over them; the shipped two-lights rig is the
    paper's but for [detection] light_axis."""
    (tmp_path / "base.toml").write_text((CONFIGS / "paper.toml").read_text())
    (tmp_path / "site.toml").write_text('extends = "base.toml"\n[detection]\nx_f = 0.02\n')
    site, paper = load_rig(tmp_path / "site.toml"), load_rig(CONFIGS / "paper.toml")
    assert float(site.detection.x_f) == 0.02 and float(paper.detection.x_f) == 0.01
    assert float(site.detection.x_m) == float(paper.detection.x_m)  # the rest of [detection] kept
    assert float(site.omni.H_o) == float(paper.omni.H_o)
    two = load_rig(CONFIGS / "two_lights.toml")
    assert two.detection.light_axis == (0.223, -0.057, -0.431) and paper.detection.light_axis is None
    assert float(two.detection.c_min) == float(paper.detection.c_min)


@pytest.mark.parametrize("text,expect", [
    ('extends = "none.toml"', "extends: no such rig file"),
    ("extends = 3", "extends: expected the name of a rig file"),
    ('extends = "rig.toml"', "a loop"),
])
def test_a_bad_extends_is_one_line(tmp_path, text, expect):
    path = tmp_path / "rig.toml"
    path.write_text(text + "\n")
    with pytest.raises(ConfigError, match=expect) as err:
        load_rig(path)
    assert "\n" not in str(err.value)
