"""``omnijax render``: docs/design.md section 7.3's contract (video + truth.jsonl), staged output, bad input."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from runtime.cli import build_parser, main
from tests.paths import CONFIGS

SIX = str(CONFIGS / "scenarios" / "six_people.toml")


def test_render_writes_video_truth_and_world(tmp_path, capsys, six_world):
    out = tmp_path / "r"
    code = main(["render", "--scenario", SIX, "--frames", "4", "--out", str(out), "--png-every", "3"])
    assert code == 0, capsys.readouterr().err
    lines = [json.loads(line) for line in (out / "truth.jsonl").read_text().splitlines()]
    assert [line["frame"] for line in lines] == [0, 1, 2, 3]
    for line in lines:
        assert len(line["persons"]) == 6
        for p in line["persons"]:
            assert set(p) >= {"id", "foot_m", "head_m", "r_f", "theta_f"}
            assert len(p["foot_m"]) == 2 and len(p["head_m"]) == 3
            assert p["head_m"][:2] == p["foot_m"]
    world = json.loads((out / "world.json").read_text())
    assert world["frames"] == 4 and world["seed"] == 6 and world["camera_model"] == "paraboloid"
    assert set(world["true_rig"]) >= {"H_o_m", "r_m_px", "H_f_m", "D_c_m", "theta_c_rad"}
    assert len(world["people"]) == 6
    assert sorted(p.name for p in (out / "frames").iterdir()) == ["000000.png", "000003.png"]
    video = cv2.VideoCapture(str(out / "omni.avi"))
    frames = []
    while True:
        ok, frame = video.read()
        if not ok:
            break
        frames.append(frame[..., ::-1])
    assert len(frames) == 4 and frames[0].shape == (480, 640, 3)
    # ffv1 is lossless: the video holds exactly the world's frames (same scenario, same seed)
    assert np.array_equal(frames[2], np.asarray(six_world.frame(2).image))
    assert lines[2]["persons"][0]["r_f"] == pytest.approx(float(six_world.frame(2).truth.r_f[0]), abs=1e-9)
    assert not list(tmp_path.glob(".r.partial*"))


@pytest.mark.slow
def test_render_by_name_records_moved_furniture_and_lamp_spectra(tmp_path, capsys):
    """A scenario named without its path; ``--seed`` overrides the file's; world.json lists the moved
    chair (both footprint centres, the time) and every lamp's spectrum."""
    out = tmp_path / "r"
    code = main(["render", "--scenario", "chair_moved", "--frames", "2", "--out", str(out), "--seed", "12"])
    assert code == 0, capsys.readouterr().err
    world = json.loads((out / "world.json").read_text())
    assert world["scenario"] == "chair moved" and world["seed"] == 12
    [moved] = world["moved_furniture"]
    assert moved["index"] == 3 and moved["at_s"] == 8.0 and moved["height_m"] == pytest.approx(0.9)
    assert moved["from_m"] == pytest.approx([0.85, 1.05]) and moved["to_m"] == pytest.approx([-0.65, 1.05])
    assert moved["size_m"] == pytest.approx([0.5, 0.5])
    assert [lamp["spectrum"] for lamp in world["lamps"]] == [pytest.approx([1.0, 0.93, 0.80])] * 3
    assert world["ambient_spectrum"] == pytest.approx([1.0, 0.93, 0.80])


@pytest.mark.parametrize("args,expect", [
    (["--frames", "0"], "--frames"),
    (["--frames", "10000000"], "--frames"),
    (["--frames", "2", "--png-every", "-1"], "--png-every"),
    (["--frames", "2", "--foveal-zoom", "0"], "--foveal-zoom"),
    (["--frames", "2", "--seed", "-3"], "--seed"),
])
def test_render_bad_arguments_exit_2(tmp_path, capsys, args, expect):
    out = tmp_path / "r"
    code = main(["render", "--scenario", SIX, "--out", str(out), *args])
    err = capsys.readouterr().err
    assert code == 2 and expect in err and err.count("\n") == 1
    assert not out.exists()


def test_render_missing_scenario_or_out_on_a_file_exits_2(tmp_path, capsys):
    code = main(["render", "--scenario", str(tmp_path / "none.toml"), "--frames", "2", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and "no such scenario file" in err and err.count("\n") == 1
    blocker = tmp_path / "file"
    blocker.write_text("")
    code = main(["render", "--scenario", SIX, "--frames", "2", "--out", str(blocker / "r")])
    err = capsys.readouterr().err
    assert code == 2 and "--out" in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_help_lists_render(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["render", "--help"])
    out = capsys.readouterr().out
    assert "truth.jsonl" in out and "--png-every" in out


@pytest.mark.slow
def test_bench_reports_the_detector_and_the_cameras_one_core_serves(tmp_path):
    """``omnijax bench --json`` in its own process (it pins itself to one core before JAX loads): the
    detector's figures per size with no compilation while timed, and the control path's
    ``cameras_per_core`` (the frame period over the mean time per frame) with its details."""
    import subprocess
    import sys

    from tests.paths import ROOT

    run = subprocess.run([sys.executable, "-m", "runtime.cli", "bench", "--sizes", "160x120", "--frames", "10",
                          "--json"], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    report = json.loads(run.stdout)
    small = report["160x120"]
    assert small["compiles"] == 0 and small["detect_ms"]["p50"] > 0 and small["mog2_ms"]["p50"] > 0
    control = report["control"]
    assert control["size"] == "640x480" and control["frames"] == 10
    f = control["frame_ms"]
    assert 0 < f["p50"] <= f["p90"] <= f["max"]
    assert report["cameras_per_core"] == pytest.approx(1e3 / control["fps"] / f["mean"])
    assert control["life_ms"]["n"] == 5 and control["life_ms"]["p50"] > 0  # stepped every second frame
