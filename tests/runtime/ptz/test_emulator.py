"""The emulated cameras: replies, error replies and slew-limited motion (clock passed in), and the CLI contract."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import serial

from runtime.ptz import PelcoDCamera, ViscaCamera, default_profile, pelco_d, visca
from runtime.ptz.pelco_d import PelcoDParser
from runtime.ptz.visca import ErrorCode, ViscaParser
from tests.paths import ROOT
from tests.runtime.ptz.helpers import wait_for

#: The installed entry point, as a user runs it.
OMNIJAX = str(Path(sys.executable).parent / "omnijax")
VISCA = default_profile("visca")
PELCO = default_profile("pelco-d")


def _send(cam, data: bytes, now: float) -> list[bytes]:
    parser = ViscaParser() if isinstance(cam, ViscaCamera) else PelcoDParser()
    return [r for f in parser.feed(data) for r in cam.receive(f, now)]


# ------------------------------------------------------------------------------------------
# VISCA
# ------------------------------------------------------------------------------------------


def test_visca_motion_is_acked_slewed_and_completed():
    cam = ViscaCamera(VISCA, now=0.0)
    pan = round(50 * 14.4)
    assert _send(cam, visca.pan_tilt_absolute(1, 24, 23, pan, 0), 0.0) == [visca.ack(1, 1)]
    assert cam.tick(0.1) == []
    # 100 deg/s at speed 24: 10 deg after 0.1 s
    assert _send(cam, visca.pan_tilt_position_inquiry(1), 0.1) == [visca.pan_tilt_position_reply(1, 144, 0)]
    assert cam.tick(0.49) == []
    assert cam.tick(0.51) == [visca.completion(1, 1)]
    assert cam.sockets == {}


def test_visca_half_speed_code_halves_the_slew():
    cam = ViscaCamera(VISCA, now=0.0)
    _send(cam, visca.pan_tilt_absolute(1, 12, 23, 1440, 0), 0.0)
    cam.tick(0.2)
    assert round(cam.pan.position) == round(0.2 * 50 * 14.4)


def test_visca_zoom_and_pan_tilt_use_both_sockets_and_a_new_target_replaces_the_old():
    cam = ViscaCamera(VISCA, now=0.0)
    assert _send(cam, visca.pan_tilt_absolute(1, 24, 23, 1000, 0), 0.0) == [visca.ack(1, 1)]
    assert _send(cam, visca.zoom_direct(1, 0x4000), 0.0) == [visca.ack(1, 2)]
    assert _send(cam, visca.pan_tilt_absolute(1, 24, 23, -1000, 0), 0.1) == [visca.completion(1, 1), visca.ack(1, 1)]
    assert cam.pan.target == -1000


@pytest.mark.parametrize("packet,code,socket", [
    (bytes.fromhex("81 01 7f ff"), ErrorCode.SYNTAX, 0),
    (bytes.fromhex("81 ff"), ErrorCode.MESSAGE_LENGTH, 0),
    (bytes.fromhex("81" + " 01" * 20 + " ff"), ErrorCode.MESSAGE_LENGTH, 0),
    (visca.pan_tilt_absolute(1, 0x30, 1, 0, 0), ErrorCode.SYNTAX, 0),          # pan speed beyond 0x18
    (visca.pan_tilt_absolute(1, 24, 23, round(175 * 14.4), 0), ErrorCode.NOT_EXECUTABLE, 1),
    (visca.zoom_direct(1, 0x5000), ErrorCode.NOT_EXECUTABLE, 1),
    (visca.cancel(1, 2), ErrorCode.NO_SOCKET, 2),
])
def test_visca_error_replies(packet, code, socket):
    cam = ViscaCamera(VISCA)
    assert _send(cam, packet, 0.0) == [visca.error(1, socket, code)]
    assert cam.errors == 1


def test_visca_cancel_stops_the_motion():
    cam = ViscaCamera(VISCA, now=0.0)
    _send(cam, visca.pan_tilt_absolute(1, 24, 23, 2000, 0), 0.0)
    assert _send(cam, visca.cancel(1, 1), 0.1) == [visca.error(1, 1, ErrorCode.CANCELLED)]
    assert not cam.moving and cam.sockets == {}


def test_visca_buffer_full():
    cam = ViscaCamera(VISCA, rng=random.Random(0), buffer_full=1.0)
    assert _send(cam, visca.zoom_direct(1, 100), 0.0) == [visca.error(1, 0, ErrorCode.BUFFER_FULL)]


def test_visca_address_set_if_clear_and_chain_position():
    cam = ViscaCamera(VISCA, chain_position=2)
    assert cam.address == 2
    assert _send(cam, visca.address_set(1), 0.0) == [visca.address_set_reply(3)]
    assert _send(cam, visca.pan_tilt_absolute(2, 24, 23, 1000, 0), 0.0) == [visca.ack(2, 1)]
    assert _send(cam, visca.if_clear(), 0.0) == [visca.if_clear_reply()]
    assert cam.sockets == {} and not cam.moving
    assert _send(cam, visca.if_clear(2), 0.0) == [visca.completion(2, 0)]
    assert _send(cam, visca.zoom_direct(1, 100), 0.0) == []          # for camera 1: not ours
    assert _send(cam, visca.ack(1, 1), 0.0) == []                    # another camera's reply: ignored


# ------------------------------------------------------------------------------------------
# Pelco-D
# ------------------------------------------------------------------------------------------


def test_pelco_moves_answers_queries_and_general_responses():
    cam = PelcoDCamera(PELCO, now=0.0)
    gr = pelco_d.general_response(1)
    assert _send(cam, pelco_d.set_pan_position(1, 6000), 0.0) == [gr]
    assert _send(cam, pelco_d.set_tilt_position(1, 4500), 0.0) == [gr]
    assert _send(cam, pelco_d.set_zoom_position(1, 65535), 0.0) == [gr]
    # 120 deg/s pan, 90 deg/s tilt, full zoom in 3 s: after 0.25 s
    replies = _send(cam, b"".join(pelco_d.query(1, q) for q in pelco_d.QUERY_REPLY), 0.25)
    assert replies == [pelco_d.position_reply(1, pelco_d.REPLY_PAN, 3000),
                       pelco_d.position_reply(1, pelco_d.REPLY_TILT, 2250),
                       pelco_d.position_reply(1, pelco_d.REPLY_ZOOM, round(65535 / 12))]
    cam.tick(5.0)
    assert not cam.moving and cam.state()["pan_deg"] == 60.0 and cam.state()["zoom"] == 30.0


def test_pelco_pan_goes_the_short_way_round():
    cam = PelcoDCamera(PELCO, now=0.0)
    _send(cam, pelco_d.set_pan_position(1, 17000), 0.0)
    cam.tick(10.0)
    _send(cam, pelco_d.set_pan_position(1, -17000), 10.0)
    cam.tick(10.1)  # 12 deg on: through 180 deg, not back through 0
    assert round(cam.pan.position) in (17000 + 1200 - 36000, 17000 + 1200)
    assert abs(abs(round(cam.pan.position)) - 17800) <= 1


def test_pelco_presets_and_stop():
    cam = PelcoDCamera(PELCO, now=0.0)
    _send(cam, pelco_d.set_pan_position(1, 1000), 0.0)
    cam.tick(2.0)
    assert _send(cam, pelco_d.preset(1, pelco_d.SET_PRESET, 5), 2.0)
    _send(cam, pelco_d.set_pan_position(1, 3000), 2.0)
    cam.tick(4.0)
    _send(cam, pelco_d.preset(1, pelco_d.GO_TO_PRESET, 5), 4.0)
    cam.tick(6.0)
    assert round(cam.pan.position) == 1000
    _send(cam, pelco_d.set_pan_position(1, 9000), 6.0)
    _send(cam, pelco_d.stop(1), 6.1)
    assert not cam.moving and 1000 < cam.pan.position < 9000
    _send(cam, pelco_d.preset(1, pelco_d.CLEAR_PRESET, 5), 7.0)
    assert _send(cam, pelco_d.preset(1, pelco_d.GO_TO_PRESET, 5), 7.0) == [] and cam.errors == 1


def test_pelco_ignores_and_counts_bad_packets():
    cam = PelcoDCamera(PELCO)
    assert _send(cam, pelco_d.set_tilt_position(1, -2000), 0.0) == []      # -20 deg: above the dome's range
    assert _send(cam, pelco_d.frame(1, 0x88, 0x00), 0.0) == []             # camera on: unsupported
    assert _send(cam, pelco_d.set_pan_position(2, 100), 0.0) == []         # another address: not counted
    assert (cam.commands, cam.errors) == (2, 2)


def test_pelco_without_general_responses():
    from runtime.ptz import parse_profile
    from tests.runtime.ptz.helpers import profile_mapping

    m = profile_mapping("pelco-d")
    m["pelco_d"] = {"general_response": False}
    cam = PelcoDCamera(parse_profile(m))
    assert _send(cam, pelco_d.set_pan_position(1, 100), 0.0) == []
    assert cam.pan.target == 100


# ------------------------------------------------------------------------------------------
# The command (docs/design.md section 7.4)
# ------------------------------------------------------------------------------------------


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([OMNIJAX, "ptz-emulator", *args], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("protocol", ["visca", "pelco-d"])
def test_emulator_command_contract(tmp_path, protocol):
    state, link = tmp_path / "state.json", tmp_path / "ptz"
    proc = _start("--protocol", protocol, "--state-file", str(state), "--link", str(link))
    try:
        path = proc.stdout.readline().strip()
        assert path.startswith("/dev/pts/") and os.path.realpath(link) == path
        query = visca.pan_tilt_position_inquiry(1) if protocol == "visca" else pelco_d.query(1, pelco_d.QUERY_PAN)
        with serial.Serial(path, timeout=5) as port:
            port.write(query)
            answer = port.read(11 if protocol == "visca" else 7)
        assert answer in (visca.pan_tilt_position_reply(1, 0, 0), pelco_d.position_reply(1, pelco_d.REPLY_PAN, 0))
        assert wait_for(lambda: state.exists() and json.loads(state.read_text())["commands"] == 1)
        s = json.loads(state.read_text())
        assert {"pan_deg", "tilt_deg", "zoom", "commands", "errors"} <= set(s)
        assert (s["pan_deg"], s["tilt_deg"], s["zoom"], s["errors"]) == (0.0, 0.0, 1.0, 0)
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert not link.exists()
    assert list(tmp_path.iterdir()) == [state]  # no temporary state files left behind


@pytest.mark.parametrize("args,expect", [
    (["--protocol", "visca", "--address", "9"], "--address: expected 1-7"),
    (["--protocol", "pelco-d", "--ptz-profile", "sony_evi_d70"], "is a visca profile"),
    (["--protocol", "visca", "--ptz-profile", "nowhere.toml"], "no such device profile"),
    (["--protocol", "visca", "--faults", "fire=0.5"], "unknown fault 'fire'"),
    (["--protocol", "visca", "--faults", "drop=2"], "probability in [0, 1]"),
    (["--protocol", "visca", "--state-file", "/no/such/dir/s.json"], "no such folder"),
])
def test_emulator_command_bad_input_exits_2(args, expect):
    proc = _start(*args)
    out, err = proc.communicate(timeout=20)
    assert proc.returncode == 2 and out == ""
    assert expect in err and len(err.strip().splitlines()) == 1
