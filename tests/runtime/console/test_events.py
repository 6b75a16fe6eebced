"""The event log and the same events on a real MQTT broker (amqtt, started here): a person appears
(trusted), has their face captured (the PTZ image saved), and leaves."""

from __future__ import annotations

import json
import logging
import time
from types import SimpleNamespace

import numpy as np
import pytest

from runtime.events import EventLog, MqttPublisher, parse_mqtt_url
from runtime.realtime.tracker import Track
from tests.runtime.console.broker import Broker, Subscriber, free_port


def _until(cond, timeout=10.0) -> bool:
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


def _frames(log, script, start=0):
    """Run ``log`` over frames start, start + 1, ... at 25 fps; ``script[k]`` is the list of tracks
    confirmed at frame start + k."""
    for k, tracks in enumerate(script, start):
        log(None, SimpleNamespace(index=k, stamp=k / 25), None, None, tracks, None, None)


def test_events_are_logged_and_published(tmp_path):
    walker = Track(id=3, x=np.array([1.0, 2.0, 0.0, 0.0]), P=np.eye(4), t=0.0)
    blob = Track(id=4, x=np.array([-1.0, 0.0, 0.0, 0.0]), P=np.eye(4), t=0.0)  # never trusted: no events
    face = np.full((48, 64, 3), 200, np.uint8)
    with Broker() as broker:
        sub = Subscriber(broker.port, "home/hall/#")
        mqtt = MqttPublisher(f"{broker.url}/home/hall").start()
        # connected first: what is queued while (re)connecting may overtake (see runtime/events/mqtt.py)
        assert _until(lambda: mqtt.connected)
        log = EventLog(tmp_path, face_image=lambda _track: face, sinks=(mqtt,))
        script = [[walker, blob]] * 5
        _frames(log, script[:2])
        walker.trusted = True
        _frames(log, script[2:], start=2)
        walker.captured = True
        _frames(log, [[walker, blob]] * 6 + [[blob]] * 40, start=5)
        got = sub.wait_for(lambda m: m[0] == "home/hall/events/person_left")
        status = sub.wait_for(lambda m: m[0] == "home/hall/status")
        mqtt.close()
        log.close()
        sub.close()
    events = [json.loads(line) for line in (tmp_path / "events.jsonl").read_text().splitlines()]
    assert [e["event"] for e in events] == ["person_appeared", "face_captured", "person_left"]
    assert all(e["track"] == 3 and e["xy"] == [1.0, 2.0] for e in events)
    assert events[1]["face"].startswith("faces/track3_") and (tmp_path / events[1]["face"]).stat().st_size > 0
    assert events[2]["t"] - events[1]["t"] > 1.0  # left after LEAVE_S without the track
    assert log.summary() == {"file": "events.jsonl", "person_appeared": 1, "face_captured": 1, "person_left": 1}
    assert len(log.faces) == 1 and log.faces[0][1][:2] == b"\xff\xd8"
    assert got and status and status[0][1] == "online"
    published = [m for m in sub.messages if "/events/" in m[0]]
    assert [m[1] for m in published] == events  # the same events, in order


@pytest.mark.parametrize("url, expected", [
    ("mqtt://broker.local", ("broker.local", 1883, "omnijax", False)),
    ("mqtts://u:p%40ss@10.0.0.2:9000/a/b", ("10.0.0.2", 9000, "a/b", True)),
])
def test_mqtt_urls(url, expected):
    u = parse_mqtt_url(url)
    assert (u.host, u.port, u.prefix, u.tls) == expected
    assert "p@ss" not in u.shown()


@pytest.mark.parametrize("url", ["http://x", "mqtt://", "mqtt://h:99999", "mqtt://h/a/#", "mqtt://h/?x=1"])
def test_bad_mqtt_urls_say_what_was_expected(url):
    with pytest.raises(ValueError, match="expected mqtt://"):
        parse_mqtt_url(url)


def test_latest_image_shows_the_newest_frame_of_a_second_video():
    """``run --ptz-video``: the PTZ camera's own video beside the loop, its newest frame shown (the last one
    while nothing new comes)."""
    import time

    from runtime.frames import Source
    from runtime.realtime.sources import LatestImage

    class Frames(Source):
        fps, name = 50.0, "ptz"

        def frames(self):
            for k in range(5):
                yield np.full((4, 6, 3), k, np.uint8)

    with LatestImage(Frames()) as view:
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and (view()[0] is None or view.image[0, 0, 0] != 4):
            time.sleep(0.02)
        assert view.image[0, 0, 0] == 4 and view()[0][0, 0, 0] == 4


def test_a_broker_down_at_the_start_or_gone_later_is_one_warning_each_and_events_go_on(caplog):
    """No broker at the start: one warning, publishing never raises nor waits; the broker comes up: the queued
    events arrive and one line says so; it goes away: one warning again."""
    port = free_port()
    caplog.set_level(logging.WARNING, logger="omnijax.events")
    mqtt = MqttPublisher(f"mqtt://127.0.0.1:{port}/hall").start()
    try:
        assert _until(lambda: mqtt.outages == 1, 10)
        t0 = time.monotonic()
        for k in range(5):
            mqtt({"event": "person_appeared", "track": k})
        assert time.monotonic() - t0 < 0.5 and not mqtt.connected
        time.sleep(1.5)  # a retry or two fail: still one warning
        said = lambda: [r.getMessage() for r in caplog.records if r.name == "omnijax.events"]
        down = said()
        assert len(down) == 1 and f"MQTT broker mqtt://127.0.0.1:{port}/hall unreachable" in down[0]
        assert "events.jsonl" in down[0] and "\n" not in down[0]
        with Broker(port) as broker:
            sub = Subscriber(broker.port, "hall/#")
            assert _until(lambda: mqtt.connected, 20)
            got = sub.wait_for(lambda m: m[0] == "hall/events/person_appeared" and m[1]["track"] == 4, 10)
            assert got and {m[1]["track"] for m in sub.messages if "/events/" in m[0]} == set(range(5))
            assert len(said()) == 2 and "connected again after" in said()[-1]
            sub.close()
        assert _until(lambda: mqtt.outages == 2, 20)
        assert len(said()) == 3 and f"{port}/hall lost (" in said()[-1]
        mqtt({"event": "person_left", "track": 4})  # gone: still no exception
        assert mqtt.summary()["outages"] == 2 and mqtt.published == 6
    finally:
        mqtt.close(timeout=0.5)
