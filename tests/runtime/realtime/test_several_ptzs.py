"""Several PTZs end to end: ``omnijax demo --ptz-count 2`` (the summary's ``cameras``, face coverage per
person over both PTZs, the log, the view with both insets) and ``omnijax run`` with one ``--ptz`` per
``[[foveal]]`` table on the demo's recorded omni frames; bad flags. The demo runs once for the module
(120 frames, every frame processed) as a child process, as users run it."""

from __future__ import annotations

import json
import tomllib

import cv2
import pytest
import tomlkit

from runtime.cli import main
from tests.paths import CONFIGS
from tests.runtime.realtime.test_demo_run import omnijax


@pytest.fixture(scope="module")
def demo2(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo2") / "out"
    proc = omnijax("demo", "--out", str(out), "--ptz-count", "2", "--frames", "120", "--pace", "all",
                   "--background-seconds", "0", "--screenshot", "60", "--inset-every", "30", "--record", "--quiet")
    stdout, stderr = proc.communicate(timeout=400)
    assert proc.returncode == 0, stderr[-2000:]
    assert "PTZ 1: head in frame" in stdout
    return out


@pytest.mark.slow
def test_demo_with_two_ptzs_scores_each_camera_and_each_person(demo2):
    s = json.loads((demo2 / "summary.json").read_text())
    cams = s["cameras"]
    assert [c["id"] for c in cams] == [0, 1] and s["config"]["ptz_count"] == 2
    for c in cams:
        assert {"id", "framed_rate", "target_frames", "handoffs"} <= set(c)
        assert c["target_frames"] > 10 and 0 <= c["framed_rate"] <= 1 and c["handoffs"] >= 0
        assert c["framed_rate"] == c["rules"]["calibrated"]["contained"] / c["target_frames"]
        assert c["driver"]["commands"] > 0 and c["emulator"]["pan_deg"] == 0  # each PTZ driven, then home
    cont = s["containment"]
    assert cont["trials"] == sum(c["target_frames"] for c in cams)
    assert cont["rules"]["calibrated"]["contained"] == sum(c["rules"]["calibrated"]["contained"] for c in cams)
    # face coverage: a person framed by both PTZs in one frame counts once
    framed = sum(round(q["rules"]["calibrated"] * q["frames_in_view"]) for q in s["face_coverage"]["people"])
    assert framed <= cont["rules"]["calibrated"]["contained"]
    assert all(0 <= q["rules"]["calibrated"] <= 1 for q in s["face_coverage"]["people"])
    assert cont["rate_person_frames"] <= 1 and s["assignment"]["doubled_while_waiting"] == 0
    log = [json.loads(line) for line in (demo2 / "log.jsonl").read_text().splitlines()]
    with_target = [r for r in log if any(r.get("ptzs") or [])]
    assert with_target and all(len(r["ptzs"]) == 2 and "ptz" not in r for r in with_target)
    video = cv2.VideoCapture(str(demo2 / s["outputs"]["video"]))
    ok, img = video.read()
    assert ok and img.shape == (480, 960, 3)
    assert (demo2 / "view.png").is_file()


@pytest.mark.slow
def test_run_drives_one_ptz_per_foveal_table(demo2, tmp_path):
    """``omnijax run`` with a rig of two ``[[foveal]]`` tables and two ``--ptz`` (emulated cameras): both
    are driven and sent home, and the summary has both."""
    from runtime.ptz import PtyEmulator, default_profile

    rig = tomllib.loads((CONFIGS / "paper.toml").read_text())
    rig["foveal"] = [rig["foveal"], {**rig["foveal"], "theta_c_deg": 180.0}]
    config = tmp_path / "two.toml"
    config.write_text(tomlkit.dumps(rig))
    out = tmp_path / "run"
    with PtyEmulator(default_profile("visca")) as first, PtyEmulator(default_profile("visca")) as second:
        proc = omnijax("run", str(demo2 / "omni.avi"), "--config", str(config), "--ptz", first.path,
                       "--ptz", second.path, "--out", str(out), "--pace", "all", "--no-video", "--quiet",
                       "--background-seconds", "0", "--max-frames", "60")
        _, stderr = proc.communicate(timeout=300)
        states = [first.state(), second.state()]
    assert proc.returncode == 0, stderr[-2000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["frames"] == 60 and len(s["cameras"]) == 2 and len(s["ptz_urls"]) == 2
    assert all(c["driver"]["commands"] > 0 for c in s["cameras"]) and s["ptz_homed"]
    assert all(st["commands"] > 0 and st["pan_deg"] == 0 and st["zoom"] == 1 for st in states)


@pytest.mark.parametrize("argv, expected", [
    (["demo", "--out", "X", "--ptz-count", "0"], "--ptz-count: expected 1 to 8"),
    (["demo", "--out", "X", "--ptz-count", "9"], "--ptz-count: expected 1 to 8"),
    (["run", ".", "--config", "TWO", "--out", "X", "--ptz", "loop://"], "--ptz: "),
])
def test_bad_ptz_counts_are_one_line_and_exit_2(argv, expected, capsys, tmp_path):
    rig = tomllib.loads((CONFIGS / "paper.toml").read_text())
    rig["foveal"] = [rig["foveal"], {**rig["foveal"], "theta_c_deg": 180.0}]
    (tmp_path / "two.toml").write_text(tomlkit.dumps(rig))
    argv = [str(tmp_path / a) if a == "X" else str(tmp_path / "two.toml") if a == "TWO" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0], err
    assert "has 2 PTZs" in err[0] or "ptz-count" in err[0]
    assert not (tmp_path / "X").exists()
