"""ONVIF: the emulator's SOAP service, WS-Security, the driver against the emulator (with quirks, auth,
the camera vanishing) and a small fixed-seed fuzz of both."""

from __future__ import annotations

import base64
import datetime as dt
import logging
import math
import time

import pytest

from runtime.bench.onvif_fuzz import REQUESTS, fuzz_driver, fuzz_emulator
from runtime.ptz import PtzError, PtzPortError, make_driver
from runtime.ptz.onvif import OnvifDriver, OnvifUrl, redact
from runtime.ptz.onvif_emulator import OnvifCamera, OnvifEmulator, OnvifService, parse_quirks
from runtime.ptz.onvif_soap import PASSWORD_DIGEST, SOAP12, TPTZ, TT, WSSE, WSU, envelope, password_digest
from runtime.ptz.profile import default_profile, parse_profile

PROFILE = default_profile("onvif")


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def service(user=None, password=None, quirks=()):
    clock = Clock()
    return OnvifService(OnvifCamera(PROFILE, 0.0, quirks), "http://127.0.0.1:1", user, password, clock=clock), clock


def call(svc, body: str, header: str = "") -> tuple[int, str]:
    data = envelope(body) if not header else envelope(body).replace(b"<s:Body>", f"<s:Header>{header}</s:Header>"
                                                                    "<s:Body>".encode())
    status, reply = svc.handle(data)
    return status, reply.decode()


def token(user: str, password: str, created: str | None = None, nonce: bytes = b"0123456789abcdef") -> str:
    created = created or dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    return (f'<wsse:Security xmlns:wsse="{WSSE}" xmlns:wsu="{WSU}"><wsse:UsernameToken>'
            f"<wsse:Username>{user}</wsse:Username>"
            f'<wsse:Password Type="{PASSWORD_DIGEST}">{password_digest(nonce, created, password)}</wsse:Password>'
            f"<wsse:Nonce>{base64.b64encode(nonce).decode()}</wsse:Nonce><wsu:Created>{created}</wsu:Created>"
            f"</wsse:UsernameToken></wsse:Security>")


ABSOLUTE = ('<tptz:AbsoluteMove><tptz:ProfileToken>profile_1</tptz:ProfileToken><tptz:Position>'
            '<tt:PanTilt x="0.5" y="1"/><tt:Zoom x="1"/></tptz:Position></tptz:AbsoluteMove>')
STATUS = "<tptz:GetStatus><tptz:ProfileToken>profile_1</tptz:ProfileToken></tptz:GetStatus>"


def test_profiles_carry_tokens_and_the_move_slews_at_the_profile_rate():
    svc, clock = service()
    status, reply = call(svc, "<trt:GetProfiles/>")
    assert status == 200 and 'Profiles token="profile_1"' in reply and 'PTZConfiguration token="ptz_config_1"' in reply
    assert call(svc, ABSOLUTE)[0] == 200
    # pan 0 -> +85 deg (x = 0.5 of [-170, 170]) at 100 deg/s; tilt 0 -> 90 deg at 90 deg/s: 1 s
    clock.t = 0.5
    reply = call(svc, STATUS)[1]
    assert 'x="0.294118"' in reply and "<tt:PanTilt>MOVING</tt:PanTilt>" in reply  # 50 deg of the half range 170
    clock.t = 2.5
    reply = call(svc, STATUS)[1]
    assert 'x="0.500000" y="1.000000"' in reply and "<tt:PanTilt>IDLE</tt:PanTilt><tt:Zoom>IDLE</tt:Zoom>" in reply


def test_unknown_operations_and_malformed_bodies_get_faults_not_exceptions():
    svc, _ = service()
    status, reply = call(svc, "<tptz:GetPresets><tptz:ProfileToken>profile_1</tptz:ProfileToken></tptz:GetPresets>")
    assert status == 500 and "ter:ActionNotSupported" in reply and f'xmlns:s="{SOAP12}"' in reply
    for body in (b"", b"<not-closed", b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e "x">]><x>&e;</x>',
                 b'<Envelope xmlns="http://schemas.xmlsoap.org/soap/envelope/"><Body/></Envelope>'):
        status, reply = svc.handle(body)
        assert status == 400 and b"<s:Fault>" in reply
    status, reply = call(svc, ABSOLUTE.replace('x="0.5"', 'x="nan"'))
    assert status == 400 and "ter:InvalidArgVal" in reply
    status, reply = call(svc, ABSOLUTE.replace("profile_1", "nope"))
    assert status == 400 and "ter:NoProfile" in reply
    assert svc.counts["faults"] == 7 and svc.counts["malformed"] == 6


