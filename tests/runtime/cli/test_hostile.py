"""Hostile inputs, one test per class of hole that benchmarks/hostile_inputs.py found, so that each stays closed.

Mostly in-process ``main([...])`` calls with tmp paths (the checks come before any work, so they
are cheap); a few subprocesses where signals and child processes are the point.
"""

from __future__ import annotations

import codecs
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from omnijax import ConfigError
from runtime.cli import main
from runtime.errors import Interrupted, UsageError, interrupt_handlers
from runtime.files import read_json, read_toml
from runtime.output import check_output, staged_output
from tests.paths import CONFIGS, ROOT

PAPER = str(CONFIGS / "paper.toml")
OBSERVATIONS = str(CONFIGS / "observations_example.json")


def one_line(capsys, code: int, *names: str) -> str:
    """The one stderr line of a refused command (exit 2), which names each of ``names``."""
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith("omnijax ") and ": error: " in lines[0]
    for name in names:
        assert name in lines[0], lines[0]
    return lines[0]


def nothing_left(folder: Path, *keep: str) -> None:
    """No staging folder and nothing but ``keep`` in ``folder``."""
    assert sorted(p.name for p in folder.iterdir()) == sorted(keep)


# ------------------------------------------------------------------------------------------
# The output place is checked before any work
# ------------------------------------------------------------------------------------------

JOBS = {
    "demo": ["demo"],
    "run": ["run", "SRC", "--config", PAPER],
    "validate": ["validate", "--config", PAPER],
    "optimise": ["optimise", "--config", PAPER],
    "calibrate": ["calibrate", "--config", PAPER, "--observations", OBSERVATIONS],
    "detect": ["detect", "SRC", "--config", PAPER],
    "render": ["render", "--scenario", "one_person", "--frames", "2"],
}


@pytest.mark.parametrize("where", ["an existing file", "inside a file", "in a folder that cannot be written"])
@pytest.mark.parametrize("command", JOBS)
def test_out_is_checked_before_any_work(command, where, tmp_path, capsys):
    taken = tmp_path / "taken"
    taken.write_text("keep me\n")
    out = {"an existing file": taken, "inside a file": taken / "sub",
           "in a folder that cannot be written": Path("/proc/omnijax-test/out")}[where]
    t0 = time.monotonic()
    code = main([*JOBS[command], "--out", str(out)])
    line = one_line(capsys, code, "--out")
    assert ("is a file" in line) if where != "in a folder that cannot be written" else ("cannot write in" in line)
    assert time.monotonic() - t0 < 30  # refused up front, not after the job
    assert taken.read_text() == "keep me\n"
    nothing_left(tmp_path, "taken")


def test_check_output_accepts_new_and_existing_folders(tmp_path):
    assert check_output(tmp_path / "a" / "b") == tmp_path / "a" / "b"
    assert check_output(tmp_path) == tmp_path
    nothing_left(tmp_path)  # the probe leaves nothing


def test_staged_output_leaves_nothing_when_interrupted_or_failing(tmp_path):
    for exc in (Interrupted("SIGTERM"), RuntimeError("boom")):
        with pytest.raises(type(exc)) as info, staged_output(tmp_path / "out") as stage:
            (stage / "half.json").write_text("{")
            raise exc
        nothing_left(tmp_path)
    assert info.type is RuntimeError
    with pytest.raises(Interrupted) as info, staged_output(tmp_path / "out") as stage:
        raise Interrupted("SIGTERM")
    assert info.value.describe() == f"interrupted by SIGTERM; nothing written to {tmp_path / 'out'}"


# ------------------------------------------------------------------------------------------
# Files that are not UTF-8 TOML / JSON
# ------------------------------------------------------------------------------------------

BAD_BYTES = {
    "UTF-16": ("H_o = 2.7\n".encode("utf-16"), "UTF-16 text, expected a config file in UTF-8"),
    "Latin-1": ("# caf\xe9\nH_o = 2.7\n".encode("latin-1"), "not UTF-8 text (byte 0xe9 on line 1)"),
    "random bytes": (bytes(range(128, 256)) * 4, "not UTF-8 text (byte 0x80 on line 1)"),
}


