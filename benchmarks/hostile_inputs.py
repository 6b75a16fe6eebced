"""Hostile inputs: a few hundred bad inputs tried against every command, as a user would, and classified.

Each case runs ``python -m runtime.cli COMMAND ...`` in a subprocess, in a fresh
temporary folder (its files written there first), with a time limit; emulators
the harness starts listen on a pseudo-terminal and are killed afterwards. An
outcome is

- ``clean``: the expected exit code (2 for bad input; 130 for a signal during
  start-up; 0 where a case says so), the last line on stderr
  ``omnijax COMMAND: error: ...`` (or ``... interrupted ...``) naming what the case
  expects it to name, no other line before it but argparse's usage and omnijax's
  own status lines, nothing half-written (no ``.NAME.partial-PID`` folder, the
  ``--out`` place as it was before) and no child process left running;
- ``traceback``: a Python traceback on stderr;
- ``wrong exit 0``: the command accepted the input;
- ``other``: anything else (a hang past the time limit, exit 1 or a signal, output
  left behind, a child left running, foreign lines such as OpenCV/FFmpeg warnings
  before the error, an error line that does not name what was wrong).

Run (from the checkout, with its venv)::

    .venv/bin/python benchmarks/hostile_inputs.py [--jobs 2] [--only SUBSTRING ...] [--json FILE]
    .venv/bin/python benchmarks/hostile_inputs.py --repo /path/to/other/checkout   # e.g. an older commit

It prints one table (tried / clean / traceback / wrong exit 0 / other, per command
and in total) and every case that was not clean, with the reason.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomlkit

HERE = Path(__file__).resolve().parent.parent
COMMANDS = ("demo", "run", "variance", "validate", "optimise", "calibrate", "detect", "bench", "render", "ptz",
            "ptz-emulator")
MARK = "OMNIJAX_HOSTILE_CASE"


@dataclass
class Case:
    """One bad input: ``argv`` after ``omnijax`` (placeholders ``{fx}`` fixtures, ``{repo}``, ``{pty}``)."""

    command: str
    name: str
    argv: list[str]
    files: dict[str, str | bytes] = field(default_factory=dict)
    expect: str | None = None  # what the error line must name
    exit: int = 2
    timeout: float = 150.0
    setup: Callable[[Path], None] | None = None
    signal: tuple[int, str, float, bool] | None = None  # (signal, stderr text to wait for, then seconds, to the
    #                                                        whole process group as a terminal's Ctrl-C is)
    unprivileged: bool = False  # without root's permission to write anywhere (CAP_DAC_OVERRIDE)
    emulator: bool = False  # start a ptz-emulator and put its pty in {pty}
    check: Callable[[Path, str, str], str | None] | None = None  # for exit-0 cases: what is wrong, or None


# --------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------

DELETE = object()


def rig_text(repo: Path, changes: dict | None = None, base: str = "paper.toml") -> str:
    """A rig file: ``configs/BASE`` with ``{"section.key": value}`` changed (DELETE removes the key)."""
    doc = tomlkit.parse((repo / "configs" / base).read_text())
    for dotted, value in (changes or {}).items():
        *path, key = dotted.split(".")
        table = doc
        for p in path:
            table = table[p]
        if value is DELETE:
            del table[key]
        else:
            table[key] = value
    return tomlkit.dumps(doc)


def scenario_text(repo: Path, rig: str, name: str = "one_person") -> str:
    text = (repo / "configs" / "scenarios" / f"{name}.toml").read_text()
    return re.sub(r'^rig = "[^"]*"', f'rig = "{rig}"', text, count=1, flags=re.M)


UTF16 = "utf-16"
RANDOM = bytes(np.random.default_rng(7).integers(0, 256, 600, dtype=np.uint8))


def encodings(text: str) -> dict[str, bytes]:
    """The same file as UTF-16 (with BOM), Latin-1 with a non-ASCII byte, and random bytes."""
    return {"utf16": text.encode(UTF16), "latin1": ("# caf\xe9\n" + text).encode("latin-1"), "random": RANDOM}


def make_fixtures(folder: Path) -> None:
    """Frames and videos the source cases read (noise around grey, so nothing is detected)."""
    import cv2

    rng = np.random.default_rng(0)

    def frames(name: str, n: int, size=(640, 480), odd: int | None = None):
        d = folder / name
        d.mkdir()
        for k in range(n):
            w, h = (320, 240) if k == odd else size
            img = np.clip(128 + rng.normal(0, 2, (h, w, 3)), 0, 255).astype(np.uint8)
            cv2.imwrite(str(d / f"{k:04d}.png"), img)

    frames("frames", 40)
    frames("small", 40, (320, 240))
    frames("mixed", 40, odd=35)
    (folder / "empty").mkdir()
    (folder / "junk").mkdir()
    for k in range(40):
        (folder / "junk" / f"{k:04d}.png").write_bytes(RANDOM)
    w = cv2.VideoWriter(str(folder / "video.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 25, (640, 480))
    for _ in range(40):
        w.write(np.clip(128 + rng.normal(0, 2, (480, 640, 3)), 0, 255).astype(np.uint8))
    w.release()
    (folder / "garbage.mp4").write_bytes(RANDOM * 50)
    (folder / "empty.mp4").write_bytes(b"")
    (folder / "text.avi").write_text("not a video\n")
    cv2.imwrite(str(folder / "frame.png"), np.full((480, 640, 3), 90, np.uint8))
    cv2.imwrite(str(folder / "frame_small.png"), np.full((240, 320, 3), 90, np.uint8))


# --------------------------------------------------------------------------------------
# The cases
# --------------------------------------------------------------------------------------


def cases(repo: Path) -> list[Case]:
    paper = rig_text(repo)
    rig_file = str(repo / "configs" / "paper.toml")
    obs_file = str(repo / "configs" / "observations_example.json")
    out: list[Case] = []

    def add(command, name, argv, **kw):
        out.append(Case(command, name, argv, **kw))

    # Small jobs, so that a bad input that slips through is seen as a wrong exit 0, not a hang.
    jobs = {
        "demo": ["demo", "--frames", "260", "--pace", "all", "--no-video", "--max-frames", "5"],
        "run": ["run", "{fx}/frames", "--config", rig_file, "--no-video", "--no-cache"],
        "validate": ["validate", "--config", rig_file, "--quick", "--trials", "8", "--fresh-trials", "8",
                     "--empty-frames", "8"],
        "optimise": ["optimise", "--config", rig_file, "--no-maps", "--landscape", "3", "--starts", "1",
                     "--grid-step-m", "0.5", "--no-cache"],
        "calibrate": ["calibrate", "--config", rig_file, "--observations", obs_file],
        "detect": ["detect", "{fx}/frames", "--config", rig_file, "--frames", "35"],
        "render": ["render", "--scenario", "one_person", "--frames", "2"],
    }

    # ---- --out: an existing file, a path through a file, a folder that cannot be written
    for cmd, argv in jobs.items():
        add(cmd, "--out is an existing file", [*argv, "--out", "taken"], files={"taken": "keep me\n"},
            expect="--out")
        add(cmd, "--out inside a file", [*argv, "--out", "taken/sub"], files={"taken": "keep me\n"},
            expect="--out")
        add(cmd, "--out in /sys (EPERM)", [*argv, "--out", "/sys/omnijax-hostile/out"], expect="--out")
    add("calibrate", "--simulate, --out is an existing file",
        ["calibrate", "--config", rig_file, "--simulate", "2", "--positions", "4", "--out", "taken"],
        files={"taken": "x"}, expect="--out")
    for cmd in ("validate", "optimise", "render", "detect", "calibrate"):
        add(cmd, "--out in a read-only folder", [*jobs[cmd], "--out", "ro/out"],
            setup=lambda d: (d / "ro").mkdir(mode=0o555), unprivileged=True, expect="--out")
    add("render", "--out is /dev/null", [*jobs["render"], "--out", "/dev/null"], expect="--out")

    # ---- files that are not UTF-8 TOML: rigs, scenarios, profiles
    for kind, data in encodings(paper).items():
        for cmd, argv in (("variance", ["variance", "--config", "rig.toml", "--foot", "100", "0.5"]),
                          ("validate", ["validate", "--config", "rig.toml", "--quick", "--out", "o"]),
                          ("optimise", ["optimise", "--config", "rig.toml", "--out", "o"]),
                          ("calibrate", ["calibrate", "--config", "rig.toml", "--observations", obs_file,
                                         "--out", "o"]),
                          ("run", ["run", "{fx}/frames", "--config", "rig.toml", "--out", "o"]),
                          ("detect", ["detect", "{fx}/frames", "--config", "rig.toml", "--out", "o"])):
            add(cmd, f"rig file {kind}", argv, files={"rig.toml": data}, expect="rig.toml")
    scenario = scenario_text(repo, rig_file)
    for kind, data in encodings(scenario).items():
        for cmd, argv in (("demo", ["demo", "--scenario", "s.toml", "--out", "o"]),
                          ("render", ["render", "--scenario", "s.toml", "--frames", "2", "--out", "o"]),
                          ("validate", ["validate", "--config", rig_file, "--scenario", "s.toml", "--quick",
                                        "--out", "o"]),
                          ("bench", ["bench", "--scenario", "s.toml", "--sizes", "640x480"])):
            add(cmd, f"scenario file {kind}", argv, files={"s.toml": data}, expect="s.toml")
        add("demo", f"scenario's rig {kind}", ["demo", "--scenario", "s.toml", "--out", "o"],
            files={"s.toml": scenario_text(repo, "rig.toml"), "rig.toml": encodings(paper)[kind]},
            expect="rig.toml")
    profile = (repo / "configs" / "devices" / "sony_evi_d70.toml").read_text()
    for kind, data in encodings(profile).items():
        add("ptz", f"profile {kind}", ["ptz", "--ptz", "loop://", "--ptz-profile", "p.toml"], files={"p.toml": data},
            expect="p.toml")
        add("ptz-emulator", f"profile {kind}", ["ptz-emulator", "--protocol", "visca", "--ptz-profile", "p.toml"],
            files={"p.toml": data}, expect="p.toml")
        add("run", f"profile {kind}", ["run", "{fx}/frames", "--config", rig_file, "--ptz-profile", "p.toml",
                                       "--out", "o"], files={"p.toml": data}, expect="p.toml")
        add("calibrate", f"profile {kind}", ["calibrate", "--config", rig_file, "--observations", obs_file,
                                             "--ptz-profile", "p.toml", "--out", "o"],
            files={"p.toml": data}, expect="p.toml")

    # ---- missing files, directories, empty files where files are expected
    for what, spec, files, setup in (("missing", "nope.toml", {}, None),
                                     ("a directory", "d.toml", {}, lambda d: (d / "d.toml").mkdir()),
                                     ("empty", "e.toml", {"e.toml": ""}, None),
                                     ("/dev/null", "/dev/null", {}, None)):
        add("variance", f"rig file {what}", ["variance", "--config", spec, "--foot", "100", "0"], files=files,
            setup=setup, expect=Path(spec).name)
        add("optimise", f"rig file {what}", ["optimise", "--config", spec, "--out", "o"], files=files, setup=setup,
            expect=Path(spec).name)
        add("render", f"scenario {what}", ["render", "--scenario", spec, "--frames", "2", "--out", "o"],
            files=files, setup=setup, expect=Path(spec).name)
        add("ptz", f"profile {what}", ["ptz", "--ptz", "loop://", "--ptz-profile", spec], files=files, setup=setup,
            expect=Path(spec).name)

    # ---- inf, nan and 1e300 in every numeric rig key
    numeric = ["omni.H_o", "omni.sigma_H_o", "omni.r_m", "omni.sigma_r_m", "foveal.D_c", "foveal.sigma_D_c",
               "foveal.theta_c_deg", "foveal.sigma_theta_c_deg", "foveal.H_f", "foveal.sigma_H_f",
               "person.H_p", "person.sigma_H_p", "person.R_h", "person.sigma_R_h", "person.shoulder_width",
               "detection.sensor_sigma", "detection.x_f", "detection.x_m", "detection.sigma_r_f",
               "detection.sigma_theta_f_deg", "zoom.p_contain", "layout.grid_step", "layout.near_radius",
               "layout.face_target_px"]
    optional = ["omni.rim", "detection.c_min", "detection.min_floor_radius", "detection.r_max",
                "detection.adapt_rate"]
    for key in numeric + optional:
        for value in (float("inf"), float("nan")):
            add("variance", f"{key} = {value}", ["variance", "--config", "rig.toml", "--foot", "100", "0.5",
                                                 "--json"], files={"rig.toml": rig_text(repo, {key: value})},
                expect=key.split(".")[-1])
    for key in ("omni.H_o", "omni.sigma_H_o", "omni.r_m", "omni.sigma_r_m", "foveal.D_c", "foveal.sigma_D_c",
                "foveal.theta_c_deg", "foveal.sigma_theta_c_deg", "foveal.H_f", "foveal.sigma_H_f",
                "person.sigma_H_p", "person.sigma_R_h", "person.shoulder_width", "detection.sensor_sigma",
                "detection.sigma_r_f", "detection.sigma_theta_f_deg", "omni.rim", "detection.min_floor_radius",
                "detection.r_max", "detection.c_min"):
        add("variance", f"{key} = 1e300", ["variance", "--config", "rig.toml", "--foot", "100", "0.5", "--json"],
            files={"rig.toml": rig_text(repo, {key: 1e300})}, expect=key.split(".")[-1])
    for pair in ("omni.center", "foveal.pan_limits_deg", "foveal.tilt_limits_deg", "foveal.zoom_range",
                 "foveal.lens.zoom", "foveal.lens.fov_h_deg", "layout.D_c", "layout.H_f"):
        base = tomlkit.parse(paper)
        node = base
        for p in pair.split("."):
            node = node[p]
        values = [float(v) for v in node]
        for bad in (float("nan"), float("inf")):
            changed = [bad, *values[1:]]
            add("variance", f"{pair}[0] = {bad}", ["variance", "--config", "rig.toml", "--foot", "100", "0.5"],
                files={"rig.toml": rig_text(repo, {pair: changed})}, expect=pair.split(".")[-1])
    outline = [[-4.5, -3.0], [3.3, -3.0], [3.3, 3.0], [float("inf"), 3.0]]
    add("variance", "room.outline with inf", ["variance", "--config", "rig.toml", "--foot", "100", "0.5"],
        files={"rig.toml": rig_text(repo, {"room.outline": outline})}, expect="outline")
    # the same holes through the commands that do more than variance
    for key, value in (("omni.H_o", float("inf")), ("foveal.D_c", 1e300), ("foveal.sigma_D_c", float("inf")),
                       ("foveal.theta_c_deg", float("nan"))):
        for cmd in ("validate", "optimise", "run", "detect", "calibrate"):
            add(cmd, f"{key} = {value}", [*jobs[cmd], "--out", "o"],
                files={"rig.toml": rig_text(repo, {key: value})}, expect=key.split(".")[-1])
            out[-1].argv = [a if a != rig_file else "rig.toml" for a in out[-1].argv]

    # ---- impossible but finite rigs
    impossible = {
        "r_m far larger than the image": {"omni.r_m": 1e6},
        "r_m = 2 px": {"omni.r_m": 2.0},
        "centre at 1e9 px": {"omni.center": [1e9, 240.0]},
        "centre outside the image": {"omni.center": [-50.0, 240.0]},
        "a 1e10 px image": {"omni.image_size": [10_000_000_000, 480]},
        "a 1x1 image": {"omni.image_size": [1, 1]},
        "the PTZ above the omni camera": {"foveal.H_f": 3.5},
        "the PTZ 1 km away": {"foveal.D_c": 1000.0},
        "H_o 1 km": {"omni.H_o": 1000.0},
        "rim 1e6 px": {"omni.rim": 1e6},
        "pan limits beyond a turn": {"foveal.pan_limits_deg": [-1000.0, 1000.0]},
        "tilt limits past straight up": {"foveal.tilt_limits_deg": [-200.0, 200.0]},
        "theta_c_deg 1e6": {"foveal.theta_c_deg": 1e6},
        "sigma_theta_c_deg 1000": {"foveal.sigma_theta_c_deg": 1000.0},
        "sensor_sigma 1e6 grey levels": {"detection.sensor_sigma": 1e6},
        "min_floor_radius beyond the room": {"detection.min_floor_radius": 100.0},
        "r_max 1 px": {"detection.r_max": 1.0},
        "a room of zero area": {"room.outline": [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]},
        "a room 1e6 m wide": {"room.outline": [[-1e6, -1e6], [1e6, -1e6], [1e6, 1e6], [-1e6, 1e6]]},
        "shoulders wider than the person is tall": {"person.shoulder_width": 5.0},
        "foveal image 1e10 px": {"foveal.image_size": [10_000_000_000, 480]},
        "zoom 1e300": {"foveal.lens.zoom": [1.0, 2.0, 4.0, 8.0, 12.0, 1e300], "foveal.zoom_range": [1.0, 1e300]},
        "face_target_px wider than the PTZ image": {"layout.face_target_px": 1e6},
        "layout H_f bounds above the omni camera": {"layout.H_f": [1.15, 30.0]},
        "layout D_c bounds 1e300": {"layout.D_c": [0.25, 1e300]},
    }
    for name, change in impossible.items():
        add("variance", name, ["variance", "--config", "rig.toml", "--foot", "100", "0.5", "--json"],
            files={"rig.toml": rig_text(repo, change)}, expect=next(iter(change)).split(".")[-1])
    for name in ("r_m far larger than the image", "centre at 1e9 px", "the PTZ above the omni camera",
                 "a 1e10 px image"):
        for cmd in ("validate", "detect"):
            add(cmd, name, [*[a if a != rig_file else "rig.toml" for a in jobs[cmd]], "--out", "o"],
                files={"rig.toml": rig_text(repo, impossible[name])},
                expect=next(iter(impossible[name])).split(".")[-1])

    # ---- wrong types, missing and unknown keys
    wrong = {
        "H_o a string": ({"omni.H_o": "2.7"}, "H_o"),
        "H_o a bool": ({"omni.H_o": True}, "H_o"),
        "image_size of floats": ({"omni.image_size": [640.5, 480.0]}, "image_size"),
        "model unknown": ({"omni.model": "fish"}, "model"),
        "model a number": ({"omni.model": 3}, "model"),
        "omni a number": ({"omni": 5}, "omni"),
        "outline a number": ({"room.outline": 3}, "outline"),
        "rule unknown": ({"zoom.rule": "best"}, "rule"),
        "p_contain 1": ({"zoom.p_contain": 1.0}, "p_contain"),
        "x_f 0": ({"detection.x_f": 0.0}, "x_f"),
        "negative sigma_H_o": ({"omni.sigma_H_o": -1.0}, "sigma_H_o"),
        "negative D_c": ({"foveal.D_c": -1.0}, "D_c"),
        "n_theta 10": ({"detection.n_theta": 10}, "n_theta"),
        "background_frames 2": ({"detection.background_frames": 2}, "background_frames"),
        "max_people -1": ({"detection.max_people": -1}, "max_people"),
        "zoom_range reversed": ({"foveal.zoom_range": [18.0, 1.0]}, "zoom_range"),
        "lens zoom not increasing": ({"foveal.lens.zoom": [1.0, 2.0, 2.0, 8.0, 12.0, 18.0]}, "zoom"),
        "unknown key": ({"omni.height": 2.7}, "height"),
        "unknown section": ({"extra": {"a": 1}}, "extra"),
        "missing H_o": ({"omni.H_o": DELETE}, "H_o"),
        "missing sigma_r_m (the comments call it required)": ({"omni.sigma_r_m": DELETE}, "sigma_r_m"),
        "missing [room]": ({"room": DELETE}, "room"),
        "calib_file with a paraboloid": ({"omni.calib_file": "x.txt"}, "calib_file"),
        "layout vary unknown": ({"layout.vary": ["D_c", "height"]}, "vary"),
        "layout grid_step 0": ({"layout.grid_step": 0.0}, "grid_step"),
    }
    for name, (change, expect) in wrong.items():
        add("variance", name, ["variance", "--config", "rig.toml", "--foot", "100", "0.5"],
            files={"rig.toml": rig_text(repo, change)}, expect=expect)
    add("variance", "TOML syntax error", ["variance", "--config", "rig.toml", "--foot", "100", "0.5"],
        files={"rig.toml": paper.replace("H_o = ", "H_o == ", 1)}, expect="rig.toml")
    add("variance", "TOML with a NUL byte", ["variance", "--config", "rig.toml", "--foot", "100", "0.5"],
        files={"rig.toml": paper.encode() + b"\x00\n"}, expect="rig.toml")

    # ---- files a config names
    fisheye = rig_text(repo, {"omni.model": "ocamcalib", "omni.calib_file": "calib.txt", "omni.image_size": DELETE,
                              "omni.center": DELETE, "omni.r_m": DELETE})
    for what, files, setup in (("missing", {}, None), ("a directory", {}, lambda d: (d / "calib.txt").mkdir()),
                               ("garbage", {"calib.txt": "1 2 3\nnot numbers\n"}, None),
                               ("UTF-16", {"calib.txt": "#polynomial\n5 1 2 3 4 5\n".encode(UTF16)}, None),
                               ("random bytes", {"calib.txt": RANDOM}, None)):
        add("variance", f"ocamcalib calib_file {what}", ["variance", "--config", "rig.toml", "--foot", "100", "0.5"],
            files={"rig.toml": fisheye, **files}, setup=setup, expect="calib_file")
    add("render", "scenario naming a missing rig", ["render", "--scenario", "s.toml", "--frames", "2", "--out", "o"],
        files={"s.toml": scenario_text(repo, "nope.toml")}, expect="nope.toml")
    add("demo", "scenario naming a missing rig", ["demo", "--scenario", "s.toml", "--out", "o"],
        files={"s.toml": scenario_text(repo, "nope.toml")}, expect="nope.toml")
    add("render", "scenario's rig is a directory", ["render", "--scenario", "s.toml", "--frames", "2", "--out", "o"],
        files={"s.toml": scenario_text(repo, "rigdir")}, setup=lambda d: (d / "rigdir").mkdir(), expect="rigdir")
    add("render", "scenario's rig has H_o = inf", ["render", "--scenario", "s.toml", "--frames", "2", "--out", "o"],
        files={"s.toml": scenario_text(repo, "rig.toml"), "rig.toml": rig_text(repo, {"omni.H_o": float("inf")})},
        expect="H_o")
    sc = tomlkit.parse(scenario)
    for key, value in (("fps", float("inf")), ("fps", float("nan")), ("fps", 0.0), ("seed", -1), ("name", 3),
                       ("room.height", float("nan")), ("room.height", 1e300), ("people.count", -1),
                       ("people.count", 10**6), ("people.speed", [0.8, float("inf")]), ("lighting.ambient", 1e300),
                       ("lighting.spectrum", [1.0, float("nan"), 0.8]), ("room.floor.tile", float("inf")),
                       ("lighting.drift.period", 0.0), ("sensor.vignetting", float("nan"))):
        doc = copy.deepcopy(sc)
        *path, last = key.split(".")
        node = doc
        for p in path:
            node = node[p]
        node[last] = value
        add("render", f"scenario {key} = {value}", ["render", "--scenario", "s.toml", "--frames", "2", "--out", "o"],
            files={"s.toml": tomlkit.dumps(doc)}, expect=last)

    # ---- observations (calibrate)
    obs_cases = {
        "UTF-16": Path(obs_file).read_text().encode(UTF16),
        "random bytes": RANDOM,
        "empty": b"",
        "a list": b"[]",
        "an empty object": b"{}",
        "positions a string": b'{"positions": "x"}',
        "truncated": Path(obs_file).read_bytes()[:200],
        "NaN reading": Path(obs_file).read_text().replace('"pan_deg": -56.008', '"pan_deg": NaN', 1).encode(),
        "1e999 reading": Path(obs_file).read_text().replace('"tilt_deg": -60.585', '"tilt_deg": 1e999', 1).encode(),
        "negative r_f": Path(obs_file).read_text().replace('"r_f": 88.53', '"r_f": -88.53', 1).encode(),
        "one position": json.dumps({"positions": json.loads(Path(obs_file).read_text())["positions"][:1]}).encode(),
    }
    for what, data in obs_cases.items():
        add("calibrate", f"observations {what}", ["calibrate", "--config", rig_file, "--observations", "obs.json",
                                                  "--out", "o"], files={"obs.json": data}, expect="obs.json")
    add("calibrate", "observations a directory", ["calibrate", "--config", rig_file, "--observations", "od",
                                                  "--out", "o"], setup=lambda d: (d / "od").mkdir(), expect="od")
    add("calibrate", "observations missing", ["calibrate", "--config", rig_file, "--observations", "nope.json",
                                              "--out", "o"], expect="nope.json")
    for what, spec in (("missing", "nope.png"), ("text", "{fx}/text.avi"), ("wrong size", "{fx}/frame_small.png"),
                       ("random bytes", "{fx}/garbage.mp4")):
        add("calibrate", f"--frame {what}", ["calibrate", "--config", rig_file, "--observations", obs_file,
                                             "--frame", spec, "--out", "o"], expect="--frame")

    # ---- flags
    flag_cases = {
        "validate": [["--grid-step-px", "0"], ["--grid-step-px", "-3"], ["--grid-step-px", "nan"],
                     ["--grid-step-px", "inf"], ["--rel-tol", "nan"], ["--rel-tol", "0"], ["--min-distance", "nan"],
                     ["--min-distance", "inf"], ["--trials", "0"], ["--trials", "-5"], ["--fresh-trials", "3"],
                     ["--empty-frames", "0"], ["--scenario", "nope"]],
        "optimise": [["--grid-step-m", "0"], ["--grid-step-m", "nan"], ["--starts", "0"], ["--landscape", "0"],
                     ["--landscape", "100000"], ["--near-radius", "nan"], ["--face-target-px", "inf"],
                     ["--face-target-px", "-1"], ["--vary", "D_c", "D_c"], ["--cache-dir", "/dev/null/x"]],
        "demo": [["--frames", "-1"], ["--frames", "10"], ["--inset-every", "0"], ["--background-seconds", "-1"],
                 ["--screenshot", "-1"], ["--seed", "-1"], ["--dwell", "nan"], ["--dwell", "-1"],
                 ["--max-seconds", "nan"], ["--max-frames", "0"], ["--dead-zone-sd", "-1"],
                 ["--faults", "broken@x"], ["--faults", "nope@3"], ["--faults", "broken@-1"],
                 ["--faults", "ptz-unplug@3:0"], ["--faults", "end@"], ["--faults", "broken@1e999"],
                 ["--scenario", "nope"], ["--zoom-rule", "best"], ["--cache-dir", "/dev/null/x"]],
        "run": [["--fps", "nan"], ["--fps", "0"], ["--background-frames", "1"], ["--background-seconds", "-1"],
                ["--max-frames", "0"], ["--dwell", "inf"], ["--faults", "ptz-unplug@3"],
                ["--faults", "wrong-size@1:3"], ["--ptz", "bogus://x"], ["--ptz", "/dev/ttyNOPE9"],
                ["--ptz-profile", "nope"]],
        "detect": [["--frames", "0"], ["--overlay-every", "0"], ["--pixel-fa", "1"], ["--sigma-floor", "nan"],
                   ["--adapt-rate", "nan"], ["--background-frames", "2"], ["--background-frames", "100"]],
        "render": [["--frames", "0"], ["--foveal-zoom", "nan"], ["--png-every", "-1"], ["--seed", "-1"],
                   ["--codec", "x"]],
        "calibrate": [["--rim-search", "2"], ["--max-sigma-m", "nan"], ["--max-sigma-deg", "0"]],
    }
    flag_base = {
        "validate": ["validate", "--config", rig_file, "--quick", "--trials", "8", "--fresh-trials", "8",
                     "--empty-frames", "8", "--out", "o"],
        "optimise": ["optimise", "--config", rig_file, "--no-maps", "--landscape", "3", "--starts", "1", "--out", "o"],
        "demo": ["demo", "--frames", "260", "--pace", "all", "--no-video", "--max-frames", "5", "--out", "o"],
        "run": ["run", "{fx}/frames", "--config", rig_file, "--no-video", "--no-cache", "--out", "o"],
        "detect": ["detect", "{fx}/frames", "--config", rig_file, "--out", "o"],
        "render": ["render", "--scenario", "one_person", "--frames", "2", "--out", "o"],
        "calibrate": ["calibrate", "--config", rig_file, "--observations", obs_file, "--out", "o"],
    }
    for cmd, flags in flag_cases.items():
        for extra in flags:
            add(cmd, " ".join(extra), [*flag_base[cmd], *extra], expect=extra[0])
    sim = ["calibrate", "--config", rig_file, "--out", "o", "--simulate"]
    for extra in (["0"], ["2", "--positions", "2"], ["2", "--heights", "1,1"], ["2", "--sigma-ptz-deg", "nan"],
                  ["2", "--positions", "x"], ["2", "--observations", obs_file]):
        add("calibrate", "--simulate " + " ".join(extra), [*sim, *extra],
            expect=next((e for e in extra if e.startswith("--")), "--simulate"))
    var = ["variance", "--config", rig_file]
    for extra, expect in ((["--foot", "nan", "0"], "--foot"), (["--foot", "-1", "0"], "--foot"),
                          (["--foot", "100", "inf"], "--foot"), (["--foot", "1e300", "0"], "--foot"),
                          (["--foot", "100", "0", "--sigma-rf", "inf"], "--sigma-rf"),
                          (["--foot", "100", "0", "--sigma-theta-deg", "nan"], "--sigma-theta-deg"),
                          (["--foot", "100", "0", "--sigma-rf", "1e300"], "--sigma-rf"),
                          (["--foot", "100", "0", "--rel-tol", "0"], "--rel-tol"),
                          (["--foot", "100", "0", "--method", "magic"], "--method"),
                          (["--foot", "100"], "--foot")):
        add("variance", " ".join(extra), [*var, *extra], expect=expect)
    bench = ["bench", "--json"]
    for extra, expect in ((["--sizes", "10x10"], "--sizes"), (["--sizes", "abc"], "--sizes"),
                          (["--sizes", "100000x100000"], "--sizes"), (["--frames", "0"], "--frames"),
                          (["--core", "99"], "--core"), (["--scenario", "nope"], "--scenario")):
        add("bench", " ".join(extra), [*bench, *extra], expect=expect)

    # ---- PTZ
    add("ptz", "--ptz bogus://x", ["ptz", "--ptz", "bogus://x"], expect="--ptz", timeout=60)
    add("ptz", "--ptz a missing device", ["ptz", "--ptz", "/dev/ttyNOPE9"], expect="--ptz", timeout=60)
    add("ptz", "--ptz socket:// without a port", ["ptz", "--ptz", "socket://localhost"], expect="--ptz", timeout=60)
    add("ptz", "no --ptz", ["ptz"], expect="--ptz")
    for extra, expect in ((["--pan-deg", "1e308", "--tilt-deg", "0", "--zoom", "1"], "--pan-deg"),
                          (["--pan-deg", "nan", "--tilt-deg", "0", "--zoom", "1"], "--pan-deg"),
                          (["--pan-deg", "0", "--tilt-deg", "inf", "--zoom", "1"], "--tilt-deg"),
                          (["--pan-deg", "0", "--tilt-deg", "500", "--zoom", "1"], "--tilt-deg"),
                          (["--pan-deg", "0", "--tilt-deg", "0", "--zoom", "0"], "--zoom"),
                          (["--pan-deg", "0", "--tilt-deg", "0", "--zoom", "-3"], "--zoom"),
                          (["--pan-deg", "0"], "--tilt-deg"), (["--wait", "nan"], "--wait"),
                          (["--timeout", "-1"], "--timeout"), (["--protocol", "pelco-d"], "--ptz-profile"),
                          (["--ptz-profile", "nope"], "nope")):
        add("ptz", " ".join(extra), ["ptz", "--ptz", "{pty}", *extra], expect=expect, emulator=True, timeout=60)
    add("ptz", "--zoom 1e308 is clamped and says so", ["ptz", "--ptz", "{pty}", "--pan-deg", "0", "--tilt-deg", "-10",
                                                       "--zoom", "1e308", "--json"], emulator=True, exit=0,
        timeout=60, check=_reports_clamped("zoom"))
    add("ptz", "--pan-deg 175 (beyond the device's 170) is clamped and says so",
        ["ptz", "--ptz", "{pty}", "--pan-deg", "175", "--tilt-deg", "-10", "--zoom", "1", "--json"], emulator=True,
        exit=0, timeout=60, check=_reports_clamped("pan"))
    emu = ["ptz-emulator", "--protocol", "visca"]
    for extra, expect, setup in ((["--address", "99"], "--address", None), (["--faults", "garble=2"], "--faults", None),
                                 (["--faults", "x"], "--faults", None),
                                 (["--state-file", "/nonexistent/dir/f"], "--state-file", None),
                                 (["--state-file", "sd"], "--state-file", lambda d: (d / "sd").mkdir()),
                                 (["--link", "taken/link"], "--link", lambda d: (d / "taken").write_text("x")),
                                 (["--protocol", "nope"], "--protocol", None),
                                 (["--ptz-profile", "pelco_d_dome"], "--ptz-profile", None)):
        add("ptz-emulator", " ".join(extra), [*emu, *extra], expect=expect, setup=setup, timeout=30)

    # ---- sources (run, detect)
    for what, spec, expect in (("missing", "nope.avi", "nope.avi"), ("an empty folder", "{fx}/empty", "empty"),
                               ("a folder of junk .png", "{fx}/junk", "junk"),
                               ("random bytes as video", "{fx}/garbage.mp4", "garbage.mp4"),
                               ("an empty .mp4", "{fx}/empty.mp4", "empty.mp4"),
                               ("a text file as video", "{fx}/text.avi", "text.avi"),
                               ("frames of the wrong size", "{fx}/small", "small"),
                               ("too few frames", "{fx}/frames", "frames")):
        extra = ["--background-frames", "39"] if what == "too few frames" else []
        add("run", f"source {what}", ["run", spec, "--config", rig_file, "--no-video", "--no-cache", "--out", "o",
                                      *extra], expect=expect)
        extra = ["--background-frames", "50"] if what == "too few frames" else []
        add("detect", f"source {what}", ["detect", spec, "--config", rig_file, "--out", "o", *extra], expect=expect)
    add("run", "camera index 99", ["run", "99", "--config", rig_file, "--no-video", "--out", "o"], expect="99")
    add("detect", "a frame of another size in the folder", ["detect", "{fx}/mixed", "--config", rig_file, "--out",
                                                            "o"], expect="0035")
    add("detect", "--change-only on a missing file", ["detect", "nope.avi", "--change-only", "--out", "o"],
        expect="nope.avi")

    # ---- signals during start-up: handlers from the start, nothing half-written, no child left
    for sig, marker, delay, group in ((signal.SIGTERM, "", 1.0, False),
                                      (signal.SIGTERM, "building the world", 2.0, False),
                                      (signal.SIGTERM, "PTZ emulator", 0.5, False),
                                      (signal.SIGTERM, "PTZ emulator", 5.0, False),
                                      (signal.SIGINT, "PTZ emulator", 2.0, False),
                                      (signal.SIGINT, "PTZ emulator", 3.0, True),
                                      (signal.SIGKILL, "PTZ emulator", 3.0, False)):
        to = " to the process group (Ctrl-C)" if group else ""
        add("demo", f"{signal.Signals(sig).name}{to} {delay:g} s after {marker or 'start'!r}",
            ["demo", "--out", "o", "--frames", "400"], exit=-9 if sig == signal.SIGKILL else 130,
            signal=(sig, marker, delay, group), expect="interrupted")
    for cmd, argv in (("run", [*jobs["run"], "--out", "o"]), ("validate", [*jobs["validate"], "--out", "o"]),
                      ("optimise", [*jobs["optimise"], "--out", "o"]), ("render", ["render", "--scenario",
                                                                                    "one_person", "--frames", "200",
                                                                                    "--out", "o"])):
        add(cmd, "SIGTERM 8 s after start", argv, exit=130, signal=(signal.SIGTERM, "", 8.0, False),
            expect="interrupted")

    # ---- the demo says what it wrote
    add("demo", "--screenshot past the last frame: view.png not listed",
        ["demo", "--out", "o", "--frames", "260", "--pace", "all", "--no-video", "--screenshot", "5000"], exit=0,
        timeout=300, check=_lists_only_written)
    return out


def _reports_clamped(axis: str):
    def check(tmp: Path, stdout: str, stderr: str) -> str | None:
        try:
            rep = json.loads(stdout)
        except ValueError:
            return "stdout is not one JSON object"
        if axis not in rep.get("target", {}).get("clamped", []):
            return f"{axis} not reported as clamped: {rep.get('target')}"
        return None
    return check


def _lists_only_written(tmp: Path, stdout: str, stderr: str) -> str | None:
    line = next((s for s in stdout.splitlines() if "outputs" in s), "")
    if "view.png" in line and not (tmp / "o" / "view.png").exists():
        return f"lists view.png, which it did not write: {line.strip()}"
    return None


# --------------------------------------------------------------------------------------
# Running and classifying
# --------------------------------------------------------------------------------------

_ERROR = re.compile(r"^omnijax [\w-]+: (error: |interrupted)")
_OWN = re.compile(r"^omnijax [\w-]+: ")
_PROGRESS = re.compile(r"\d+%\|")


def _survivors(tag: str) -> list[int]:
    pids = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if f"{MARK}={tag}".encode() in (p / "environ").read_bytes().split(b"\0"):
                    pids.append(int(p.name))
            except OSError:
                continue
    return pids


def _snapshot(folder: Path) -> dict[str, tuple]:
    out = {}
    for p in folder.rglob("*"):
        try:
            st = p.lstat()
        except OSError:
            continue
        out[str(p.relative_to(folder))] = (st.st_mode, st.st_size, st.st_mtime_ns)
    return out


def _start_emulator(repo: Path, env: dict) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", "ptz-emulator", "--protocol", "visca"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=repo, env=env,
                            start_new_session=True)
    return proc, proc.stdout.readline().strip()


def run_case(case: Case, index: int, repo: Path, fixtures: Path) -> dict:
    tag = f"{os.getpid()}-{index}"
    tmp = Path(tempfile.mkdtemp(prefix="hostile-"))
    shared = fixtures.parent
    env = {**os.environ, "PYTHONPATH": str(repo), MARK: tag, "PYTHONFAULTHANDLER": "1", "HOME": str(shared / "home"),
           "XDG_CACHE_HOME": str(shared / "cache"), "MPLCONFIGDIR": str(shared / "mpl")}
    emulator = None
    try:
        for name, data in case.files.items():
            path = tmp / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data.encode() if isinstance(data, str) else data)
        if case.setup:
            case.setup(tmp)
        pty = ""
        if case.emulator:
            emulator, pty = _start_emulator(repo, {**env, MARK: "emulator"})
        argv = [a.format(fx=fixtures, repo=repo, pty=pty) for a in case.argv]
        before = _snapshot(tmp)
        prefix = []
        if case.unprivileged and os.geteuid() == 0:  # root writes anywhere: drop that power for this case
            caps = "-dac_override,-dac_read_search"
            prefix = ["setpriv", f"--bounding-set={caps}", f"--inh-caps={caps}"]
        t0 = time.monotonic()
        proc = subprocess.Popen([*prefix, sys.executable, "-m", "runtime.cli", *argv], cwd=tmp, env=env, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, errors="replace",
                                start_new_session=True)
        chunks = {"out": [], "err": []}
        readers = [threading.Thread(target=lambda s=s, k=k: chunks[k].extend(iter(s.readline, "")), daemon=True)
                   for s, k in ((proc.stdout, "out"), (proc.stderr, "err"))]
        for r in readers:
            r.start()
        if case.signal is not None:
            sig, marker, delay, group = case.signal
            while marker and marker not in "".join(chunks["err"]) and proc.poll() is None \
                    and time.monotonic() - t0 < case.timeout:
                time.sleep(0.05)
            time.sleep(delay)
            if proc.poll() is None:
                if group:
                    os.killpg(proc.pid, sig)
                else:
                    proc.send_signal(sig)
        try:
            rc = proc.wait(case.timeout - (time.monotonic() - t0))
            hung = False
        except subprocess.TimeoutExpired:
            proc.kill()
            rc, hung = proc.wait(), True
        for r in readers:
            r.join(5)
        seconds = time.monotonic() - t0
        stdout, stderr = "".join(chunks["out"]), "".join(chunks["err"])
        left = _survivors(tag)
        for _ in range(50):  # children that watch their parent are given 5 s to go
            if not left:
                break
            time.sleep(0.1)
            left = _survivors(tag)
        for pid in left:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        after = _snapshot(tmp)
        verdict, reason = classify(case, rc, hung, stdout, stderr, before, after, left, tmp)
        return {"command": case.command, "case": case.name, "argv": argv, "exit": rc, "seconds": round(seconds, 1),
                "verdict": verdict, "reason": reason,
                "stderr_tail": stderr.strip().splitlines()[-(3 if verdict == "clean" else 40):]}
    finally:
        if emulator is not None:
            os.killpg(emulator.pid, signal.SIGKILL)
            emulator.wait()
        subprocess.run(["chmod", "-R", "u+rwx", str(tmp)], check=False)
        shutil.rmtree(tmp, ignore_errors=True)


def classify(case: Case, rc: int, hung: bool, stdout: str, stderr: str, before: dict, after: dict,
             left: list[int], tmp: Path) -> tuple[str, str]:
    lines = [s for s in stderr.splitlines() if s.strip()]
    if hung:
        return "other", f"no exit within {case.timeout:g} s"
    if "Traceback (most recent call last)" in stderr:
        return "traceback", lines[-1][:160] if lines else ""
    partial = sorted(k for k in after if ".partial-" in k)
    changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k)
                     and not (case.exit == 0 and k.split("/")[0] == "o"))
    if case.signal is not None and rc == 0 and (tmp / "o" / "summary.json").is_file() and not left:
        return "clean", ""  # the signal came after start-up: the loop ended cleanly and wrote everything
    if case.signal is not None and case.signal[0] == signal.SIGKILL and rc == -signal.SIGKILL:
        # nothing can clean up after SIGKILL (a staging folder stays); what must not stay is a child
        return ("other", f"{len(left)} child process(es) outlived the command") if left else ("clean", "")
    if rc == case.exit:
        if left:
            return "other", f"{len(left)} child process(es) outlived the command"
        if partial:
            return "other", f"half-written output left: {partial[0]}"
        if case.exit == 0:
            problem = case.check(tmp, stdout, stderr) if case.check else None
            return ("other", problem) if problem else ("clean", "")
        if changed:
            return "other", f"output place changed: {changed[0]}"
        if not lines or not _ERROR.match(lines[-1]):
            return "other", f"last line is not omnijax's error: {lines[-1][:160] if lines else '(nothing)'}"
        usage = False
        for s in lines[:-1]:
            if s.startswith("usage: "):
                usage = True
                continue
            if usage and s.startswith(" "):
                continue
            usage = False
            if case.signal is not None and _PROGRESS.search(s):
                continue  # a job interrupted while working has shown its progress
            if not _OWN.match(s):
                return "other", f"foreign line before the error: {s[:160]}"
        if case.expect and case.expect.lower() not in lines[-1].lower():
            return "other", f"error does not name {case.expect!r}: {lines[-1][:160]}"
        return "clean", ""
    if rc == 0:
        return "wrong exit 0", (lines[-1][:160] if lines else "")
    if left:
        return "other", f"exit {rc}, {len(left)} child process(es) outlived the command"
    return "other", f"exit {rc}: {lines[-1][:160] if lines else '(no stderr)'}" + (
        f"; half-written {partial[0]}" if partial else "")


def table(results: list[dict]) -> str:
    cols = ("clean", "traceback", "wrong exit 0", "other")
    rows = ["| command | tried | clean | traceback | wrong exit 0 | other |",
            "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for cmd in (*COMMANDS, "total"):
        rs = [r for r in results if cmd in ("total", r["command"])]
        if rs:
            counts = [sum(r["verdict"] == c for r in rs) for c in cols]
            name = f"**{cmd}**" if cmd == "total" else f"`{cmd}`"
            rows.append(f"| {name} | {len(rs)} | " + " | ".join(str(c) for c in counts) + " |")
    return "\n".join(rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repo", type=Path, default=HERE, help="the checkout to test (default: this one)")
    ap.add_argument("--jobs", type=int, default=2, help="cases run at once (default 2)")
    ap.add_argument("--only", nargs="+", default=[], metavar="TEXT", help="only cases whose command or name has TEXT")
    ap.add_argument("--json", type=Path, metavar="FILE", help="also write every outcome to FILE")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args()
    repo = args.repo.resolve()
    all_cases = [c for c in cases(repo) if not args.only or any(t in f"{c.command} {c.name}" for t in args.only)]
    if args.list:
        for c in all_cases:
            print(f"{c.command:13s} {c.name}")
        print(f"{len(all_cases)} cases")
        return 0
    work = Path(tempfile.mkdtemp(prefix="hostile-fixtures-"))
    fixtures = work / "fx"
    fixtures.mkdir()
    for name in ("cache", "home", "mpl"):
        (work / name).mkdir(mode=0o777)
        os.chmod(work / name, 0o777)
    os.chmod(work, 0o755)
    make_fixtures(fixtures)
    subprocess.run(["chmod", "-R", "a+rX", str(work)], check=True)
    print(f"{len(all_cases)} cases against {repo} ({args.jobs} at a time)", file=sys.stderr)
    t0 = time.monotonic()
    done = [0]

    def one(item):
        k, case = item
        try:
            r = run_case(case, k, repo, fixtures)
        except Exception as exc:  # the harness's own failure: reported, not counted against the command
            r = {"command": case.command, "case": case.name, "argv": case.argv, "exit": None, "seconds": 0.0,
                 "verdict": "harness error", "reason": f"{type(exc).__name__}: {exc}", "stderr_tail": []}
        done[0] += 1
        mark = "" if r["verdict"] == "clean" else f"  [{r['verdict']}: {r['reason']}]"
        print(f"{done[0]:4d}/{len(all_cases)} {r['seconds']:6.1f} s  {case.command} | {case.name}{mark}",
              file=sys.stderr, flush=True)
        return r

    try:
        with ThreadPoolExecutor(args.jobs) as pool:
            results = list(pool.map(one, enumerate(all_cases)))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    errors = [r for r in results if r["verdict"] == "harness error"]
    results = [r for r in results if r["verdict"] != "harness error"]
    print(table(results))
    for r in errors:
        print(f"harness error (not counted): {r['command']} | {r['case']}: {r['reason']}")
    bad = [r for r in results if r["verdict"] != "clean"]
    if bad:
        print(f"\nnot clean ({len(bad)}):")
        for r in bad:
            print(f"- {r['command']} | {r['case']}: {r['verdict']}: {r['reason']}")
    print(f"\n{len(results)} cases in {time.monotonic() - t0:.0f} s")
    if args.json:
        args.json.write_text(json.dumps({"repo": str(repo), "results": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
