"""The PTZ emulator as a child process (pseudo-terminal or network), for the demo and the tests.

:class:`EmulatorProcess` runs ``omnijax ptz-emulator`` with ``--state-file`` and, on a pty,
``--link`` (a stable path that follows the pty); over the network (``visca-ip``) it binds
127.0.0.1 and a free port, and a restart binds the same port again. :attr:`url` is what the
driver opens. :meth:`unplug` kills the emulator, so the port vanishes as when a USB adapter
is pulled (or the camera loses power), and starts a new one at the same address after a
delay, as when it is plugged back in.

The child never outlives this process: it runs in its own session (Ctrl-C in a terminal
reaches this process only), leaving the context manager in any way (an error, Ctrl-C,
SIGTERM) stops it, and it runs with ``--parent-pid`` set to this process, so that it stops by
itself within a fraction of a second if this process dies without cleaning up (SIGKILL).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from urllib.parse import urlsplit

from runtime.realtime.session import read_state


class EmulatorProcess:
    """``omnijax ptz-emulator`` in a child process (see the module docstring)."""

    def __init__(self, protocol: str = "visca", profile: str | None = None, folder: Path | None = None):
        self._tmp = None
        if folder is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="omnijax-ptz-")
            folder = Path(self._tmp.name)
        self.folder = Path(folder)
        self.link = self.folder / "ptz"
        self.state_file = self.folder / "ptz-state.json"
        self.protocol, self.profile = protocol, profile
        from runtime.ptz.transports import NETWORK_EMULATED

        self.network = protocol in NETWORK_EMULATED
        self.listen = "127.0.0.1:0"
        self.proc: subprocess.Popen | None = None
        self.unplugs = 0
        self._timer: threading.Timer | None = None
        self._lock = threading.Lock()

    def start(self) -> EmulatorProcess:
        """Start the emulator and wait for its pty (first line on its stdout)."""
        cmd = [sys.executable, "-m", "runtime.cli", "ptz-emulator", "--protocol", self.protocol,
               "--state-file", str(self.state_file), "--parent-pid", str(os.getpid())]
        cmd += ["--listen", self.listen] if self.network else ["--link", str(self.link)]
        if self.profile:
            cmd += ["--ptz-profile", self.profile]
        with self._lock:
            # its own session: Ctrl-C in the terminal reaches this process, which stops the child itself
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                         cwd=Path(__file__).resolve().parents[2], start_new_session=True)
            line = self.proc.stdout.readline().strip()
        if not line:
            raise RuntimeError(f"the PTZ emulator did not start (exit code {self.proc.poll()})")
        self.pty = line
        if self.network:  # a restart binds the same port, as a camera keeps its address
            self.listen = urlsplit(line).netloc
        return self

    @property
    def url(self) -> str:
        """What the driver opens: the pty's stable link, or ``visca-udp://HOST:PORT``."""
        from runtime.ptz.transports import emulator_url

        return emulator_url(self.protocol, self.pty) if self.network else str(self.link)

    def state(self, settle_s: float = 0.0) -> dict | None:
        """The emulated camera's state (``--state-file``); with ``settle_s``, the first that is not moving
        within that many seconds (the file is the child's view, written apart from its replies)."""
        deadline = time.monotonic() + settle_s
        state = read_state(self.state_file)
        while (state is None or state.get("moving")) and time.monotonic() < deadline:
            time.sleep(0.01)
            state = read_state(self.state_file)
        return state

    def kill(self) -> None:
        """Stop the emulator: its pty and link vanish."""
        with self._lock:
            if self.proc is not None and self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(5)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
            self.proc = None

    def unplug(self, seconds: float) -> None:
        """Kill the emulator now and start a new one on the same link after ``seconds`` (in a thread)."""
        self.kill()
        self.unplugs += 1
        self._timer = threading.Timer(seconds, self.start)
        self._timer.daemon = True
        self._timer.start()

    def close(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer.join()
        self.kill()
        if self._tmp is not None:
            self._tmp.cleanup()

    def __enter__(self) -> EmulatorProcess:
        try:
            return self.start()
        except BaseException:  # interrupted or failed while starting: no child is left behind
            self.close()
            raise

    def __exit__(self, *exc) -> None:
        self.close()
