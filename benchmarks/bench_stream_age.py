"""How old is the frame the loop acts on, with a live network source? ``omnijax run http://...`` against a
local MJPEG server that stamps its parts (issue 24: "a live network source runs 5 s behind").

A :class:`tests.runtime.mjpeg.MjpegServer` on 127.0.0.1 (a port the OS picks; it stops by itself) serves
640x480 frames at 25 fps, each with its part number drawn into the image and the time it was sent kept
(``time.monotonic()``, the clock of ``log.jsonl``: same machine). ``omnijax run`` (a child process, the code
of ``--repo``) reads it with ``--record`` and no PTZ; after ``--run-s`` seconds of the loop running the
server drops the stream for ``--outage-s`` seconds, and ``--after-s`` seconds after it is back the run gets
SIGTERM. Each processed frame's part number is read back from ``omni.avi`` (the frames as processed, in the
order of ``log.jsonl``'s processed frames), and its age is when the loop acted on it (``t`` +
``age_ms`` of its log line; ``t`` alone where the log has no ``age_ms``: the code before issue 24) minus
when the server sent it. Prints one JSON object: the ages (ms, p50/p90/p99/max, first frame, by quarter
of the run), the largest gap between log lines' ``t`` (the outage as the log shows it), and the run's
``summary.json`` figures (``frame_age_ms``, ``latency_ms``, ``stream``).

    .venv/bin/python benchmarks/bench_stream_age.py [--repo PATH] [--run-s 20] [--outage-s 5] [--after-s 8]

Not a timing of the loop's speed: the figure is whether the loop acts on the newest frame (milliseconds)
or on a backlog (seconds).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.runtime.mjpeg import MjpegServer, read_stamp


def _image(size=(640, 480)) -> np.ndarray:
    w, h = size
    img = np.zeros((h, w, 3), np.uint8)
    img[..., 0] = np.linspace(40, 200, w, dtype=np.uint8)[None, :]
    img[..., 1] = np.linspace(40, 200, h, dtype=np.uint8)[:, None]
    img[..., 2] = 90
    return img


def _pct(a) -> dict:
    a = np.asarray(a, float)
    if not a.size:
        return {"n": 0}
    return {"n": int(a.size), "p50": float(np.median(a)), "p90": float(np.percentile(a, 90)),
            "p99": float(np.percentile(a, 99)), "max": float(a.max())}


def measure(repo: Path, run_s: float, outage_s: float, after_s: float, fps: float) -> dict:
    work = Path(tempfile.mkdtemp(prefix="stream-age-"))
    out = work / "run"
    env = {**os.environ, "PYTHONPATH": str(repo)}
    with MjpegServer(fps=fps, images=[_image()], stamp=True, lifetime_s=run_s + outage_s + after_s + 600) as server:
        proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", "run", server.url, "--config",
                                 str(repo / "configs" / "paper.toml"), "--out", str(out), "--no-video", "--quiet",
                                 "--record", "--background-frames", "30"], cwd=repo, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        t_launch = time.monotonic()
        started = dropped = None
        while proc.poll() is None:
            logs = list(work.glob(".run.partial-*/log.jsonl"))
            if started is None and logs and logs[0].stat().st_size > 0:
                started = time.monotonic()
            if started is not None and dropped is None and time.monotonic() - started > run_s:
                server.drop(outage_s)
                dropped = time.monotonic()
            if dropped is not None and time.monotonic() - dropped > outage_s + after_s:
                proc.send_signal(signal.SIGTERM)
                break
            time.sleep(0.05)
        _, stderr = proc.communicate(timeout=120)
        sent = list(server.sent)
    if proc.returncode != 0:
        raise SystemExit(f"omnijax run failed ({proc.returncode}): {stderr[-2000:]}")
    summary = json.loads((out / "summary.json").read_text())
    log = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    processed = [r for r in log if "fault" not in r]
    video = cv2.VideoCapture(str(out / "omni.avi"))
    parts = []
    while True:
        ok, img = video.read()
        if not ok:
            break
        parts.append(read_stamp(img))
    n = min(len(parts), len(processed))
    acted = np.array([r["t"] + r.get("age_ms", 0.0) / 1e3 for r in processed[:n]])
    ages = 1e3 * (acted - np.array([sent[k] for k in parts[:n]]))
    t = np.array([r["t"] for r in log])
    gaps = np.diff(t)
    quarters = np.array_split(ages, 4)
    return {
        "repo": str(repo), "fps": fps, "startup_s": None if started is None else started - t_launch,
        "run_s": run_s, "outage_s": outage_s, "after_s": after_s, "parts_sent": len(sent),
        "frames_processed": len(processed), "frames_recorded": len(parts),
        "age_ms": _pct(ages), "age_first_ms": float(ages[0]) if n else None,
        "age_by_quarter_ms_p50": [float(np.median(q)) if q.size else None for q in quarters],
        "log_largest_gap_s": float(gaps.max()) if gaps.size else None,
        "summary": {k: summary.get(k) for k in ("frames", "fps", "frame_age_ms", "latency_ms", "stream", "faults",
                                                 "stop_reason")},
        "load_before_after": None,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repo", type=Path, default=ROOT, help="the checkout whose omnijax runs (default: this one)")
    ap.add_argument("--run-s", type=float, default=20.0, help="seconds of the loop running before the outage")
    ap.add_argument("--outage-s", type=float, default=5.0, help="seconds the stream is down")
    ap.add_argument("--after-s", type=float, default=8.0, help="seconds after the outage before SIGTERM")
    ap.add_argument("--fps", type=float, default=25.0)
    args = ap.parse_args()
    load0 = os.getloadavg()
    result = measure(args.repo.resolve(), args.run_s, args.outage_s, args.after_s, args.fps)
    result["load_before_after"] = [load0, os.getloadavg()]
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
