"""The operator's console against a running ``omnijax demo --serve`` (one run for the module, a child
process as users run it, with ``--mqtt`` to a real broker started here): the address line, the status
contract, the token, bad requests, choosing a target, pausing, pointing, zones into the running loop and
the rig file, the calibration assistant, the events on MQTT, and, where Chromium is installed, the page
in a real headless browser. The demo's scenario and rig are copies, so that the zones the tests save
never touch configs/.

With ``OMNIJAX_SCREENSHOTS=DIR`` the browser tests save what the page shows into DIR (console_live.png,
console_zone.png, console_calibration.png: the pictures of docs/console.md); without it they save nothing.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from runtime.cli import main
from tests.paths import CONFIGS, ROOT
from tests.runtime.console.broker import Broker, Subscriber

CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
POSTS = ("/api/target", "/api/zones", "/api/point", "/api/ptz", "/api/release", "/api/pause", "/api/home",
         "/api/calibration/mark", "/api/calibration/clear", "/api/calibration/fit")


@dataclass
class Demo:
    proc: subprocess.Popen
    base: str
    token: str
    out: Path
    rig: Path
    stderr: list
    subscriber: Subscriber


def call(demo: Demo, method: str, path: str, body=None, token: str | None = "", raw: bytes | None = None):
    """(HTTP status, parsed JSON body); ``token`` "" means the demo's own, ``None`` none."""
    data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
    req = urllib.request.Request(demo.base + path.lstrip("/"), data=data, method=method)
    if token is not None:
        req.add_header("Authorization", f"Bearer {token or demo.token}")
    try:
        with urllib.request.urlopen(req, timeout=120) as res:
            return res.status, json.loads(res.read() or b"null")
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read() or b"null")


def status(demo: Demo) -> dict:
    code, body = call(demo, "GET", "/api/status")
    assert code == 200
    return body


def wait_for(predicate, timeout: float = 20.0, every: float = 0.1):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got = predicate()
        if got:
            return got
        time.sleep(every)
    return None


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    folder = tmp_path_factory.mktemp("console")
    shutil.copy(CONFIGS / "paper.toml", folder / "paper.toml")
    # at 10 fps, not 25: the module's tests wait on the loop's answers, not on its rate, and the demo
    # running live all through the module would otherwise take most of a core from the other worker
    scenario = (CONFIGS / "scenarios" / "three_people.toml").read_text()
    assert 'rig = "../paper.toml"' in scenario and "\nfps = 25.0\n" in scenario
    scenario = scenario.replace('rig = "../paper.toml"', 'rig = "paper.toml"')
    scenario = scenario.replace("\nfps = 25.0\n", "\nfps = 10.0\n")
    (folder / "three_people.toml").write_text(scenario)
    out = folder / "out"
    with Broker() as broker:
        subscriber = Subscriber(broker.port, "test/console/#")
        proc = subprocess.Popen(
            [sys.executable, "-m", "runtime.cli", "demo", "--scenario", str(folder / "three_people.toml"),
             "--out", str(out), "--frames", "30000", "--background-seconds", "0", "--inset-every", "4", "--quiet",
             "--max-seconds", "900", "--serve", "127.0.0.1:0", "--mqtt", f"{broker.url}/test/console"],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        lines: list[str] = []
        threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True).start()
        line = wait_for(lambda: next((x for x in lines if x.startswith("serving ")), None), 120)
        assert line, "".join(lines)[-2000:]
        m = re.fullmatch(r"serving (http://127\.0\.0\.1:\d+/)\?token=(\S+)\n", line)
        assert m, line
        d = Demo(proc, m.group(1), m.group(2), out, folder / "paper.toml", lines, subscriber)
        assert wait_for(lambda: proc.poll() is None and status(d)["frames"] > 25, 400, 0.5), "".join(lines)[-2000:]
        yield d
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            proc.wait(60)
        subscriber.close()


