"""``omnijax demo --serve 127.0.0.1:0`` as a child process, for the console's benchmarks: started, its
serving line read (address and token), its JSON API called, stopped with SIGTERM (or ended by itself).
The same way tests/runtime/console/test_console.py drives it."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


class ServedDemo:
    """``with ServedDemo(args, out) as d:`` runs ``omnijax demo --out OUT --serve 127.0.0.1:0 ARGS`` and
    waits (at most ``start_s``) until its loop has processed ``min_frames`` frames; leaving the block
    sends SIGTERM if it still runs and waits for the outputs. ``d.summary()`` reads summary.json."""

    def __init__(self, args: list[str], out: Path, min_frames: int = 25, start_s: float = 600.0,
                 prefix: list[str] | None = None):
        self.args, self.out, self.min_frames, self.start_s = list(args), Path(out), min_frames, start_s
        self.prefix = prefix or []
        self.lines: list[str] = []
        self.base = self.token = ""

    def __enter__(self) -> ServedDemo:
        cmd = [*self.prefix, sys.executable, "-m", "runtime.cli", "demo", "--out", str(self.out), "--quiet",
               "--serve", "127.0.0.1:0", *self.args]
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        threading.Thread(target=lambda: self.lines.extend(self.proc.stderr), daemon=True).start()
        deadline = time.monotonic() + self.start_s
        while time.monotonic() < deadline and self.proc.poll() is None:
            line = next((x for x in self.lines if x.startswith("serving ")), None)
            if line:
                m = re.fullmatch(r"serving (http://127\.0\.0\.1:\d+/)\?token=(\S+)\n", line)
                self.base, self.token = m.group(1), m.group(2)
                break
            time.sleep(0.1)
        while self.base and time.monotonic() < deadline and self.proc.poll() is None:
            if self.call("GET", "/api/status")[1].get("frames", 0) >= self.min_frames:
                return self
            time.sleep(0.5)
        self.stop()
        raise RuntimeError("the demo did not start: " + "".join(self.lines)[-1500:])

    def __exit__(self, *exc) -> None:
        self.stop()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(300)

    def wait(self, timeout: float) -> int:
        """The exit code once the demo ends by itself (within ``timeout`` s)."""
        return self.proc.wait(timeout)

    def call(self, method: str, path: str, body=None) -> tuple[int, dict]:
        """(HTTP status, JSON body) of an API request with the token."""
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path.lstrip("/"), data=data, method=method)
        req.add_header("Authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(req, timeout=300) as res:
                return res.status, json.loads(res.read() or b"null")
        except urllib.error.HTTPError as err:
            return err.code, json.loads(err.read() or b"null")

    def summary(self) -> dict:
        return json.loads((self.out / "summary.json").read_text())
