"""VISCA over IP: the framing, the camera's side, and the driver through real UDP sockets on 127.0.0.1.

Every socket is bound by the test to 127.0.0.1 with a port the OS picks; waits use generous
time-outs on conditions (never a tight timing bound).
"""

from __future__ import annotations

import math
import socket
import subprocess
import sys
import threading
import time

import pytest

from runtime.cli import main
from runtime.ptz import Faults, PtyEmulator, PtzPortError, UdpEmulator, ViscaCamera, make_driver, visca, visca_ip as vip
from runtime.ptz.packets import Packet
from tests.paths import ROOT
from tests.runtime.ptz.helpers import quick_profile, wait_for

TARGETS = [(30.0, -20.0, 4.0), (-120.0, 4.0, 1.0), (165.0, -29.0, 12.5), (0.0, 0.0, 18.0)]


def _rad(pan_deg, tilt_deg, zoom):
    return math.radians(pan_deg), math.radians(tilt_deg), zoom


def _url(emu: UdpEmulator) -> str:
    return f"visca-udp://127.0.0.1:{emu.address[1]}"


# -- framing ------------------------------------------------------------------------------


def test_frame_is_sonys_header_and_round_trips():
    d = vip.frame(vip.COMMAND, 0x01020304, b"\x81\x01\x04\x07\x00\xff")
    assert d[:8] == bytes.fromhex("0100 0006 01020304")
    assert vip.unframe(d) == vip.Datagram(vip.COMMAND, 0x01020304, b"\x81\x01\x04\x07\x00\xff")


@pytest.mark.parametrize("data", [b"", b"\x01\x00\x00\x01", bytes.fromhex("0100 0002 00000001 81"),
                                  bytes.fromhex("0300 0001 00000001 81"), vip.HEADER.pack(0x0100, 17, 1) + bytes(17)])
def test_unframe_refuses_malformed(data):
    assert vip.unframe(data) is None


@pytest.mark.parametrize("url, expected", [("visca-udp://10.0.0.5", ("10.0.0.5", 52381)),
                                           ("visca-udp://cam.local:1259", ("cam.local", 1259)),
                                           ("VISCA-UDP://[::1]:7", ("::1", 7))])
def test_parse_url(url, expected):
    assert vip.parse_url(url) == expected


@pytest.mark.parametrize("url", ["visca-udp://", "visca-udp://h:x", "visca-udp://h:99999", "visca-udp://h/path"])
def test_parse_url_refuses_malformed(url):
    with pytest.raises(PtzPortError, match="expected visca-udp://HOST"):
        vip.parse_url(url)


# -- the camera's side ------------------------------------------------------------------------


def _camera():
    return vip.ViscaIpCamera(ViscaCamera(quick_profile("visca"), now=0.0))


def test_reset_then_sequence_rules():
    cam = _camera()
    assert cam.receive(vip.frame(vip.CONTROL, 0, vip.RESET), 0.0) == [vip.frame(vip.CONTROL_REPLY, 0, vip.RESET)]
    move = visca.pan_tilt_absolute(1, 24, 20, 100, 50)
    first = cam.receive(vip.frame(vip.COMMAND, 5, move), 0.0)
    assert first == [vip.frame(vip.REPLY, 5, visca.ack(1, 1))]
    # a retry (same number) gets the same replies and does not execute again
    assert cam.receive(vip.frame(vip.COMMAND, 5, move), 0.0) == first
    assert cam.camera.commands == 1
    # a number going backwards is a sequence error; RESET clears it
    assert cam.receive(vip.frame(vip.COMMAND, 4, move), 0.0) == [vip.frame(vip.CONTROL_REPLY, 4, vip.SEQUENCE_ERROR)]
    cam.receive(vip.frame(vip.CONTROL, 0, vip.RESET), 0.0)
    assert cam.receive(vip.frame(vip.INQUIRY, 1, visca.zoom_position_inquiry(1)), 0.0)[0][:8] == \
        vip.HEADER.pack(vip.REPLY, 7, 1)
    # the completion carries the number of the command that started the motion
    done = cam.tick(60.0)
    assert done == [vip.frame(vip.REPLY, 5, visca.completion(1, 1))]


def test_unknown_command_is_a_syntax_error_and_bad_payload_a_message_error():
    cam = _camera()
    assert cam.receive(vip.frame(vip.COMMAND, 1, bytes.fromhex("81 01 7f ff")), 0.0) == \
        [vip.frame(vip.REPLY, 1, bytes.fromhex("90 60 02 ff"))]
    assert cam.receive(vip.frame(vip.COMMAND, 2, b"\x81\x01"), 0.0) == \
        [vip.frame(vip.CONTROL_REPLY, 2, vip.MESSAGE_ERROR)]
    assert cam.receive(vip.frame(vip.CONTROL, 3, b"\x02"), 0.0) == [vip.frame(vip.CONTROL_REPLY, 3, vip.MESSAGE_ERROR)]
    assert cam.receive(b"\x01\x00", 0.0) == []
    assert cam.errors == 3 and cam.camera.errors == 1


