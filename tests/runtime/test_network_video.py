"""Network video through OpenCV's FFmpeg: an MJPEG-over-HTTP stream this test serves on 127.0.0.1
(a port the OS picks), read in order, dropped part-way and reconnected (counted)."""

from __future__ import annotations

import itertools
import time

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
    assert broken == 1
    c = source.counters
    assert c["reconnects"] == 1 and c["drops"] == 1 and c["failed_opens"] >= 1 and c["outage_s"] >= 0.4
    assert srv.streams == 2


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
