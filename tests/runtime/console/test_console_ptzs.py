"""The console with several PTZs, without a running loop: a snapshot as the drawing thread leaves it for
a rig of two PTZs; every PTZ's view is served, and a manual pointing names its PTZ."""

from __future__ import annotations

import json
import os
import sys
import threading
import urllib.error
import urllib.request
from types import SimpleNamespace

import numpy as np
import pytest

from omnijax.config import with_ptz_count
from runtime.console import Console
from runtime.console.live import Snapshot
from runtime.realtime.config import LoopConfig


def _call(console, method, path, body=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(console.url + path.lstrip("/"), data=data, method=method)
    req.add_header("Authorization", f"Bearer {console.token}")
    try:
        with urllib.request.urlopen(req, timeout=60) as res:
            raw = res.read()
            return res.status, raw if res.headers.get_content_type() == "image/jpeg" else json.loads(raw)
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


@pytest.fixture(scope="module")
def console(paper_rig):
    rig = with_ptz_count(paper_rig, 2)
    camera = {"pan_deg": 10.0, "tilt_deg": -20.0, "zoom": 2.0, "link": None}
    status = {"frames": 5, "tracks": [], "target": None, "ptz": camera, "zones_version": 0,
              "cameras": [{"id": k, "target": None, "view": f"PTZ {k}", **camera} for k in range(2)]}
    grey = np.full((48, 64, 3), 90, np.uint8)
    views = ((grey, "PTZ 0"), (None, "PTZ 1"))
    with Console("127.0.0.1:0") as c:
        c.rig, c.loop = rig, SimpleNamespace(cfg=LoopConfig(quiet=True))
        c.live = SimpleNamespace(snapshot=Snapshot(status=status, omni=grey, views=views, index=5),
                                 recent_events=list)
        yield c


def test_every_ptzs_view_is_served(console):
    for name in ("omni", "ptz", "ptz0"):
        code, body = _call(console, "GET", f"/api/view/{name}.jpg")
        assert code == 200 and body[:2] == b"\xff\xd8", name
    code, body = _call(console, "GET", "/api/view/ptz1.jpg")
    assert code == 404 and "no ptz1 image yet" in body["error"]
    code, body = _call(console, "GET", "/api/view/ptz2.jpg")
    assert code == 404 and "ptz0, ptz1" in body["error"]


def test_a_manual_pointing_names_its_ptz(console):
    cx, cy = (float(v) for v in console.rig.omni.center)
    code, body = _call(console, "POST", "/api/point", {"x": cx + 80.0, "y": cy + 60.0, "camera": 1})
    assert code == 200 and body["camera"] == 1 and console.operator.state.point_camera == 1
    # PTZ 1 stands on the other side of the room: it aims at the same floor point otherwise
    code0, body0 = _call(console, "POST", "/api/point", {"x": cx + 80.0, "y": cy + 60.0})
    assert code0 == 200 and body0["camera"] == 0
    assert abs(body0["pan_deg"] - body["pan_deg"]) > 1.0
    code, body = _call(console, "POST", "/api/ptz", {"dpan_deg": 5.0, "camera": 1})
    assert code == 200 and body["camera"] == 1 and body["pan_deg"] == pytest.approx(15.0)  # from where it was sent
    for bad in (2, -1, "1", True):
        code, body = _call(console, "POST", "/api/home", {"camera": bad})
        assert code == 400 and "camera: expected a PTZ number 0 to 1" in body["error"]
    code, body = _call(console, "POST", "/api/home", {"camera": 1})
    assert code == 200 and body["camera"] == 1 and body["pan_deg"] == 0.0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="a thread's own nice value is Linux's")
def test_the_consoles_threads_yield_the_cpu_to_the_control_thread(console):
    """The server's thread and the workers that encode its images run at NICE (the control thread at 0)."""
    from runtime.console.server import NICE

    assert _call(console, "GET", "/api/view/omni.jpg")[0] == 200  # a worker has encoded an image
    threads = [t for t in threading.enumerate() if t is console._thread or t.name.startswith("omnijax-console-work")]
    assert len(threads) >= 2
    assert {os.getpriority(os.PRIO_PROCESS, t.native_id) for t in threads} == {NICE}
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) < NICE


def test_a_10_mb_request_body_is_refused_in_one_line_and_nothing_changes(console):
    body = b'{"zones": [' + b" " * (10 * 2**20) + b"]}"
    req = urllib.request.Request(console.url + "api/zones", data=body, method="POST")
    req.add_header("Authorization", f"Bearer {console.token}")
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(req, timeout=60)
    assert err.value.code == 413
    assert json.loads(err.value.read()) == {"error": "request body too large: at most 1024 KiB (POST /api/zones)"}
    assert console.zones == () and console.zones_version == 0
    assert _call(console, "GET", "/api/view/omni.jpg")[0] == 200  # still serving
