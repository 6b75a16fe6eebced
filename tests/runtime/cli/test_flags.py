"""Flags: every help, one spelling per idea, old spellings as hidden aliases, the loop settings from LoopConfig."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from runtime.cli import build_parser, main
from runtime.cli._main import COMMANDS
from runtime.realtime.config import LoopConfig
from runtime.settings import flag_of
from tests.paths import CONFIGS

PAPER = str(CONFIGS / "paper.toml")

#: (command and its required arguments, old spelling, new spelling, value, the option's dest) for every rename.
RENAMED = [
    (["run", "SRC", "--config", "C", "--out", "O"], "--profile", "--ptz-profile", "pelco_d_dome", "ptz_profile"),
    (["run", "SRC", "--config", "C", "--out", "O"], "--dead-zone", "--dead-zone-sd", "2.5", "dead_zone_sd"),
    (["demo", "--out", "O"], "--dead-zone", "--dead-zone-sd", "2.5", "dead_zone_sd"),
    (["ptz"], "--port", "--ptz", "/dev/ttyUSB0", "ptz"),
    (["ptz"], "--profile", "--ptz-profile", "pelco_d_dome", "ptz_profile"),
    (["ptz-emulator", "--protocol", "visca"], "--profile", "--ptz-profile", "sony_evi_d70", "ptz_profile"),
    (["validate", "--config", "C", "--out", "O"], "--grid-step", "--grid-step-px", "24", "grid_step_px"),
    (["optimise", "--config", "C", "--out", "O"], "--grid-step", "--grid-step-m", "0.5", "grid_step_m"),
    (["optimise", "--config", "C", "--out", "O"], "--face-target", "--face-target-px", "60", "face_target_px"),
    (["detect", "SRC", "--out", "O"], "--limit", "--frames", "100", "frames"),
    (["calibrate", "--config", "C", "--out", "O"], "--sigma-height", "--sigma-height-m", "0.01", "sigma_height_m"),
]


@pytest.mark.parametrize("command", COMMANDS)
def test_every_help_prints_and_hides_the_old_spellings(command, capsys):
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args([command, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for *_, old, new, _value, _dest in RENAMED:
        assert f"{old} " not in out.replace(new, "")


@pytest.mark.parametrize("argv,old,new,value,dest", RENAMED, ids=[f"{r[0][0]}{r[1]}" for r in RENAMED])
def test_old_spellings_still_work_with_one_line_on_stderr(argv, old, new, value, dest, capsys):
    parser = build_parser()
    by_new = parser.parse_args([*argv, new, value])
    assert capsys.readouterr().err == ""
    by_old = parser.parse_args([*argv, old, value])
    err = capsys.readouterr().err
    assert getattr(by_old, dest) == getattr(by_new, dest)
    assert err.count("\n") == 1 and f"{old} is deprecated, use {new}" in err


def test_sigma_theta_keeps_its_radians(capsys):
    """The original contract names ``--sigma-theta`` (radians) for ``variance``: it still works, in radians."""
    code = main(["variance", "--config", PAPER, "--json", "--foot", "100", "0.7", "--sigma-theta", "0.01"])
    out, err = capsys.readouterr()
    assert code == 0 and json.loads(out)["inputs"]["theta_f"]["sigma"] == 0.01
    assert err.count("\n") == 1 and "--sigma-theta is deprecated, use --sigma-theta-deg" in err and "radians" in err
    code = main(["variance", "--config", PAPER, "--json", "--foot", "100", "0.7", "--sigma-theta-deg",
                 str(math.degrees(0.01))])
    out, err = capsys.readouterr()
    assert code == 0 and err == "" and json.loads(out)["inputs"]["theta_f"]["sigma"] == pytest.approx(0.01)
    assert main(["variance", "--config", PAPER, "--foot", "100", "0.7", "--sigma-theta", "0.01",
                 "--sigma-theta-deg", "0.5"]) == 2


def test_loop_settings_are_the_flags_of_run_and_demo():
    fields = [f for f in dataclasses.fields(LoopConfig) if "option" in f.metadata]
    assert {f.name for f in fields} >= {"zoom_rule", "tracker", "target", "dwell_s", "dead_zone_sd", "max_frames",
                                        "max_seconds", "quiet"}
    parser = build_parser()
    for argv in (["run", "SRC", "--config", "C", "--out", "O"], ["demo", "--out", "O"]):
        args = parser.parse_args(argv)
        assert all(getattr(args, f.name) == f.default for f in fields)  # the defaults are LoopConfig's
        args = parser.parse_args([*argv, "--zoom-rule", "paper", "--dwell", "0.5", "--max-frames", "7", "--quiet"])
        assert (args.zoom_rule, args.dwell_s, args.max_frames, args.quiet) == ("paper", 0.5, 7, True)
    assert [flag_of(f) for f in fields if f.name in ("dwell_s", "dead_zone_sd")] == ["--dwell", "--dead-zone-sd"]


@pytest.mark.parametrize("flag,value,expect", [
    ("--dwell", "-1", "--dwell: expected seconds >= 0, got -1.0"),
    ("--dead-zone-sd", "-0.5", "--dead-zone-sd: expected a number of standard deviations >= 0, got -0.5"),
    ("--max-seconds", "0", "--max-seconds: expected seconds > 0, got 0.0"),
    ("--max-frames", "0", "--max-frames: expected frames > 0, got 0"),
])
def test_loop_setting_out_of_bounds_is_one_line_naming_the_flag(flag, value, expect, tmp_path, capsys):
    assert main(["run", str(tmp_path), "--config", PAPER, "--out", str(tmp_path / "o"), flag, value]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and expect in err
    assert not (tmp_path / "o").exists()


def test_loop_config_in_code_is_checked_by_the_same_metadata():
    with pytest.raises(ValueError, match="dwell_s: expected seconds >= 0"):
        LoopConfig(dwell_s=-1.0)
    with pytest.raises(ValueError, match="zoom_rule: expected one of paper, calibrated"):
        LoopConfig(zoom_rule="widest")
    assert LoopConfig(max_frames=None, tracker="nearest").tracker == "nearest"


def test_a_reader_that_goes_away_ends_the_command_quietly():
    """``omnijax variance ... --json | head -1``: stdout's reader is gone before anything is written; the
    command ends with 141 (128 + SIGPIPE, as the shell reports it) and nothing on stderr."""
    import subprocess
    import sys

    from tests.paths import ROOT

    argv = ["variance", "--config", PAPER, "--foot", "100", "0.7", "--method", "analytic", "--json"]
    proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", *argv], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # the reader went away
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 141 and stderr == "", stderr[-2000:]