def test_ws_security_digest_is_required_with_a_user():
    svc, _ = service("admin", "secret")
    assert "ter:NotAuthorized" in call(svc, STATUS)[1]
    assert "ter:NotAuthorized" in call(svc, STATUS, token("admin", "wrong"))[1]
    assert call(svc, STATUS, token("admin", "secret"))[0] == 200
    assert "nonce replayed" in call(svc, STATUS, token("admin", "secret"))[1]
    assert "ter:NotAuthorized" in call(svc, STATUS, token("admin", "secret", "2001-01-01T00:00:00Z", b"n2"))[1]
    assert svc.counts["unauthorised"] == 4
    assert call(svc, "<tds:GetSystemDateAndTime/>")[0] == 200  # pre-authentication, as ONVIF allows


def test_quirks_withdraw_the_move_modes_and_status():
    svc, _ = service(quirks=parse_quirks("relative-only,no-move-status"))
    status, reply = call(svc, ABSOLUTE)
    assert status == 500 and "not supported" in reply
    reply = call(svc, "<tptz:GetConfigurationOptions><tptz:ConfigurationToken>ptz_config_1"
                      "</tptz:ConfigurationToken></tptz:GetConfigurationOptions>")[1]
    assert "RelativePanTiltTranslationSpace" in reply and "AbsolutePanTiltPositionSpace" not in reply
    assert "MoveStatus" not in call(svc, STATUS)[1]
    with pytest.raises(ValueError, match="unknown quirk"):
        parse_quirks("no-such")


def test_urls_are_parsed_and_passwords_never_shown():
    assert OnvifUrl.parse("onvif://a%40b:p%3Aw@cam.local:8080") == OnvifUrl("cam.local", 8080, "a@b", "p:w")
    assert OnvifUrl.parse("onvif://10.0.0.5").port == 80
    for bad in ("onvif://", "onvif://host:", "onvif://host:99999", "onvif://host/onvif/device_service",
                "onvif://:pw@host"):
        with pytest.raises(PtzPortError):
            OnvifUrl.parse(bad)
    assert redact("onvif://admin:secret@h:1") == "onvif://admin:***@h:1"
    assert isinstance(make_driver("onvif://127.0.0.1:1", PROFILE), OnvifDriver)


@pytest.mark.parametrize("quirks, user, mode", [
    ((), "admin", "absolute"),
    (("relative-only", "no-move-status"), None, "relative"),
    (("continuous-only",), None, "continuous"),
    (("always-moving",), None, "absolute"),
])
def test_driver_reaches_targets_through_the_emulator(quirks, user, mode):
    with OnvifEmulator(PROFILE, user=user, password="pw" if user else None, quirks=quirks) as em:
        url = f"onvif://{user + ':pw@' if user else ''}127.0.0.1:{em.address[1]}"
        with OnvifDriver(url, PROFILE).connect(timeout=20) as d:
            assert d.discovered["mode"] == mode
            for pan, tilt, zoom in ((40, 20, 6), (-120, -10, 1.5)):
                t = d.set_target(math.radians(pan), math.radians(tilt), zoom)
                assert d.wait_reached(15), (pan, tilt, zoom, d.stats())
                deadline = time.monotonic() + 10
                while d.stats()["moving"] and time.monotonic() < deadline:  # continuous: until Stop is sent
                    time.sleep(0.05)
                # a continuous move is stopped within half a unit of the goal and coasts on for the Stop's
                # round trip at the (proportional, by then tiny) speed: 0.02 deg allowed there, one unit elsewhere
                tol = 2 if mode == "continuous" else 1
                st = em.state()["units"]
                assert max(abs(st[a] - getattr(t, a)) for a in ("pan", "tilt", "zoom")) <= tol, (st, t)
            assert d.counters["errors"] == 0
            assert d.take_writes(), "move requests are time-stamped for the frame-to-wire latency"


def test_wrong_password_is_bad_input_and_a_vanished_camera_is_reconnected(caplog):
    caplog.set_level(logging.CRITICAL)
    with OnvifEmulator(PROFILE, user="admin", password="pw") as em:
        with pytest.raises(PtzPortError, match="refused the user name or password"):
            OnvifDriver(f"onvif://admin:nope@127.0.0.1:{em.address[1]}", PROFILE).connect(timeout=5)
    em = OnvifEmulator(PROFILE).start()
    port = em.address[1]
    d = OnvifDriver(f"onvif://127.0.0.1:{port}", PROFILE).connect(timeout=20)
    try:
        d.set_target(0.3, 0.1, 2.0)
        assert d.wait_reached(10)
        em.close()  # the camera vanishes
        for _ in range(20):
            d.set_target(-0.3, 0.2, 3.0)  # the loop keeps setting targets: nothing raises
            time.sleep(0.05)
        with pytest.raises(PtzError):
            d.query_position()
        assert not d.connected and d.counters["errors"] >= 1
        em = OnvifEmulator(PROFILE, port=port).start()  # back on the same address
        assert d.wait_reached(15)
        assert d.counters["reconnects"] == 1
    finally:
        d.disconnect()
        em.close()


