"""Network video through OpenCV's FFmpeg: an MJPEG-over-HTTP stream this test serves on 127.0.0.1
(a port the OS picks), read in order, dropped part-way and reconnected (counted)."""

from __future__ import annotations

import itertools
import time

import numpy as np
import pytest

from runtime.cli import main
from runtime.frames import NetworkSource, SourceError, _redact, open_source
from tests.runtime.mjpeg import MjpegServer, free_port


def _number(img) -> int:
    return int(round(float(img[:16, :16].mean())))


def test_stream_is_read_in_order():
    with MjpegServer(fps=50) as srv:
        source = open_source(srv.url)
        assert isinstance(source, NetworkSource) and source.live
        try:
            got = [_number(img) for img in itertools.islice(source.frames(), 20)]
        finally:
            source.close()
    assert got == list(range(20))  # JPEG keeps a flat 16x16 block exact to within rounding


def test_stream_drop_is_reconnected_and_counted():
    with MjpegServer(fps=50) as srv:
        source = NetworkSource(srv.url, backoff_s=(0.05, 0.2))
        frames = source.frames()
        try:
            assert [_number(next(frames)) for _ in range(5)] == list(range(5))
            srv.drop(0.5)
            t0 = time.monotonic()
            broken = 0
            while (img := next(frames)) is None or _number(img) > 3:  # a new stream starts at frame 0
                broken += img is None
                assert time.monotonic() - t0 < 20
        finally:
            source.close()
    c = source.counters
    assert broken == 1, (broken, c)
    assert c["reconnects"] == 1 and c["drops"] == 1 and c["failed_opens"] >= 1 and c["outage_s"] >= 0.4, c
    assert srv.streams == 2, (srv.streams, c)


def test_a_stream_that_never_comes_back_ends():
    with MjpegServer(fps=50) as srv:
        source = NetworkSource(srv.url, backoff_s=(0.05, 0.1), give_up_s=0.5)
        frames = source.frames()
        next(frames)
        srv.drop(60)
        rest = list(itertools.islice(frames, 1000))
    assert rest[-1] is None and len(rest) < 1000 and source.counters["reconnects"] == 0


def test_nothing_listening_is_a_one_line_source_error():
    url = f"http://user:secret@127.0.0.1:{free_port()}/stream.mjpg"
    with pytest.raises(SourceError, match="cannot open the stream") as exc:
        NetworkSource(url, open_timeout_s=1.0)
    assert "secret" not in str(exc.value) and "user:***@" in str(exc.value)
    assert _redact("rtsp://cam/x") == "rtsp://cam/x"


def test_run_on_an_unreachable_stream_is_exit_2(capsys, tmp_path):
    from tests.paths import ROOT

    url = f"http://127.0.0.1:{free_port()}/stream.mjpg"
    assert main(["run", url, "--config", str(ROOT / "configs" / "paper.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot open the stream" in err[0]


def test_a_live_stream_is_drained_and_the_loop_gets_the_newest_frame():
    """The way it was found, without the loop's weight: a stream at 25 fps whose parts are stamped; the
    capture starts, nothing takes a frame for 2 s (the loop starting up), then a consumer that works 60 ms
    per frame (slower than the stream) takes frames: each is the newest, under 2 frame periods after the
    server sent it, from the first one on (a few may be late by a period on a loaded machine; none by the
    seconds of a backlog); what arrived meanwhile is skipped and counted. A 1 s outage
    shows as a 1 s gap in the frames' arrival times and about 1 s of ``outage_s``."""
    from runtime.realtime.sources import Capture
    from tests.runtime.mjpeg import read_stamp

    period = 1 / 25
    with MjpegServer(fps=25, size=(320, 240), stamp=True) as srv:
        source = NetworkSource(srv.url, backoff_s=(0.05, 0.2))
        with Capture(source, paced=True) as cap:
            time.sleep(2.0)  # starting up: the stream is drained meanwhile, nothing piles up
            cap.begin()
            taken, dropped_at = [], None
            while len(taken) < 40 or (dropped_at is not None and time.monotonic() - dropped_at < 3.0):
                f = cap.get(timeout=5)
                assert f is not None
                t_taken = time.monotonic()
                if f.image is not None:
                    taken.append((f, t_taken, srv.sent[read_stamp(f.image)]))
                if len(taken) == 20 and dropped_at is None:
                    srv.drop(1.0)
                    dropped_at = time.monotonic()
                time.sleep(0.06)  # the loop's work on it
            counts = dict(cap.counts)
    assert counts["skipped_at_start"] >= 25  # what arrived while starting up was read and let go
    assert counts["dropped"] > 0
    # how old each frame was when taken, by the server's clock; on a quiet machine all are under 2 periods, on a
    # loaded one a thread waiting for a core delays a few by a period or two; a backlog is seconds (here 2 s)
    ages = np.array([t_taken - t_sent for _, t_taken, t_sent in taken])
    assert np.median(ages) < period and np.mean(ages < 2 * period) >= 0.9 and ages.max() < 0.5, ages
    arrived = np.array([f.t - t_sent for f, _, t_sent in taken])  # the arrival stamp: when its bytes came in
    assert (arrived >= 0).all() and np.median(arrived) < 0.01 and arrived.max() < 0.5, arrived
    arrivals = np.array([f.t for f, _, _ in taken])
    assert 0.9 < np.diff(arrivals).max() < 2.5
    assert 0.9 < source.counters["outage_s"] < 2.5 and source.counters["reconnects"] == 1


def test_an_outage_lasts_from_the_last_frame_to_the_next():
    """What a live source (camera or stream) counts: the time without frames, however late a failure is seen."""
    from runtime.frames import _Outages

    o = _Outages()
    o.failed(0.5)  # before any frame: from the failure
    o.frame(1.0)
    o.frame(1.04)
    o.failed(2.5)  # seen late (a read time-out): the outage began with the last frame
    o.failed(2.6)
    o.frame(6.04)
    o.failed(7.0)
    o.ended(9.0)  # never came back: 6.04 to 9.0
    assert o.counters["drops"] == 4
    assert o.counters["outage_s"] == pytest.approx(0.5 + 5.0 + 2.96)