@pytest.mark.parametrize("hex_", ["81 01 ee 77 ff", "81 01 06 99 ff", "ee 77 ff"])
def test_a_message_with_a_high_body_byte_is_a_syntax_error_in_a_reply_with_its_number(hex_):
    cam = _camera()
    assert cam.receive(vip.frame(vip.COMMAND, 9, bytes.fromhex(hex_)), 0.0) == \
        [vip.frame(vip.REPLY, 9, bytes.fromhex("90 60 02 ff"))]
    assert cam.errors == 0 and cam.camera.errors == 1


def test_serial_emulator_answers_an_unknown_command_with_a_syntax_error():
    cam = ViscaCamera(quick_profile("visca"), now=0.0)
    data = bytes.fromhex("81 01 06 99 ff")
    assert cam.receive(Packet(data, 0, len(data)), 0.0) == [bytes.fromhex("90 60 02 ff")]


@pytest.mark.parametrize("hex_", ["81 01 ee 77 ff", "81 01 06 99 ff"])
def test_the_serial_emulator_answers_a_high_body_byte_through_its_pty(hex_):
    """Through the pty and the emulator's own packet reader, as a client's bytes arrive."""
    import serial

    with PtyEmulator(quick_profile("visca")) as emu, serial.Serial(emu.path, timeout=2) as port:
        port.write(bytes.fromhex(hex_))
        assert port.read(4) == bytes.fromhex("90 60 02 ff")


def test_the_driver_drops_a_reply_datagram_that_is_not_one_message():
    counters: dict = {}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as cam:
        cam.bind(("127.0.0.1", 0))
        cam.settimeout(2)
        threading.Thread(target=_answer_reset, args=(cam,), daemon=True).start()
        port = vip.ViscaIpPort("127.0.0.1", cam.getsockname()[1], timeout=0.05, ack_timeout_s=2.0, counters=counters)
        try:
            port.write(visca.pan_tilt_position_inquiry(1))
            port._take(vip.frame(vip.REPLY, 1, visca.ack(1, 1) + visca.ack(1, 2)))
            assert port.in_waiting == 0 and counters["malformed_datagrams"] == 1
            port._take(vip.frame(vip.REPLY, 1, visca.ack(1, 1)))
            assert port.read(16) == visca.ack(1, 1)
        finally:
            port.close()


def _answer_reset(sock: socket.socket) -> None:
    data, peer = sock.recvfrom(2048)
    sock.sendto(vip.frame(vip.CONTROL_REPLY, vip.unframe(data).seq, vip.RESET), peer)


# -- the driver through UDP ---------------------------------------------------------------


def test_round_trip_reaches_every_target():
    profile = quick_profile("visca")
    with UdpEmulator(profile) as emu, make_driver(_url(emu), profile) as ptz:
        for pan, tilt, zoom in TARGETS:
            t = ptz.set_target(*_rad(pan, tilt, zoom))
            assert ptz.wait_reached(timeout=20)
            assert ptz.query_position().units == (t.pan, t.tilt, t.zoom)
        s = ptz.stats()
        assert s["errors"] == 0 and s["unsolicited"] == 0 and s["completions"] >= len(TARGETS)
        assert s["transport"]["resets"] == 1 and s["transport"]["stale_replies"] == 0
        assert emu.state()["errors"] == 0
        caps = ptz.capabilities()
        assert caps.transport == "udp" and caps.move_modes == ("absolute",) and caps.move_status == "completion"


def test_lost_and_garbled_datagrams_are_retried_and_counted():
    profile = quick_profile("visca", ack_timeout_s=0.3, max_silent=10)
    faults = Faults(drop=0.2, garble=0.1, noise=0.1)
    with UdpEmulator(profile, faults=faults, seed=3) as emu, make_driver(_url(emu), profile).connect(10) as ptz:
        for pan, tilt, zoom in TARGETS:
            ptz.set_target(*_rad(pan, tilt, zoom))
            assert ptz.wait_reached(timeout=30)
        t = ptz.stats()["transport"]
        assert t["retries"] > 0
        assert t["malformed_datagrams"] + ptz.stats()["garbage_bytes"] + ptz.stats()["unsolicited"] > 0


def test_sequence_error_resets_and_resends():
    profile = quick_profile("visca")
    with UdpEmulator(profile) as emu, make_driver(_url(emu), profile) as ptz:
        with emu._lock:
            emu.ip.last_seq = 10 ** 6  # the camera still expects a later number (e.g. another controller's)
        ptz.set_target(*_rad(40.0, 10.0, 3.0))
        assert ptz.wait_reached(timeout=20)
        t = ptz.stats()["transport"]
        assert t["sequence_errors"] >= 1 and t["resets"] >= 2


