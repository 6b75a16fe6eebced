"""The console's calibration assistant: observations gathered by pointing, then ``omnijax calibrate``.

The operator drives the PTZ (the page's arrow keys: manual pointings) until its crosshair is on a mark,
then clicks the mark's foot in the omni image with the mark's height above the floor: :meth:`mark`
waits until the PTZ stands still, reads its position back (device degrees, as ``OBS.json`` wants them)
and adds an aim to the floor position clicked (a click within :data:`SAME_POSITION_PX` of an earlier
one adds to that position: the same pole, another height). A PTZ standing at a limit of its range
is refused: it stopped there, not on the mark (e.g. a floor mark below its lowest tilt). :meth:`fit`
writes ``observations.json`` (docs/calibration.md's format) and runs ``omnijax calibrate`` on it in a
child process, so that the fit never competes with the loop for the interpreter; its
``calibration.json`` (fitted values, sigmas, residuals) is what the page shows. Everything goes to
``calibration/`` of the run's output folder.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

#: Clicks closer than this (px) are the same floor position.
SAME_POSITION_PX = 6.0
#: Longest wait (s) for the loop to send the operator's latest pointing before the PTZ is read.
SENT_S = 5.0
#: The readings' sigmas written into observations.json (docs/calibration.md).
SIGMA_PTZ_DEG, SIGMA_HEIGHT_M = 0.1, 0.005


class CalibrationAssistant:
    """See the module docstring. ``driver``/``profile``: the loop's PTZ (``None``: no PTZ, nothing to read)."""

    def __init__(self, rig, rig_path: Path | None, folder: Path, driver=None, profile=None,
                 profile_spec: str | None = None, sent: Callable[[], bool] | None = None):
        self.rig, self.rig_path, self.folder = rig, rig_path, Path(folder)
        self.sent = sent or (lambda: True)
        self.driver, self.profile, self.profile_spec = driver, profile, profile_spec
        self.positions: list[dict] = []
        self.result: dict | None = None
        self.error: str | None = None
        self.running = False
        self.runs = 0

    def mark(self, x: float, y: float, height_m: float) -> dict:
        """Add the PTZ's position now as an aim at a mark ``height_m`` above the floor point seen at pixel
        (x, y). Blocks until the PTZ stands still (at most seconds): call it off the server's loop."""
        from runtime.ptz import PtzError

        if self.driver is None or self.profile is None:
            raise ValueError("no PTZ to read the position of: the calibration assistant needs --ptz")
        omni = self.rig.omni
        if not 0 <= height_m <= float(omni.H_o):
            raise ValueError(f"height_m: expected the mark's height above the floor, 0 to {float(omni.H_o):g} m "
                             f"(omni.H_o), got {height_m:g}")
        r, theta = (float(v) for v in omni.to_polar(x, y))
        if r >= float(omni.rim):
            raise ValueError(f"({x:g}, {y:g}) lies outside the image circle (rim {float(omni.rim):g} px)")
        deadline = time.monotonic() + SENT_S
        while not self.sent() and time.monotonic() < deadline:  # the loop takes a new pointing at its next frame
            time.sleep(0.02)
        self.driver.wait_reached(3.0)
        try:
            pos = self.driver.query_position(2.0)
        except (PtzError, TimeoutError) as exc:
            raise ValueError(f"the PTZ did not say where it is: {exc}") from None
        for k, axis in enumerate(("pan", "tilt")):
            limit = self.profile.at_limit(axis, pos.units[k])
            if limit is not None:
                raise ValueError(f"the PTZ stands at its {axis} limit ({limit:g} deg): its crosshair cannot be on a "
                                 "mark beyond it; choose a mark it can centre")
        aim = {"height_m": round(height_m, 4), "pan_deg": round(pos.units[0] / self.profile.pan.units_per_deg, 4),
               "tilt_deg": round(pos.units[1] / self.profile.tilt.units_per_deg, 4)}
        near = [p for p in self.positions if math.hypot(p["x"] - x, p["y"] - y) <= SAME_POSITION_PX]
        if near:
            near[0]["aims"].append(aim)
        else:
            self.positions.append({"label": f"P{len(self.positions) + 1}", "x": round(x, 2), "y": round(y, 2),
                                   "r_f": round(r, 3), "theta_f": round(theta, 6), "aims": [aim]})
        return self.report()

    def clear(self) -> None:
        self.positions.clear()
        self.result = self.error = None

    def observations(self) -> dict:
        """The ``OBS.json`` object of the positions so far (docs/calibration.md)."""
        return {"comment": "recorded with the calibration assistant of omnijax's console",
                "sigma_pan_deg": SIGMA_PTZ_DEG, "sigma_tilt_deg": SIGMA_PTZ_DEG, "sigma_height_m": SIGMA_HEIGHT_M,
                "positions": [{k: p[k] for k in ("label", "r_f", "theta_f", "aims")} for p in self.positions]}

    async def fit(self) -> None:
        """Write ``observations.json`` and run ``omnijax calibrate`` on it; ``result`` or ``error`` after."""
        if self.running:
            raise ValueError("a fit is running already")
        if self.rig_path is None:
            raise ValueError("the rig has no file to calibrate from")
        if not self.positions:
            raise ValueError("no observations yet: drive the PTZ onto a mark, then click the mark's foot")
        self.running, self.runs = True, self.runs + 1
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            obs = self.folder / "observations.json"
            tmp = obs.with_name(f".{obs.name}.{os.getpid()}.tmp")
            tmp.write_text(json.dumps(self.observations(), indent=1) + "\n")
            os.replace(tmp, obs)
            out = self.folder / f"fit-{self.runs}"
            cmd = [sys.executable, "-m", "runtime.cli", "calibrate", "--config", str(self.rig_path),
                   "--observations", str(obs), "--out", str(out)]
            if self.profile_spec:
                cmd += ["--ptz-profile", self.profile_spec]
            proc = await asyncio.create_subprocess_exec(*cmd, stdout=asyncio.subprocess.PIPE,
                                                        stderr=asyncio.subprocess.PIPE)
            _, err = await proc.communicate()
            if proc.returncode == 0:
                report = json.loads((out / "calibration.json").read_text())
                self.result = {k: report.get(k) for k in ("params", "rms_residual_deg", "chi2", "dof",
                                                          "chi2_p_value", "residuals_deg", "observations_used")}
                self.result["folder"] = str(out)
                self.error = None
            else:
                lines = err.decode(errors="replace").strip().splitlines()
                self.result, self.error = None, lines[-1] if lines else f"omnijax calibrate exited {proc.returncode}"
        finally:
            self.running = False

    def report(self) -> dict:
        aims = sum(len(p["aims"]) for p in self.positions)
        heights = sorted({a["height_m"] for p in self.positions for a in p["aims"]})
        return {"observations": self.positions, "aims": aims, "heights_m": heights, "running": self.running,
                "result": self.result, "error": self.error,
                "ready": len(self.positions) >= 3 and len(heights) >= 2 and aims >= 4,
                "pixels": np.round([[p["x"], p["y"]] for p in self.positions], 1).tolist()}
