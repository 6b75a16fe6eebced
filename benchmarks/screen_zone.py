"""False alarms from a flickering screen, with and without an ignore zone over it (issue 25).

For each seed, runs ``omnijax demo --scenario flickering_screen --seed S --frames N --pace all
--no-video`` three times, on copies of the scenario and its rig in a temporary folder: as shipped,
with the rig holding one ``[[zones]] kind = "ignore"`` polygon over the screen (docs/console.md#zones): the
box, in omni image pixels of the configured rig, around the image of the screen's rectangle (its
edges subdivided: straight edges are curves in the omni image), grown by ``--margin-px``; and, as the
floor of what a zone can do, the same world without its screen (zone ``no screen``). Prints each
run's summary.json ``detection`` (false alarms: detections farther than 0.5 m from every true foot)
and the medians over the seeds, as a table and, with ``--json``, as JSON.

    .venv/bin/python benchmarks/screen_zone.py --seeds 9101 9102 9103
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "configs" / "scenarios" / "flickering_screen.toml"


def screen_zone(margin_px: float) -> list[list[float]]:
    """The ignore polygon (omni px, a box) around the scenario's first screen, in the configured rig."""
    import numpy as np

    from omnijax import world_to_image
    from runtime.files import load_scenario

    rig, sc = load_scenario(SCENARIO)
    sc_screens = sc.screens
    if sc_screens.size < 1:
        raise SystemExit(f"{SCENARIO}: expected a [[screens]] table")
    outline = np.asarray(rig.room.outline)
    w = int(sc_screens.wall[0])
    a, b = outline[w], outline[(w + 1) % len(outline)]
    e = (b - a) / np.linalg.norm(b - a)
    (u0, u1), (z0, z1) = np.asarray(sc_screens.along[0]), np.asarray(sc_screens.height[0])
    s = np.linspace(0.0, 1.0, 21)
    u = np.concatenate([u0 + (u1 - u0) * s, np.full_like(s, u1), u1 - (u1 - u0) * s, np.full_like(s, u0)])
    z = np.concatenate([np.full_like(s, z0), z0 + (z1 - z0) * s, np.full_like(s, z1), z1 - (z1 - z0) * s])
    xy = a + u[:, None] * e
    x, y = (np.asarray(v) for v in world_to_image(rig.omni, xy[:, 0], xy[:, 1], z))
    x0, x1 = float(x.min() - margin_px), float(x.max() + margin_px)
    y0, y1 = float(y.min() - margin_px), float(y.max() + margin_px)
    return [[round(x0, 1), round(y0, 1)], [round(x1, 1), round(y0, 1)], [round(x1, 1), round(y1, 1)],
            [round(x0, 1), round(y1, 1)]]


def without_screens(text: str) -> str:
    """The scenario's TOML text without its ``[[screens]]`` tables (the same world otherwise)."""
    out, skipping = [], False
    for line in text.splitlines(keepends=True):
        if line.startswith("["):
            skipping = line.strip() == "[[screens]]"
        if not skipping:
            out.append(line)
    return "".join(out)


def run_demo(folder: Path, seed: int, frames: int, zone: list[list[float]] | None, screen: bool = True) -> dict:
    """One demo on copies of the scenario and its rig (with the zone, if given; without the screen if
    ``screen`` is false); its summary.json (a run already in ``folder``, from an earlier ``--keep``, is
    read, not repeated)."""
    if (folder / "out" / "summary.json").is_file():
        return json.loads((folder / "out" / "summary.json").read_text())
    rig_text = (SCENARIO.parent / "../paper.toml").resolve().read_text()
    if zone is not None:
        rig_text += f'\n[[zones]]\nkind = "ignore"\nname = "screen"\npoints = {json.dumps(zone)}\n'
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "paper.toml").write_text(rig_text)
    text = SCENARIO.read_text().replace('rig = "../paper.toml"', 'rig = "paper.toml"')
    (folder / "scenario.toml").write_text(text if screen else without_screens(text))
    out = folder / "out"
    cmd = [sys.executable, "-m", "runtime.cli", "demo", "--scenario", str(folder / "scenario.toml"), "--seed",
           str(seed), "--frames", str(frames), "--pace", "all", "--no-video", "--quiet", "--out", str(out)]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"demo failed (exit {done.returncode}): {done.stderr.strip().splitlines()[-1:]}")
    return json.loads((out / "summary.json").read_text())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[9101, 9102, 9103])
    p.add_argument("--frames", type=int, default=600)
    p.add_argument("--margin-px", type=float, default=6.0, help="the zone's margin around the screen (px)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    p.add_argument("--keep", type=Path, help="keep the runs' folders here (created; runs found there are reused)")
    args = p.parse_args(argv)
    if any(s < 0 for s in args.seeds) or args.frames < 1 or args.margin_px < 0:
        p.error("--seeds: expected integers >= 0, --frames >= 1, --margin-px >= 0")
    zone = screen_zone(args.margin_px)
    rows = []
    base = Path(tempfile.mkdtemp(prefix="screen_zone_")) if args.keep is None else args.keep
    try:
        for seed in args.seeds:
            for name, z, screen in (("none", None, True), ("ignore", zone, True), ("no screen", None, False)):
                summary = run_demo(base / f"{seed}_{name.replace(' ', '_')}", seed, args.frames, z, screen)
                d = summary["detection"]
                rows.append({"seed": seed, "zone": name, "frames": summary["frames"], "detections": d["detections"],
                             "false_alarms": d["false_alarms"], "false_alarm_rate": d["false_alarm_rate"],
                             "false_alarms_per_frame": d["false_alarms_per_frame"], "miss_rate": d["miss_rate"]})
                print(f"seed {seed} zone {name}: {rows[-1]}", file=sys.stderr, flush=True)
    finally:
        if args.keep is None:
            shutil.rmtree(base, ignore_errors=True)
    keys = ("false_alarms", "false_alarm_rate", "false_alarms_per_frame", "miss_rate")
    median = {name: {k: statistics.median(r[k] or 0.0 for r in rows if r["zone"] == name) for k in keys}
              for name in ("none", "ignore", "no screen")}
    if args.json:
        print(json.dumps({"zone_points_px": zone, "runs": rows, "median": median}, indent=2))
        return 0
    print(f"ignore zone (omni px): {zone}")
    print("| seed | zone | frames | detections | false alarms | false-alarm rate | per frame | miss rate |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['seed']} | {r['zone']} | {r['frames']} | {r['detections']} | {r['false_alarms']} | "
              f"{r['false_alarm_rate'] or 0:.4f} | {r['false_alarms_per_frame'] or 0:.4f} | "
              f"{r['miss_rate'] or 0:.4f} |")
    for name, m in median.items():
        print(f"| median | {name} | | | {m['false_alarms']:g} | {m['false_alarm_rate']:.4f} | "
              f"{m['false_alarms_per_frame']:.4f} | {m['miss_rate']:.4f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