def test_camera_vanishing_and_coming_back_reconnects():
    profile = quick_profile("visca", ack_timeout_s=0.2)
    emu = UdpEmulator(profile).start()
    port = emu.address[1]
    ptz = make_driver(_url(emu), profile).connect(10)
    try:
        ptz.set_target(*_rad(10.0, 0.0, 2.0))
        assert ptz.wait_reached(timeout=20)
        emu.close()
        ptz.set_target(*_rad(-50.0, 5.0, 6.0))
        assert wait_for(lambda: not ptz.connected, timeout=20)
        time.sleep(0.3)
        emu = UdpEmulator(profile, ("127.0.0.1", port)).start()
        assert ptz.wait_reached(timeout=20)
        c = ptz.counters
        assert c["reconnects"] == 1 and c["errors"] >= 1
    finally:
        ptz.disconnect()
        emu.close()


def test_stray_datagrams_to_the_driver_are_counted_not_fatal():
    profile = quick_profile("visca")
    with UdpEmulator(profile) as emu, make_driver(_url(emu), profile) as ptz:
        port = ptz._conn.port
        for data in (b"", b"\x01", vip.frame(vip.REPLY, 999_999, visca.ack(1, 1)), bytes(range(40)),
                     vip.frame(vip.CONTROL_REPLY, 1, b"\x0f\x09")):
            port._take(data)
        t = ptz.stats()["transport"]
        assert t["stale_replies"] == 1 and t["malformed_datagrams"] == 4
        ptz.set_target(*_rad(20.0, 0.0, 2.0))
        assert ptz.wait_reached(timeout=20)


def test_a_pelco_profile_over_visca_udp_is_refused():
    with pytest.raises(PtzPortError, match="carries visca"):
        make_driver("visca-udp://127.0.0.1", quick_profile("pelco-d"))


# -- the command line -----------------------------------------------------------------------


def test_cli_emulator_prints_its_address_and_serves_the_ptz_command(tmp_path, capsys):
    proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", "ptz-emulator", "--protocol", "visca-ip",
                             "--listen", "127.0.0.1:0", "--state-file", str(tmp_path / "s.json")],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
    try:
        line = proc.stdout.readline().strip()
        assert line.startswith("udp://127.0.0.1:")
        url = "visca-udp://" + line.removeprefix("udp://")
        assert main(["ptz", "--ptz", url, "--pan-deg", "25", "--tilt-deg", "-5", "--zoom", "2", "--json"]) == 0
        assert '"reached": true' in capsys.readouterr().out
        # a malformed datagram does not stop it
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(b"\x00" * 30, ("127.0.0.1", int(line.rsplit(":", 1)[1])))
        assert main(["ptz", "--ptz", url]) == 0
        assert proc.poll() is None
    finally:
        proc.terminate()
        assert proc.wait(10) == 0


@pytest.mark.parametrize("argv, message", [
    (["ptz-emulator", "--protocol", "visca-ip", "--listen", "nowhere"], "--listen: expected HOST:PORT"),
    (["ptz-emulator", "--protocol", "visca", "--listen", "127.0.0.1:0"], "--listen: only for --protocol visca-ip"),
    (["ptz", "--ptz", "visca-udp://127.0.0.1:1:2"], "--ptz: "),
    (["ptz", "--ptz", "visca-udp://127.0.0.1", "--protocol", "pelco-d"], "carries visca"),
])
def test_cli_bad_input_is_one_line_and_exit_2(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_an_idle_driver_notices_a_silent_camera_by_its_keep_alive():
    """UDP has no connection: with nothing to send, the port's keep-alive inquiry finds the camera gone."""
    profile = quick_profile("visca", ack_timeout_s=0.2)
    emu = UdpEmulator(profile).start()
    ptz = make_driver(_url(emu), profile).connect(10)
    try:
        ptz.set_target(*_rad(10.0, 0.0, 2.0))
        assert ptz.wait_reached(timeout=20)
        assert wait_for(lambda: ptz.stats()["transport"]["keepalives"] >= 1, timeout=20)
        assert ptz.stats()["unsolicited"] == 0  # the port keeps the keep-alive's answers
        emu.faults = Faults(drop=1.0)  # the camera stops answering (no ICMP either, as when its cable is pulled)
        t0 = time.monotonic()
        assert wait_for(lambda: not ptz.connected, timeout=20)
        assert time.monotonic() - t0 < 10  # not the 10 s completion time-out
    finally:
        ptz.disconnect()
        emu.close()


def test_only_the_newest_unanswered_packet_is_sent_again():
    """A retry under a number below one already sent would be a sequence error at the camera."""
    from tests.runtime.ptz.fuzz_ip import _ResetAnswerer

    answerer = _ResetAnswerer()  # answers RESET only: every other packet stays unanswered
    port = vip.ViscaIpPort("127.0.0.1", answerer.port, timeout=0.01, ack_timeout_s=0.1)
    try:
        port.write(visca.zoom_position_inquiry(1))
        port.write(visca.pan_tilt_position_inquiry(1))
        first, second = list(port._outstanding)
        time.sleep(0.05)
        port._retry_due()
        assert list(port._outstanding) == [second] and port.counters["retries"] == 1
        assert port._outstanding[second].tries == 2 and first not in port._outstanding
    finally:
        port.close()
        answerer.close()
