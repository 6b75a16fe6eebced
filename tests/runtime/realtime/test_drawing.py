"""The drawing thread: it never holds up the control thread (a full queue skips and counts, and
lists which frames), it handles what it got in order, and a hook's failure is reported."""

from __future__ import annotations

import json
import threading
import time

import pytest

from runtime.realtime.drawing import OffPath


def _item(k):
    return {"record": {"frame": k}, "frame": k, "dets": None, "z": None, "tracks": [], "commands": [None],
            "status": {"frames": k}}


def test_a_stalled_hook_costs_the_control_thread_nothing(tmp_path):
    gate = threading.Event()
    seen = []

    def hook(record, frame, dets, z, tracks, commands, status):
        gate.wait(10)  # the drawing thread is stuck (a slow inset, a slow disk)
        seen.append(frame)
        return {"drawn": True}

    times = []
    off = OffPath(tmp_path / "log.jsonl", hook, lambda item: {}, lambda stage, t: time.monotonic(), size=4)
    for k in range(20):
        t0 = time.monotonic()
        off.submit(_item(k))
        times.append(time.monotonic() - t0)
    assert max(times) < 0.05  # never waited for the stuck hook
    # one item taken by the thread (stuck in the hook), four queued, the rest skipped
    assert off.skipped in (15, 16)
    assert off.skipped_frames == list(range(20 - off.skipped, 20))
    gate.set()
    off.close()
    assert seen == list(range(20 - off.skipped))
    lines = [json.loads(s) for s in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert [r["frame"] for r in lines] == seen and all(r["drawn"] for r in lines)
    assert off.summary()["skipped"] == off.skipped and off.summary()["done"] == len(seen)


def test_fault_records_are_logged_without_the_hooks(tmp_path):
    calls = []
    off = OffPath(tmp_path / "log.jsonl", lambda *a: calls.append(a), lambda item: {}, lambda s, t: t)
    off.submit({"record": {"frame": 3, "fault": "broken frame"}})
    off.close()
    assert calls == []
    assert json.loads((tmp_path / "log.jsonl").read_text()) == {"frame": 3, "fault": "broken frame"}


def test_a_failing_hook_is_reported_at_close(tmp_path):
    def hook(*_):
        raise ValueError("no codec")

    off = OffPath(tmp_path / "log.jsonl", hook, lambda item: {}, lambda s, t: t)
    off.submit(_item(0))
    off.submit(_item(1))
    for _ in range(200):
        if off.error is not None:
            break
        time.sleep(0.01)
    assert isinstance(off.error, ValueError)
    with pytest.raises(RuntimeError, match="drawing thread failed.*no codec"):
        off.close()