def test_bad_serve_address_or_port_in_use_is_one_line_and_exit_2(capsys, tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        for spec, expected in (("nonsense", "expected HOST:PORT"), ("127.0.0.1:70000", "expected HOST:PORT"),
                               (f"127.0.0.1:{port}", "in use"), ("[::1:80", "expected HOST:PORT")):
            assert main(["demo", "--out", str(tmp_path / "x"), "--serve", spec]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and err[0].startswith("omnijax demo: error: --serve") and expected in err[0], err
    assert main(["demo", "--out", str(tmp_path / "x"), "--mqtt", "http://broker"]) == 2
    assert "--mqtt: expected mqtt://" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_status_contract(demo):
    s = status(demo)
    assert {"frames", "fps", "latency_ms", "tracks", "target", "ptz"} <= set(s) and not s["starting"]
    assert s["frames"] > 0 and s["fps"] > 0 and set(s["latency_ms"]) == {"p50", "p99"}
    for tr in s["tracks"]:
        assert isinstance(tr["id"], int) and len(tr["xy"]) == 2 and len(tr["px"]) == 2
    assert s["ptz"]["p_contain"] == 0.99 and s["ptz"]["link"]["connected"]
    assert s["target"] is None or isinstance(s["target"], int)
    for which in ("omni", "ptz"):
        with urllib.request.urlopen(f"{demo.base}api/view/{which}.jpg", timeout=30) as res:
            assert res.headers["Content-Type"] == "image/jpeg" and res.read(2) == b"\xff\xd8"
    with urllib.request.urlopen(demo.base, timeout=30) as res:
        assert b"omnijax" in res.read()


@pytest.mark.parametrize("path", POSTS)
def test_changes_need_the_token(demo, path):
    for token in (None, "not-the-token"):
        code, body = call(demo, "POST", path, {"track": None}, token=token)
        assert code == 401 and "Bearer" in body["error"]


def test_bad_requests_get_a_clear_4xx_and_the_loop_goes_on(demo):
    before = status(demo)["frames"]
    square = [[10, 10], [60, 10], [60, 60], [10, 60]]
    cases = [
        ("/api/target", None, b"{not json", 400, "malformed JSON"),
        ("/api/target", ["track", 1], None, 400, "expected a JSON object"),
        ("/api/target", {"track": "one"}, None, 400, "track: expected a track id"),
        ("/api/target", {"track": 10**9}, None, 404, "no track"),
        ("/api/zones", {"zones": [{"kind": "ignore", "points": [[0, 0], [99, 99], [99, 0], [0, 99]]}]}, None, 422,
         "zones.0.points: edges 0-1 and 2-3 cross"),
        ("/api/zones", {"zones": [{"kind": "ignore", "points": [[600, 400], [900, 400], [650, 470]]}]}, None, 422,
         "outside the 640x480"),
        ("/api/zones", {"zones": [{"kind": "mask", "points": square}]}, None, 422, "zones.0.kind"),
        ("/api/zones", {"zone": []}, None, 400, "expected"),
        ("/api/point", {"x": -5, "y": 10}, None, 400, "outside the 640x480"),
        ("/api/pause", {"paused": "yes"}, None, 400, "paused"),
        ("/api/ptz", {"pan_deg": float("nan")}, None, 400, "finite"),
    ]
    for path, body, raw, code, expected in cases:
        got, answer = call(demo, "POST", path, body, raw=raw)
        assert got == code and expected in answer["error"] and "\n" not in answer["error"], (path, answer)
    assert wait_for(lambda: status(demo)["frames"] > before + 10)  # still running
    assert demo.proc.poll() is None


def test_choosing_a_person_makes_them_the_target(demo):
    def chosen():
        s = status(demo)
        picks = [tr["id"] for tr in s["tracks"] if tr["framable"] and tr["id"] != s["target"]]
        if not picks:
            return None
        assert call(demo, "POST", "/api/target", {"track": picks[0]})[0] in (200, 404)  # 404: gone meanwhile
        return wait_for(lambda: status(demo)["target"] == picks[0] and status(demo)["operator"]["target"] == picks[0],
                        10)

    assert wait_for(chosen, 60, 0.5)
    assert status(demo)["operator"]["target"] is not None
    code, body = call(demo, "POST", "/api/target", {"track": None})
    assert code == 200 and body["target"] is None
    assert wait_for(lambda: status(demo)["operator"]["target"] is None, 10)


def test_pause_point_home_and_release(demo):
    assert call(demo, "POST", "/api/pause", {"paused": True})[0] == 200
    assert wait_for(lambda: (s := status(demo))["operator"]["paused"] and s["target"] is None, 10)
    assert call(demo, "POST", "/api/pause", {"paused": False})[0] == 200
    cx, cy = 320 + 80, 240
    code, aim = call(demo, "POST", "/api/point", {"x": cx, "y": cy, "seconds": 60})
    assert code == 200 and -180 <= aim["pan_deg"] <= 180 and aim["zoom"] >= 1
    assert wait_for(lambda: (s := status(demo))["manual"] and s["target"] is None
                    and abs(s["ptz"]["pan_deg"] - aim["pan_deg"]) < 1e-2, 10)
    code, home = call(demo, "POST", "/api/home", {"seconds": 60})
    assert code == 200 and (home["pan_deg"], home["tilt_deg"], home["zoom"]) == (0.0, 0.0, 1.0)
    assert wait_for(lambda: (p := status(demo)["ptz"])["pan_deg"] == 0.0 and p["zoom"] == 1.0, 10)
    assert call(demo, "POST", "/api/release")[0] == 200
    assert wait_for(lambda: not status(demo)["manual"] and status(demo)["operator"]["point"] is None, 10)


def test_zones_go_into_the_running_loop_and_the_rig_file(demo):
    from runtime.files import load_rig

    zones = [{"kind": "ignore", "points": [[20, 20], [90, 20], [90, 80], [20, 80]], "name": "screen"},
             {"kind": "priority", "points": [[500, 380], [600, 380], [600, 460]]}]
    code, body = call(demo, "POST", "/api/zones", {"zones": zones})
    assert code == 200 and body["saved"] == str(demo.rig) and body["zones"] == [
        {**z, "points": [[float(x), float(y)] for x, y in z["points"]]} for z in zones]
    rig = load_rig(demo.rig)
    assert [z.as_dict() for z in rig.zones] == body["zones"]
    assert "# The paper's rig" in demo.rig.read_text()  # comments kept
    code, got = call(demo, "GET", "/api/zones")
    assert got["zones"] == body["zones"] and got["version"] == body["version"]
    assert wait_for(lambda: status(demo)["zones_version"] == body["version"], 120, 0.5)  # the detector took them
    assert call(demo, "GET", "/api/zones")[1]["applied"]
    assert call(demo, "POST", "/api/zones", {"zones": []})[0] == 200
    assert load_rig(demo.rig).zones == ()


@pytest.mark.slow
def test_calibration_assistant_records_aims_and_fits_the_rig(demo):
    """Drive the PTZ onto marks (the rig's own pointing at each mark, as an operator would by eye), click
    each mark's foot: the assistant reads the PTZ back, writes observations.json and runs the fit."""
    import jax.numpy as jnp

    from omnijax import pointing, world_to_image
    from runtime.files import load_rig

    rig = load_rig(demo.rig)
    try:
        assert call(demo, "POST", "/api/calibration/clear")[0] == 200
        marks = [(-1.0, -1.5), (-1.0, 1.8), (-2.5, 2.2), (-3.2, -0.6)]  # spread, within the PTZ's tilt range
        for X, Y in marks:
            x, y = (float(v) for v in world_to_image(rig.omni, X, Y, 0.0))
            r, theta = (float(v) for v in rig.omni.to_polar(x, y))
            for h in (0.0, 1.5):
                inputs = rig.input_mean(r, theta).at[7].set(h).at[8].set(0.0)  # aim at the mark: H_p - R_h = h
                p = pointing(jnp.asarray(inputs), rig.omni.profile)
                code, _ = call(demo, "POST", "/api/ptz", {"pan_deg": math.degrees(float(p.pan)),
                                                           "tilt_deg": math.degrees(float(p.tilt)), "zoom": 1.0,
                                                           "seconds": 300})
                assert code == 200
                code, obs = call(demo, "POST", "/api/calibration/mark", {"x": x, "y": y, "height_m": h})
                assert code == 200, obs
        assert len(obs["observations"]) == len(marks) and obs["aims"] == 2 * len(marks) and obs["ready"]
        code, report = call(demo, "POST", "/api/calibration/fit")
        assert code == 200 and report["error"] is None, report
        params = report["result"]["params"]
        assert {"H_o", "D_c", "theta_c", "H_f", "pan_zero", "tilt_zero"} <= set(params)
        assert all(p["sigma"] > 0 for p in params.values())
        assert abs(params["H_o"]["value"] - float(rig.omni.H_o)) < 0.2
        assert len(report["result"]["residuals_deg"]["pan"]) == 2 * len(marks)
        # written into the run's staging folder (renamed to --out when the run ends: docs/runtime.md)
        stage = demo.out.parent / f".{demo.out.name}.partial-{demo.proc.pid}"
        assert (stage / "calibration" / "observations.json").is_file()
        # a mark below the PTZ's lowest tilt: it stops at its limit, not on the mark; refused, nothing added
        code, _ = call(demo, "POST", "/api/ptz", {"pan_deg": 10.0, "tilt_deg": -85.0, "zoom": 1.0, "seconds": 300})
        assert code == 200
        code, body = call(demo, "POST", "/api/calibration/mark", {"x": 330.0, "y": 250.0, "height_m": 0.0})
        assert code == 422 and "the PTZ stands at its tilt limit" in body["error"], body
        assert call(demo, "GET", "/api/calibration")[1]["aims"] == 2 * len(marks)
    finally:  # the manual pointing must not outlive the test, whatever failed
        assert call(demo, "POST", "/api/release")[0] == 200


def test_events_reach_the_broker(demo):
    got = demo.subscriber.wait_for(lambda m: m[0] == "test/console/events/person_appeared", 60)
    assert got and {"event", "track", "xy", "frame", "t", "time"} <= set(got[0][1])
    assert demo.subscriber.wait_for(lambda m: m[0] == "test/console/status" and m[1] == "online", 5)
    code, events = call(demo, "GET", "/api/events")
    assert code == 200 and any(e["event"] == "person_appeared" for e in events["events"])


# -- in a real browser -----------------------------------------------------------------------


@pytest.fixture(scope="module")
def browser(demo, tmp_path_factory):
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        pytest.skip("no browser: install Chromium and its driver to run the console's browser tests "
                    "(apt-get install chromium chromium-driver)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for arg in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--disable-dev-shm-usage", "--window-size=1400,1000",
                f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    driver.set_page_load_timeout(60)
    driver.get(f"{demo.base}?token={demo.token}")
    assert wait_for(lambda: driver.find_element("id", "conn").text == "live"
                    and driver.execute_script("return document.getElementById('overlay').width") == 640, 60)
    yield driver
    driver.quit()


def _screenshot(browser, name: str) -> None:
    """Save the browser's window as DIR/name when OMNIJAX_SCREENSHOTS=DIR is set (else nothing)."""
    folder = os.environ.get("OMNIJAX_SCREENSHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        assert browser.save_screenshot(str(Path(folder) / name)), name


def _click_image(browser, x: float, y: float) -> None:
    """Click the omni image at pixel (x, y) (the overlay canvas over it, scaled as shown)."""
    from selenium.webdriver.common.action_chains import ActionChains

    canvas = browser.find_element("id", "overlay")
    w, h = canvas.size["width"], canvas.size["height"]
    dx, dy = x * w / 640 - w / 2, y * h / 480 - h / 2  # from the element's centre
    ActionChains(browser).move_to_element_with_offset(canvas, dx, dy).click().perform()


def test_browser_click_on_a_person_makes_them_the_target(demo, browser):
    browser.find_element("id", "mode-select").click()

    def clicked():
        before = {tr["id"] for tr in status(demo)["tracks"]}
        time.sleep(0.6)  # the page polls the status too: click only tracks it has seen
        s = status(demo)
        picks = [tr for tr in s["tracks"] if tr["framable"] and tr["id"] in before and tr["id"] != s["target"]]
        if not picks:
            return None
        tr = picks[-1]  # the newest: not the one the round-robin would choose next anyway
        _click_image(browser, *tr["px"])
        done = wait_for(lambda: status(demo)["operator"]["target"] == tr["id"]
                        and browser.find_element("id", "status-target").text == str(tr["id"]), 10)
        if not done:  # gone meanwhile, or the click fell on the floor (a manual pointing): try another
            call(demo, "POST", "/api/release")
        return done

    assert wait_for(clicked, 120, 0.5)
    time.sleep(1.0)  # a fresh omni image with the target bracketed
    _screenshot(browser, "console_live.png")
    browser.find_element("id", "auto").click()
    assert wait_for(lambda: status(demo)["operator"]["target"] is None, 10)


def test_browser_draws_an_ignore_zone(demo, browser):
    from runtime.files import load_rig

    browser.find_element("id", "mode-ignore").click()
    corners = [(40, 400), (140, 400), (140, 460), (40, 460)]
    for x, y in corners:
        _click_image(browser, x, y)
    browser.find_element("id", "zone-name").send_keys("door")
    browser.find_element("id", "zone-finish").click()

    def saved():
        zones = call(demo, "GET", "/api/zones")[1]["zones"]
        return zones if len(zones) == 1 else None

    zones = wait_for(saved, 20)
    assert zones and zones[0]["kind"] == "ignore" and zones[0]["name"] == "door"
    assert np.allclose(zones[0]["points"], corners, atol=2.0)
    assert [z.kind for z in load_rig(demo.rig).zones] == ["ignore"]
    assert wait_for(lambda: "door" in browser.find_element("id", "zones-list").text, 10)
    _screenshot(browser, "console_zone.png")
    browser.find_element("id", "mode-select").click()


def test_browser_calibration_assistant_drives_the_ptz_and_records_a_mark(demo, browser):
    """Calibrate mode: an arrow key turns the PTZ (a manual pointing, 1 deg), a click on the omni image
    records the PTZ's position as an aim at the mark there, at the height typed in."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    before = call(demo, "GET", "/api/calibration")[1]["aims"]
    browser.find_element("id", "mode-calibrate").click()
    assert browser.find_element("id", "calibration").get_attribute("open") is not None
    pan = status(demo)["ptz"]["pan_deg"]
    ActionChains(browser).send_keys(Keys.ARROW_RIGHT).perform()
    assert wait_for(lambda: (s := status(demo))["manual"] and abs(s["ptz"]["pan_deg"] - pan) > 0.5, 10)
    height = browser.find_element("id", "cal-height")
    height.clear()
    height.send_keys("1.5")
    _click_image(browser, 250, 300)
    cal = wait_for(lambda: (c := call(demo, "GET", "/api/calibration")[1])["aims"] == before + 1 and c, 20)
    assert cal and any(a["height_m"] == 1.5 for p in cal["observations"] for a in p["aims"])
    assert wait_for(lambda: "1.5: " in browser.find_element("id", "cal-table").text, 10)
    browser.execute_script("document.getElementById('calibration').scrollIntoView()")
    _screenshot(browser, "console_calibration.png")
    browser.find_element("id", "mode-select").click()
    assert call(demo, "POST", "/api/release")[0] == 200


# -- last: the run ends -----------------------------------------------------------------------


def test_sigterm_ends_the_run_and_everything_is_written(demo):
    assert demo.proc.poll() is None and not status(demo)["starting"]  # the loop is running
    demo.proc.send_signal(signal.SIGTERM)
    assert demo.proc.wait(120) == 0, "".join(demo.stderr)[-2000:]
    s = json.loads((demo.out / "summary.json").read_text())
    events = [json.loads(line) for line in (demo.out / "events.jsonl").read_text().splitlines()]
    counts = {k: sum(e["event"] == k for e in events) for k in ("person_appeared", "face_captured", "person_left")}
    assert {k: s["events"][k] for k in counts} == counts and counts["person_appeared"] > 0
    assert all((demo.out / e["face"]).is_file() for e in events if e["event"] == "face_captured" and e["face"])
    assert s["events"]["mqtt"]["published"] == len(events)
    assert s["console"]["operator"] > 0 and s["counts"]["operator_frames"] == s["console"]["operator"]
    published = lambda: [m[1] for m in list(demo.subscriber.messages) if "/events/" in m[0]]
    assert wait_for(lambda: len(published()) == len(events), 10) and published() == events