def test_fuzz_fixed_seed_no_exception_no_hang(caplog):
    """Fixed seed 0: 1500 mutated or random bodies to the service (600 with WS-Security on), and the
    driver against a camera mutating half its replies until 60 mutated replies were served."""
    caplog.set_level(logging.CRITICAL)
    assert len(REQUESTS) == 11
    for user, n in ((None, 1500), ("admin", 600)):
        r = fuzz_emulator(PROFILE, n, seed=0, user=user)
        assert (r.bodies, r.exceptions, r.hangs) == (n, 0, 0), r.examples
        assert r.statuses.get(400, 0) > n / 2  # most mutations are refused as the sender's fault
    r = fuzz_driver(PROFILE, 60, seed=0)
    assert r.exceptions == 0 and r.hangs == 0, r.examples
    assert r.statuses["malformed"] + r.statuses["faults"] > 0


def test_the_generic_spaces_span_the_profile_ranges():
    p = PROFILE
    assert p.from_normalised("pan", -1) == p.limits_units("pan")[0] and p.from_normalised("pan", 1) == 17000
    assert p.from_normalised("tilt", -1) == -3000 and p.from_normalised("tilt", 1) == 9000
    assert p.to_normalised("zoom", p.zoom.position[-1]) == 1.0
    for axis, units in (("pan", 1234.0), ("tilt", -250.0), ("zoom", 4321.0)):
        assert p.from_normalised(axis, p.to_normalised(axis, units)) == pytest.approx(units, abs=1e-9)
    with pytest.raises(ValueError, match="hundredths of a degree"):
        parse_profile({**p.model_dump(), "pan": {**p.pan.model_dump(), "units_per_deg": 14.4}})


def test_capabilities_say_how_a_quirky_camera_is_driven():
    with OnvifEmulator(PROFILE, quirks=("relative-only", "no-move-status")) as em:
        with OnvifDriver(f"onvif://127.0.0.1:{em.address[1]}", PROFILE).connect(timeout=20) as d:
            c = d.capabilities()
    assert (c.protocol, c.transport, c.move_modes, c.move_status, c.position) == (
        "onvif", "http", ("relative",), "timer", True)
    assert any("no AbsoluteMove" in n for n in c.notes)


def test_status_vector_names_are_the_schema_ones():
    # the driver reads tt:PanTilt/tt:Zoom in tt:Position; keep the emulator's namespaces the ONVIF ones
    assert TT == "http://www.onvif.org/ver10/schema" and TPTZ == "http://www.onvif.org/ver20/ptz/wsdl"


