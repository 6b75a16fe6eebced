"""Does the operator's console slow the control path? ``omnijax demo --serve`` without a browser against
the same run with the page open in two headless Chromium browsers (issue 25).

Each run is ``omnijax demo --scenario S --seed K --frames N --pace live --no-video --serve 127.0.0.1:0``
(a port the OS picks, on this machine only; the demo ends by itself after its N frames), a) with no
browser and b) with the page (and its token) open in two headless Chromium browsers driven by Selenium,
polling the status and loading the views as an operator's page does, until the demo ends; ``--repeat R``
alternates a) and b) R times. Prints, per run and pooled (median over the repeats), summary.json's
``latency_ms`` (frame arrived -> PTZ bytes written), ``compute_latency_ms`` (-> command handed to the
driver) and ``frame_age_ms`` (every processed frame), p50 and p99, as a table and, with ``--json``, as
JSON. Needs /usr/bin/chromium and /usr/bin/chromedriver (apt-get install chromium chromium-driver).

On a quiet machine, the demo pinned to core 0 and the script with its browsers to core 1:

    ../shared/tools/quiet taskset -c 1 .venv/bin/python benchmarks/bench_console.py --demo-cpus 0

(``--demo-cpus 0`` runs the demo under ``taskset -c 0``). A smoke test of the script (no figures):
``--frames 400 --repeat 1``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _served_demo import ServedDemo

CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
KEYS = ("latency_ms", "compute_latency_ms", "frame_age_ms")


def open_page(url: str, profile: Path):
    """A headless Chromium with the console's page loaded and live."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for arg in ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage", "--window-size=1400,1000",
                f"--user-data-dir={profile}"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    driver.set_page_load_timeout(60)
    driver.get(url)
    deadline = time.monotonic() + 60
    while driver.find_element("id", "conn").text != "live":
        if time.monotonic() > deadline:
            driver.quit()
            raise RuntimeError("the page did not go live within 60 s")
        time.sleep(0.2)
    return driver


def one_run(args, folder: Path, browsers: int) -> dict:
    demo_args = ["--scenario", args.scenario, "--seed", str(args.seed), "--frames", str(args.frames),
                 "--pace", "live", "--no-video"]
    prefix = ["taskset", "-c", args.demo_cpus] if args.demo_cpus else None
    drivers = []
    with ServedDemo(demo_args, folder / "out", min_frames=1, prefix=prefix) as demo:
        try:
            for i in range(browsers):
                drivers.append(open_page(f"{demo.base}?token={demo.token}", folder / f"chromium-{i}"))
            page_frames = demo.call("GET", "/api/status")[1]["frames"]
            code = demo.wait(args.frames / 5 + 600)
        finally:
            for driver in drivers:
                driver.quit()
    if code != 0:
        raise SystemExit(f"the demo ended with exit code {code}: {''.join(demo.lines)[-800:]}")
    s = demo.summary()
    return {"browsers": browsers, "frames": s["frames"], "fps": s["fps"],
            "frames_before_pages_open": page_frames, **{k: {q: s[k][q] for q in ("p50", "p99")} for k in KEYS}}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default="three_people", help="scenario name or file (default three_people)")
    p.add_argument("--seed", type=int, default=9101)
    p.add_argument("--frames", type=int, default=3000, help="frames per run, background learning included")
    p.add_argument("--repeat", type=int, default=3, help="pairs of runs (without, with browsers)")
    p.add_argument("--demo-cpus", default="", help="run the demo under taskset -c CPUS (e.g. 0)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    args = p.parse_args(argv)
    if args.seed < 0 or args.frames < 1 or args.repeat < 1:
        p.error("--seed: expected an integer >= 0; --frames, --repeat: at least 1")
    if not (CHROMIUM.is_file() and CHROMEDRIVER.is_file()):
        p.error("no browser: install Chromium and its driver (apt-get install chromium chromium-driver)")
    if args.demo_cpus and not shutil.which("taskset"):
        p.error("--demo-cpus: taskset is not installed")
    base = Path(tempfile.mkdtemp(prefix="bench_console_"))
    runs = []
    try:
        for r in range(args.repeat):
            for browsers in (0, 2):
                runs.append(one_run(args, base / f"{r}-{browsers}", browsers))
                print(f"run {r} with {browsers} browsers: {runs[-1]}", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(base, ignore_errors=True)
    pooled = {b: {k: {q: statistics.median(run[k][q] for run in runs if run["browsers"] == b and run[k][q] is not None)
                      for q in ("p50", "p99")} for k in KEYS} for b in (0, 2)}
    if args.json:
        print(json.dumps({"scenario": args.scenario, "seed": args.seed, "frames": args.frames, "runs": runs,
                          "median": {f"{b}_browsers": v for b, v in pooled.items()}}, indent=2))
        return 0
    print("| browsers | run | fps | latency p50 / p99 (ms) | compute p50 / p99 (ms) | frame age p50 / p99 (ms) |")
    print("| --- | --- | --- | --- | --- | --- |")
    rows = [(run["browsers"], str(i // 2), f"{run['fps']:.1f}", run) for i, run in enumerate(runs)]
    rows += [(b, "median", "", pooled[b]) for b in (0, 2)]
    for b, label, fps, v in rows:
        ms = lambda x: "-" if x is None else f"{x:.2f}"
        print(f"| {b} | {label} | {fps} | " + " | ".join(f"{ms(v[k]['p50'])} / {ms(v[k]['p99'])}" for k in KEYS) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