@pytest.mark.parametrize("kind", BAD_BYTES)
def test_files_that_are_not_utf8_are_one_line(kind, tmp_path):
    data, expect = BAD_BYTES[kind]
    path = tmp_path / "rig.toml"
    path.write_bytes(data)
    with pytest.raises(ConfigError) as err:
        read_toml(path)
    assert str(err.value).startswith(f"{path}: ") and expect in str(err.value)
    with pytest.raises(UsageError, match="observations"):
        read_json(path, "observations file", UsageError)


def test_directories_devices_and_byte_order_marks(tmp_path):
    with pytest.raises(ConfigError, match="is a directory, expected a config file"):
        read_toml(tmp_path)
    with pytest.raises(ConfigError, match="/dev/zero: not a regular file"):  # read to the end, it never ends
        read_toml("/dev/zero")
    bom = tmp_path / "bom.toml"
    bom.write_bytes(codecs.BOM_UTF8 + b"a = 1\n")  # Windows editors write one: accepted
    assert read_toml(bom) == {"a": 1}


def test_every_reader_of_files_uses_it(tmp_path, capsys):
    """Rig, scenario (and the rig it names), device profile, observations: one line each, exit 2."""
    bad = tmp_path / "bad.toml"
    bad.write_bytes("x = 1\n".encode("utf-16"))
    scenario = tmp_path / "s.toml"
    scenario.write_text((CONFIGS / "scenarios" / "one_person.toml").read_text().replace(
        'rig = "../paper.toml"', 'rig = "bad.toml"'))
    for argv, name in (
        (["variance", "--config", str(bad), "--foot", "100", "0"], "bad.toml"),
        (["render", "--scenario", str(bad), "--frames", "2", "--out", str(tmp_path / "o")], "bad.toml"),
        (["render", "--scenario", str(scenario), "--frames", "2", "--out", str(tmp_path / "o")], "bad.toml"),
        (["ptz", "--ptz", "loop://", "--ptz-profile", str(bad)], "--ptz-profile"),
        (["calibrate", "--config", PAPER, "--observations", str(bad), "--out", str(tmp_path / "o")], "--observations"),
    ):
        assert "UTF-16" in one_line(capsys, main(argv), name)
    nothing_left(tmp_path, "bad.toml", "s.toml")


# ------------------------------------------------------------------------------------------
# Numbers on the command line
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("argv,expect", [
    (["validate", "--config", PAPER, "--grid-step-px", "0"], "--grid-step-px: expected a positive number of pixels"),
    (["validate", "--config", PAPER, "--grid-step-px", "0.5"], "--grid-step-px: expected 1 px (a point per pixel)"),
    (["validate", "--config", PAPER, "--grid-step-px", "nan"], "argument --grid-step-px: expected a finite number"),
    (["validate", "--config", PAPER, "--trials", "0"], "--trials: expected at least 8 frames, got 0"),
    (["validate", "--config", PAPER, "--rel-tol", "0"], "--rel-tol: expected a number in (0, 1)"),
    (["optimise", "--config", PAPER, "--grid-step-m", "inf"], "argument --grid-step-m: expected a finite number"),
    (["demo", "--dwell", "nan"], "argument --dwell: expected a finite number, got 'nan'"),
    (["demo", "--frames", "99999999"], "--frames: expected at most 1000000"),
    (["demo", "--seed", "-1"], "--seed: expected an integer >= 0"),
    (["run", "SRC", "--config", PAPER, "--fps", "inf"], "argument --fps: expected a finite number"),
    (["variance", "--config", PAPER, "--foot", "100", "nan"], "argument --foot: expected a finite number"),
    (["ptz", "--ptz", "loop://", "--pan-deg", "1e308", "--tilt-deg", "0", "--zoom", "1"],
     "--pan-deg: expected degrees in [-360, 360]"),
    (["ptz", "--ptz", "loop://", "--pan-deg", "0", "--tilt-deg", "100", "--zoom", "1"],
     "--tilt-deg: expected degrees in [-90, 90]"),
    (["ptz", "--ptz", "loop://", "--pan-deg", "0", "--tilt-deg", "0", "--zoom", "0"], "--zoom: expected a zoom"),
    (["ptz", "--ptz", "bogus://x"], "--ptz: bogus://x: not a usable serial port URL"),
    (["ptz", "--ptz", "socket://localhost"], "--ptz: socket://localhost: not a usable serial port URL"),
    (["ptz-emulator", "--protocol", "visca", "--parent-pid", "999999999"], "--parent-pid: no process 999999999"),
])
def test_number_flags_are_checked_never_replaced(argv, expect, tmp_path, capsys):
    if argv[0] in JOBS:
        argv = [*argv, "--out", str(tmp_path / "o")]
    assert expect in one_line(capsys, main(argv))
    nothing_left(tmp_path)