@pytest.mark.parametrize("args, expect", [
    (["--quirks", "fire"], "--quirks: unknown quirk 'fire'"),
    (["--user", "admin"], "--user, --password: give both"),
    (["--quirks", "relative-only,continuous-only"], "exclude each other"),
    (["--faults", "drop=0.1"], "use --quirks"),
    (["--listen", "127.0.0.1"], "--listen: expected HOST:PORT"),
])
def test_emulator_command_bad_input_is_one_line_exit_2(args, expect, capsys):
    from runtime.cli._main import main

    assert main(["ptz-emulator", "--protocol", "onvif", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0]


def test_ptz_command_wrong_password_is_one_line_exit_2_and_never_shows_it(capsys, caplog):
    from runtime.cli._main import main

    caplog.set_level(logging.CRITICAL)
    with OnvifEmulator(PROFILE, user="admin", password="s3cret") as em:
        url = f"onvif://admin:hunter2@127.0.0.1:{em.address[1]}"
        assert main(["ptz", "--ptz", url, "--timeout", "20"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "refused the user name or password" in err[0] and "hunter2" not in err[0]
        url = f"onvif://admin:s3cret@127.0.0.1:{em.address[1]}"
        assert main(["ptz", "--ptz", url, "--pan-deg", "10", "--tilt-deg", "5", "--zoom", "2", "--json"]) == 0
        out = capsys.readouterr().out
        assert '"reached": true' in out and "s3cret" not in out and "admin:***@" in out


class BadServer:
    """An HTTP server on 127.0.0.1 (a port the OS picks) that answers every POST with ``status``,
    ``content_type`` and ``body``: something at the ONVIF URL that is no ONVIF camera. Stops on leaving."""

    def __init__(self, status: int, content_type: str, body: bytes) -> None:
        import threading
        from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                return None

            def do_POST(self):
                self.rfile.read(int(self.headers.get("Content-Length", 0)))
                self.send_response(status)
                self.send_header("Content-Type", content_type)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                try:
                    self.wfile.write(body)
                except OSError:  # the client stopped reading (a capped body)
                    pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self.url = f"onvif://127.0.0.1:{self.httpd.server_address[1]}"
        self._thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)

    def __enter__(self) -> BadServer:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


BAD_REPLIES = [
    (500, "text/html", b"<html><body><h1>500 Internal Server Error</h1></body></html>",
     "GetServices got HTTP 500 (text/html, 60 bytes: '<html><body><h1>500 Internal Server Error</h1></body></html>')"),
    (200, "application/soap+xml", b"hello, this is not XML", "GetServices got HTTP 200 (application/soap+xml, "
                                                             "22 bytes: 'hello, this is not XML'): not XML"),
    (200, "application/soap+xml", b"<s:Envelope><s:Body></s:Envelope>", "malformed reply to GetServices"),
    (200, "application/soap+xml", b"<a>" + bytes(10 << 20) + b"</a>",
     "GetServices got HTTP 200 (application/soap+xml): a reply of more than 1024 KiB, not read further"),
]


@pytest.mark.parametrize("status, content_type, body, expect", BAD_REPLIES, ids=["500", "text", "xml", "10MB"])
def test_what_is_no_onvif_camera_is_one_line_naming_what_came_back(status, content_type, body, expect, caplog):
    """An HTTP error page, a body that is not XML, malformed XML or 10 MB: connect gives up at the first
    answer (not after its whole time-out), and its one line says what came back; the body is capped."""
    caplog.set_level(logging.DEBUG, logger="omnijax.ptz")
    with BadServer(status, content_type, body) as server:
        driver = OnvifDriver(server.url, PROFILE)
        t0 = time.monotonic()
        with pytest.raises(PtzError) as exc:
            driver.connect(timeout=60)
    assert time.monotonic() - t0 < 30
    assert str(exc.value).startswith(f"{server.url}: not an ONVIF PTZ camera: ") and expect in str(exc.value)
    assert len(str(exc.value)) < 400 and "\n" not in str(exc.value)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]  # nothing else said meanwhile


def test_run_against_an_http_500_is_one_line_and_exit_2(tmp_path):
    """``omnijax run --ptz onvif://`` to a server answering HTTP 500, as a user runs it: exit 2, one line on
    stderr formatted like every other (no raw ``WARNING:omnijax.ptz:`` lines from the ONVIF library's
    logging set-up)."""
    import subprocess
    import sys

    import cv2
    import numpy as np

    from tests.paths import CONFIGS, ROOT

    (tmp_path / "frames").mkdir()
    cv2.imwrite(str(tmp_path / "frames" / "0.png"), np.zeros((480, 640, 3), np.uint8))
    status, content_type, body, expect = BAD_REPLIES[0]
    with BadServer(status, content_type, body) as server:
        proc = subprocess.run([sys.executable, "-m", "runtime.cli", "run", str(tmp_path / "frames"), "--config",
                               str(CONFIGS / "paper.toml"), "--ptz", server.url, "--out", str(tmp_path / "out")],
                              cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("omnijax run: error: --ptz: ") and expect in err[0], proc.stderr
    assert not (tmp_path / "out").exists()


def test_warnings_are_lines_like_every_other_message(capsys, monkeypatch):
    """Under the command line, a warning reads ``omnijax run: warning: ...``, and a library's own
    ``logging.basicConfig`` (onvif-zeep-async's, on import) adds no second, raw handler."""
    from runtime.cli._main import log_lines

    monkeypatch.setattr(logging.getLogger(), "handlers", [])  # a process where nobody configured logging
    with log_lines("omnijax run"):
        logging.basicConfig(level=logging.INFO)
        assert len(logging.getLogger().handlers) == 1
        logging.getLogger("omnijax.ptz").warning("PTZ link lost on %s: %s; reconnecting", "onvif://h", "gone")
        logging.getLogger("omnijax.ptz").info("PTZ connected")
    assert capsys.readouterr().err == "omnijax run: warning: PTZ link lost on onvif://h: gone; reconnecting\n"
    assert logging.getLogger().handlers == []


def test_a_continuous_move_over_a_slow_link_ends_on_the_goal():
    """A continuous-only camera behind a slow link (every request 0.15 s late: the Stop too, so the camera
    coasts on after it was sent): the steering and the look after the Stop end within two units."""
    with OnvifEmulator(PROFILE, quirks=("continuous-only",), latency_s=0.15) as em:
        with OnvifDriver(f"onvif://127.0.0.1:{em.address[1]}", PROFILE).connect(timeout=20) as d:
            t = d.set_target(math.radians(40), math.radians(20), 6)
            assert d.wait_reached(30), d.stats()
            st = em.state()["units"]
            assert max(abs(st[a] - getattr(t, a)) for a in ("pan", "tilt", "zoom")) <= 2, (st, t)
