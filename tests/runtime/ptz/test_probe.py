"""``omnijax ptz probe`` and ``ptz calibrate`` against emulated cameras (UDP and pty, in-process).

The calibration is checked against the emulator's configured speeds and latency with tolerances
wide enough for a loaded machine (the samples are stamped by this process's clock).
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from runtime.cli import main
from runtime.ptz import PtyEmulator, UdpEmulator, default_profile, load_profile, make_driver
from runtime.ptz.probe import calibrate, fit_move, probe, probe_table
from tests.runtime.ptz.helpers import quick_profile


def test_fit_move_recovers_speed_and_latency():
    rng = np.random.default_rng(0)
    t_write, latency, speed, start, end = 10.0, 0.05, 250.0, -100.0, 400.0
    t = np.sort(rng.uniform(t_write, t_write + 2.5, 40))
    p = np.clip(start + speed * (t - t_write - latency), start, end)
    got_speed, got_latency = fit_move(list(zip(t, p)), start, end, t_write)
    assert got_speed == pytest.approx(speed, rel=1e-9) and got_latency == pytest.approx(latency, abs=1e-9)
    with pytest.raises(ValueError, match="position samples"):
        fit_move([(t_write, start), (t_write + 1, end)], start, end, t_write)


@pytest.mark.parametrize("protocol", ["visca-ip", "pelco-d"])
def test_probe_says_drivable(protocol):
    profile = quick_profile("visca" if protocol == "visca-ip" else protocol)
    emu = UdpEmulator(profile) if protocol == "visca-ip" else PtyEmulator(profile)
    with emu:
        url = f"visca-udp://127.0.0.1:{emu.address[1]}" if protocol == "visca-ip" else emu.path
        with make_driver(url, profile) as ptz:
            before = ptz.query_position()
            report = probe(ptz)
            after = ptz.query_position()
    assert report["verdict"]["drivable"], report
    assert report["checks"]["position"]["ok"] and report["checks"]["move"]["ok"]
    assert after.units == before.units  # the test move went back
    if protocol == "visca-ip":
        assert report["checks"]["move"]["completions"] >= 2 and report["capabilities"]["transport"] == "udp"
    table = probe_table(report, url)
    assert "verdict             drivable" in table and "position read-back  yes" in table


def test_calibrate_finds_the_emulators_speeds_and_latency():
    profile = default_profile("visca")
    latency = 0.02
    with UdpEmulator(profile, latency_s=latency) as emu, \
            make_driver(f"visca-udp://127.0.0.1:{emu.address[1]}", profile) as ptz:
        fitted = calibrate(ptz, moves=1, span=0.3)
    p = fitted["profile"]
    # 1-2 % on a quiet machine (docs/ptz.md); 10 % leaves room for a loaded one (samples stamped by our clock)
    assert p["pan.max_speed_deg_s"] == pytest.approx(profile.pan.max_speed_deg_s, rel=0.1)
    assert p["tilt.max_speed_deg_s"] == pytest.approx(profile.tilt.max_speed_deg_s, rel=0.1)
    assert p["zoom.seconds_full_range"] == pytest.approx(profile.zoom.seconds_full_range, rel=0.1)
    assert latency - 0.01 <= p["link.command_latency_s"] <= latency + 0.1


@pytest.mark.slow
def test_cli_calibrate_writes_a_profile_that_loads(tmp_path, capsys):
    profile = default_profile("visca")
    out = tmp_path / "cam.toml"
    with UdpEmulator(profile) as emu:
        url = f"visca-udp://127.0.0.1:{emu.address[1]}"
        assert main(["ptz", "calibrate", "--ptz", url, "--out", str(out), "--moves", "1", "--span", "0.3"]) == 0
        assert main(["ptz", "probe", "--ptz", url, "--json"]) == 0
    text = out.read_text()
    assert text.startswith("# Calibrated by `omnijax ptz calibrate")
    cal = load_profile(out)
    assert cal.pan.max_speed_deg_s == pytest.approx(100.0, rel=0.1)
    assert cal.link.command_latency_s < 0.1
    assert "ack_timeout_s = 0.5" in text  # the rest is kept
    assert tomllib.loads(text)["name"] == profile.name
    assert '"drivable": true' in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["ptz", "calibrate", "--ptz", "visca-udp://127.0.0.1", "--out", "/no/such/dir/p.toml"], "--out: no such folder"),
    (["ptz", "calibrate", "--ptz", "visca-udp://127.0.0.1", "--out", "p.toml", "--moves", "0"], "--moves: expected"),
    (["ptz", "calibrate", "--ptz", "visca-udp://127.0.0.1", "--out", "p.toml", "--span", "2"], "--span: expected"),
    (["ptz", "probe"], "--ptz: expected"),
    (["ptz", "probe", "--ptz", "visca-udp://127.0.0.1", "--step-deg", "45"], "--step-deg: expected"),
    (["ptz", "probe", "--ptz", "visca-udp://h:x"], "--ptz: "),
])
def test_cli_bad_input_is_one_line_and_exit_2(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_cli_probe_of_a_silent_camera_is_exit_1(capsys):
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:  # bound but never answering
        s.bind(("127.0.0.1", 0))
        url = f"visca-udp://127.0.0.1:{s.getsockname()[1]}"
        assert main(["ptz", "probe", "--ptz", url, "--timeout", "0.5"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no visca camera within 0.5 s" in err[0]


def test_the_loop_adds_the_profiles_command_latency_to_the_slew_time():
    """What ``calibrate`` writes is what the loop predicts arrival with: latency + slowest axis."""
    from runtime.ptz import parse_profile
    from runtime.realtime.ptz_link import PtzLink
    from tests.runtime.ptz.helpers import profile_mapping

    m = profile_mapping("visca")
    m["link"] = {**m.get("link", {}), "command_latency_s": 0.25}
    profile = parse_profile(m)
    link = PtzLink(0, None, profile)
    link.sent = (0.0, 0.0, 1.0)
    t = link.slew_time((math.radians(50.0), 0.0, 1.0))
    assert t == pytest.approx(0.25 + 50.0 / link.rates[0])


@pytest.mark.parametrize("pan_deg, tilt_deg", [(0.0, 45.0), (60.0, 0.0), (-30.0, 60.0)])
def test_the_loop_predicts_arrival_at_the_speed_the_driver_commands(pan_deg, tilt_deg):
    """One source of truth for speed: the emulated EVI-D70, driven by the driver's own pan-tilt packet (tilt
    speed code 20 of 23: 78 deg/s, not the 90 deg/s top speed), completes when the loop predicts it."""
    from runtime.ptz import ViscaCamera, default_profile
    from runtime.ptz.dialect import ViscaDialect
    from runtime.ptz.visca import ViscaParser, completion
    from runtime.realtime.ptz_link import PtzLink

    profile = default_profile("visca")
    assert profile.tilt.move_deg_s() == pytest.approx(90.0 * 20 / 23)
    target = (math.radians(pan_deg), math.radians(tilt_deg), 1.0)
    link = PtzLink(0, None, profile)
    link.sent = (0.0, 0.0, 1.0)
    predicted = link.slew_time(target)
    camera = ViscaCamera(profile, now=0.0)
    (_, _, move), _zoom = ViscaDialect(profile).commands(profile.to_device(*target))
    for packet in ViscaParser().feed(move.packet):
        camera.receive(packet, 0.0)
    t = 0.0
    while completion(1, 1) not in camera.tick(t):
        t += 0.001
    assert t == pytest.approx(predicted, abs=0.002 + 1 / (14.4 * min(profile.move_rates_deg_s())))