def test_ptz_reports_the_axes_it_clamped(capsys):
    from runtime.ptz import PtyEmulator
    from tests.runtime.ptz.helpers import quick_profile

    with PtyEmulator(quick_profile("visca")) as emu:
        code = main(["ptz", "--ptz", emu.path, "--pan-deg", "175", "--tilt-deg", "-10", "--zoom", "1e308",
                     "--wait", "30", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    target = json.loads(out)["target"]
    assert target["clamped"] == ["pan", "zoom"]  # the EVI-D70 pans to 170 deg; its lens stops at 18x


def test_state_file_and_link_are_checked_before_the_pty_opens(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    for argv, expect in ((["--state-file", str(tmp_path)], "is a folder, expected a file"),
                         (["--state-file", str(tmp_path / "no" / "f")], "no such folder"),
                         (["--link", str(tmp_path / "file")], "exists and is not a symlink")):
        assert expect in one_line(capsys, main(["ptz-emulator", "--protocol", "visca", *argv]), argv[0])
    nothing_left(tmp_path, "file")


# ------------------------------------------------------------------------------------------
# Other programs' warnings, and what the demo says it wrote
# ------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_opencv_says_nothing_before_the_one_line(tmp_path):
    """OpenCV's own warnings (a camera index that is not there, a file that is not a video) are silenced."""
    junk = tmp_path / "junk.avi"
    junk.write_bytes(bytes(range(256)) * 8)
    for argv in (["run", "99", "--config", PAPER, "--out", "o"], ["detect", str(junk), "--config", PAPER,
                                                                   "--out", "o"]):
        env = {k: v for k, v in os.environ.items() if not k.startswith(("OPENCV_LOG", "OPENCV_FFMPEG"))}
        proc = subprocess.run([sys.executable, "-m", "runtime.cli", *argv], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
        assert proc.stderr.startswith(f"omnijax {argv[0]}: error: ")


def test_demo_lists_only_what_it_wrote(capsys):
    from runtime.cli.demo import _report

    rule = {"rate": 1.0, "trials": 3, "rate_feasible": 1.0, "feasible_trials": 3, "rate_person_frames": 1.0}
    summary = {"containment": {"p_contain": 0.99, "rules": {"calibrated": rule}, "person_frames": 3,
                               "no_person_share": 0.0, "held": {"untrusted": 0, "unframeable": 0, "no_track": 0}},
               "face_coverage": {"people": [{"rules": {"calibrated": 1.0}}]},
               "face_px": {"rules": {"calibrated": {"median": 100.0}}}, "detection": {"miss_rate": 0.0,
               "false_alarm_rate": 0.0}, "latency_ms": {"p50": 1.0, "p99": 2.0}, "frames": 3, "fps": 25.0,
               "stop_reason": "source ended", "foot_error_m": {"rms": 0.1},
               "ptz": {"commands": 1, "errors": 0, "reconnects": 0},
               "faults": {"broken_frames": 0, "wrong_size_frames": 0}, "outputs": {"log": "log.jsonl"}}
    _report(summary, "o")
    assert capsys.readouterr().out.splitlines()[-1] == "demo outputs: o/ (summary.json, log.jsonl)"
    summary["outputs"].update(video="annotated.mp4", view="view.png")
    _report(summary, "o")
    listed = "demo outputs: o/ (summary.json, log.jsonl, annotated.mp4, view.png)"
    assert capsys.readouterr().out.splitlines()[-1] == listed
    # the loop's pointing: the person it frames worst is named, with their height
    people = [{"person": 0, "H_p_m": 1.743, "frames": 227, "nees_mean": 0.585, "pan_nees_mean": 1.03,
               "tilt_nees_mean": 0.156},
              {"person": 1, "H_p_m": 1.886, "frames": 272, "nees_mean": 4.577, "pan_nees_mean": 1.79,
               "tilt_nees_mean": 7.608},
              {"person": 2, "H_p_m": 1.7, "frames": 0, "nees_mean": None, "pan_nees_mean": None,
               "tilt_nees_mean": None}]
    summary["pointing"] = {"frames": 499, "nees_mean": 2.78, "nees_over_5_99": 0.2, "people": people,
                           "curve": [{"rule": "calibrated", "p_contain": 0.99, "rate": 0.8, "trials": 499}]}
    _report(summary, "o")
    assert ("  pointing per person: the worst person 1 (1.89 m tall), NEES 4.577 (tilt 7.608) on 272 frames; each "
            "person in summary.json pointing.people") in capsys.readouterr().out.splitlines()


# ------------------------------------------------------------------------------------------
# Ctrl-C and SIGTERM from the first moment; children never outlive the command
# ------------------------------------------------------------------------------------------

def test_interrupt_handlers_raise_and_are_put_back():
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Interrupted) as info, interrupt_handlers():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    assert info.value.signame == "SIGTERM" and signal.getsignal(signal.SIGTERM) is before


def test_a_signal_inside_a_garbage_collector_callback_still_interrupts():
    """SIGTERM arriving while a gc callback runs (JAX registers one): raised there it would be printed and
    dropped and the command would run on (a render ran to its end and wrote its outputs); it comes
    again a moment later and interrupts."""
    import gc

    def callback(phase, info):
        if phase == "start" and not sent:
            sent.append(True)
            os.kill(os.getpid(), signal.SIGTERM)
            sum(range(1000))  # the handler runs here, inside the callback

    sent: list[bool] = []
    gc.callbacks.append(callback)
    try:
        with pytest.raises(Interrupted) as info, interrupt_handlers():
            gc.collect()
            time.sleep(5)
    finally:
        gc.callbacks.remove(callback)
    assert sent and info.value.signame == "SIGTERM"


def test_a_signal_handled_inside_a_weakref_callback_of_the_collector_still_interrupts():
    """The collector also runs weakref callbacks (a WeakKeyDictionary's removal, of garbage that other
    code left in a cycle); a signal whose handler runs there would be printed and dropped as well. Seen
    once in the suite: the SIGTERM sent in a gc callback was handled in such a weakref callback later in
    the same collection."""
    import gc
    import weakref

    class Node:
        pass

    def removed(_ref):
        if not sent:
            sent.append(True)
            os.kill(os.getpid(), signal.SIGTERM)
        sum([k for k in range(100)])  # Python code: the handler runs here, inside the weakref callback

    sent: list[bool] = []
    gc.collect()
    node = Node()
    node.self = node  # a cycle: only the collector frees it, and runs the callback while it does
    ref = weakref.ref(node, removed)
    del node
    with pytest.raises(Interrupted) as info, interrupt_handlers():
        gc.collect()
        time.sleep(5)
    assert sent and info.value.signame == "SIGTERM" and ref() is None


def test_demo_interrupted_during_start_up_says_so_and_writes_nothing(tmp_path, monkeypatch, capsys):
    import omnijax.world

    def interrupted(*_, **__):
        raise Interrupted("SIGTERM")

    monkeypatch.setattr(omnijax.world, "build_world", interrupted)
    code = main(["demo", "--out", str(tmp_path / "o"), "--frames", "260"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 130
    assert err[-1] == f"omnijax demo: interrupted by SIGTERM during start-up; nothing written to {tmp_path / 'o'}"
    nothing_left(tmp_path)


def test_the_emulator_child_stops_however_its_block_ends():
    from runtime.ptz.child import EmulatorProcess

    with pytest.raises(Interrupted), EmulatorProcess("visca") as emu:
        proc = emu.proc
        assert proc.poll() is None and emu.link.is_symlink()
        raise Interrupted("SIGTERM")
    assert proc.poll() is not None and emu.proc is None and not emu.folder.exists()


def _children_marked(mark: str) -> list[int]:
    pids = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if f"OMNIJAX_TEST_MARK={mark}".encode() in (p / "environ").read_bytes().split(b"\0"):
                    pids.append(int(p.name))
            except OSError:
                pass
    return pids


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc to find the children")
def test_the_emulator_child_goes_when_its_parent_is_killed(tmp_path):
    """SIGKILL leaves no chance to clean up: the emulator child notices and stops by itself."""
    mark = f"{os.getpid()}-{time.monotonic_ns()}"
    script = ("import sys, time\n"
              "from pathlib import Path\n"
              "from runtime.ptz.child import EmulatorProcess\n"
              "emu = EmulatorProcess('visca', folder=Path(sys.argv[1])).start()\n"  # killed: nothing cleans up /tmp
              "print(emu.proc.pid, flush=True)\n"
              "time.sleep(600)\n")
    parent = subprocess.Popen([sys.executable, "-c", script, str(tmp_path)], cwd=ROOT, stdout=subprocess.PIPE,
                              text=True, env={**os.environ, "OMNIJAX_TEST_MARK": mark})
    try:
        emulator = int(parent.stdout.readline())
        assert emulator in _children_marked(mark)
        parent.kill()
        parent.wait()
        deadline = time.monotonic() + 10
        while _children_marked(mark) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _children_marked(mark) == []
    finally:
        for pid in _children_marked(mark):
            os.kill(pid, signal.SIGKILL)


def test_sigterm_while_working_ends_with_130_and_nothing_written(tmp_path):
    """A real process: the handlers are installed first thing, and the process ends cleanly (no SIGSEGV while
    JAX's threads run, see runtime.cli.console). Staging folders removed on interruption: tested above."""
    proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", "render", "--scenario", "one_person", "--frames",
                             "2000", "--out", "o"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    time.sleep(3)  # importing, reading the scenario, building the world: the handlers are in place from the start
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    lines = [s for s in err.splitlines() if s.strip() and "%|" not in s]  # progress bars aside
    assert proc.returncode == 130, err
    assert lines == ["omnijax render: interrupted by SIGTERM; nothing written to o"], err
    nothing_left(tmp_path)


# ------------------------------------------------------------------------------------------
# Holes the harness still found after the first round (run on d86107d)
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("flag,value", [("--grid-step-m", "0"), ("--starts", "0"), ("--landscape", "100000"),
                                        ("--vary", "D_c D_c")])
def test_optimise_override_is_named_by_its_flag(capsys, tmp_path, flag, value):
    code = main(["optimise", "--config", PAPER, "--out", str(tmp_path / "o"), flag, *value.split()])
    one_line(capsys, code, flag)
    nothing_left(tmp_path)


def test_variance_foot_beyond_the_rim_is_refused(capsys):
    code = main(["variance", "--config", PAPER, "--foot", "1e300", "0"])
    one_line(capsys, code, "--foot", "omni.rim")
    code = main(["variance", "--config", PAPER, "--foot", "100", "0", "--sigma-rf", "1e300"])
    one_line(capsys, code, "--sigma-rf", "omni.rim")


def test_cache_dir_that_cannot_be_made_is_refused_before_work(capsys, tmp_path):
    code = main(["optimise", "--config", PAPER, "--out", str(tmp_path / "o"), "--cache-dir", "/dev/null/x"])
    one_line(capsys, code, "--cache-dir", "/dev/null/x")
    nothing_left(tmp_path)
