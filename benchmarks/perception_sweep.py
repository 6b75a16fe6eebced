"""Perception against the synthetic world's truth over many scenes and seeds: misses, false alarms, their
causes, NEES per range band; the worst and the median seed per scene.

Two ways in:

- ``sweep``: renders each (scene, seed) in this process and runs ``omnijax detect``'s own pipeline on
  the frames (:func:`runtime.realtime.perception.detect_frames`, its defaults: what ``omnijax detect``
  does to the same frames read from a lossless video), scoring every processed frame;
- ``folders R:D ...``: scores ``omnijax render`` output R against ``omnijax detect`` output D.

Scoring and causes: :mod:`runtime.validation.perception` (docs/detection.md, "Per-cause figures").

Run:

    .venv/bin/python benchmarks/perception_sweep.py sweep --scenes three_people six_people \\
        --seeds 5000-5009 --frames 600 --json out/sweep.json
    .venv/bin/python benchmarks/perception_sweep.py folders R:D
    .venv/bin/python benchmarks/perception_sweep.py folders out/keep/*   # runs kept by sweep --keep out/keep
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
import numpy as np
from tqdm import tqdm

from omnijax import detection_sigmas, floor_from_detections
from runtime.validation.perception import FA_CAUSES, MISS_CAUSES, History, PerceptionScore


def seeds_arg(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def floor_and_sigmas(rig, people: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    if not people:
        return np.zeros((0, 2)), np.zeros((0, 2))
    r = np.array([p["r_f"] for p in people])
    t = np.array([p["theta_f"] for p in people])
    s_r = np.array([p.get("detector_sigma_r_f", p["sigma_r_f"]) for p in people])
    s_t = np.array([p.get("detector_sigma_theta_f", p["sigma_theta_f"]) for p in people])
    b_r, b_t = (np.array([p.get(f"detector_bound_{k}", 0.0) for p in people]) for k in ("r_f", "theta_f"))
    z, _ = floor_from_detections(rig, r, t, s_r, s_t, b_r, b_t)
    sr, st = detection_sigmas(rig, s_r, s_t, b_r, b_t, r)
    return np.asarray(z), np.stack([np.asarray(sr), np.asarray(st)], -1)


def score_lines(rig, truth_lines: list[dict], world: dict, det_lines: list[dict], learning_frames,
                moved_furniture=()) -> dict:
    history = History.from_truth_lines(truth_lines, world, learning_frames, moved_furniture)
    by_frame = {t["frame"]: t for t in truth_lines}
    score = PerceptionScore(blind_radius_m=float(rig.detection.min_floor_radius))
    for d in det_lines:
        z, sig = floor_and_sigmas(rig, d["people"])
        score.add_frame(d["frame"], by_frame[d["frame"]], d["people"], z, sig, history)
    return {**score.summary(), "records": score.records}


def read_jsonl(path: Path) -> list[dict]:
    with path.open() as f:
        return [json.loads(line) for line in f]


def folders(args) -> list[dict]:
    from runtime.files import load_rig, load_scenario

    rows = []
    for pair in args.pairs:
        r, d = (Path(p) for p in (pair.split(":", 1) if ":" in pair else (pair, pair)))
        world = json.loads((r / "world.json").read_text())
        summary = json.loads((d / "summary.json").read_text())
        rig = load_scenario(summary["scenario"])[0] if "scenario" in summary else load_rig(summary["config"])
        learning = summary.get("learning_frames", list(range(summary.get("background_frames", 30))))
        s = score_lines(rig, read_jsonl(r / "truth.jsonl"), world, read_jsonl(d / "detections.jsonl"), learning,
                        summary.get("moved_furniture", ()))
        # the scene as `sweep` names it (the scenario file's name) where the run says which file it was;
        # world.json holds only the scenario's display name
        scene = Path(summary["scenario"]).stem if "scenario" in summary else world["scenario"]
        rows.append({"scene": scene, "seed": world["seed"], **s})
    return rows


def sweep(args) -> list[dict]:
    from omnijax.world import build_world
    from runtime.files import load_scenario
    from runtime.realtime.perception import detect_frames
    from runtime.validation.truth import truth_line, world_summary

    rows = []
    jobs = [(s, k) for s in args.scenes for k in args.seeds]
    bar = tqdm(jobs, desc="sweep", unit="run", disable=None)
    for scene, seed in bar:
        bar.set_postfix_str(f"{scene} {seed}")
        rig, sc = load_scenario(Path("configs/scenarios") / f"{scene}.toml")
        world = build_world(rig, sc, seed, n_frames=args.frames)
        t0 = time.perf_counter()
        truth_lines, det_lines = [], []

        def frames(world=world, truth_lines=truth_lines):
            for t in range(args.frames):
                f = world.frame(t)
                truth_lines.append(truth_line(jax.device_get(f.truth)))
                yield np.asarray(f.image)

        result = detect_frames(rig, frames(), fps=float(sc.fps))
        for item in result:
            det_lines.append({"frame": item.index, "people": item.people})
        summary = world_summary(world)
        moved = getattr(world, "moved_furniture", ())
        s = score_lines(rig, truth_lines, summary, det_lines, result.learning_frames, moved)
        if args.keep:
            keep_run(args.keep / f"{scene}_{seed}", summary, truth_lines, det_lines, result.learning_frames, moved,
                     Path("configs/scenarios") / f"{scene}.toml")
        rows.append({"scene": scene, "seed": seed, "seconds": time.perf_counter() - t0,
                     "life": result.perception.keeper.summary(), **s})
    return rows


def keep_run(folder: Path, world: dict, truth_lines: list[dict], det_lines: list[dict], learning_frames,
             moved_furniture, scenario: Path) -> None:
    """One run's truth and detections in ``folder`` as ``omnijax render`` and ``omnijax detect`` write them
    (``world.json``, ``truth.jsonl``; ``summary.json``, ``detections.jsonl``), so ``folders FOLDER:FOLDER``
    scores them again (a changed classifier) without rendering or detecting."""
    from runtime.output import dumps  # as omnijax render writes world.json

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "world.json").write_text(dumps(world) + "\n")
    summary = {"scenario": str(scenario.resolve()), "learning_frames": list(learning_frames),
               "moved_furniture": np.asarray(moved_furniture, float).reshape(-1, 2)}
    (folder / "summary.json").write_text(dumps(summary) + "\n")
    for name, lines in (("truth.jsonl", truth_lines), ("detections.jsonl", det_lines)):
        (folder / name).write_text("".join(json.dumps(line, default=float) + "\n" for line in lines))


def table(rows: list[dict]) -> str:
    head = ("| scene | seed | miss | false alarms | NEES r_f | P(>6.63) | NEES theta_f | P(>6.63) | ghost gone (s) | "
            "standing detected | FA causes | miss causes |\n"
            "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- |")
    out = [head]
    for r in rows:
        n = r["nees"]["all"]
        fa = " ".join(f"{k}:{v}" for k, v in r["fa_causes"].items() if v)
        mi = " ".join(f"{k}:{v}" for k, v in r["miss_causes"].items() if v)
        out.append(f"| {r['scene']} | {r['seed']} | {_f(r['miss_rate'])} | {_f(r['false_alarm_rate'])} | "
                   f"{_f(n.get('r_f_mean'), 2)} | {_f(n.get('r_f_over_6_63'))} | {_f(n.get('theta_f_mean'), 2)} | "
                   f"{_f(n.get('theta_f_over_6_63'))} | {_f(r.get('ghost_gone_s'), 2)}{_late(r)} | "
                   f"{_f(r.get('standing_detected_rate'))} ({r.get('standing_frames', 0)}) | {fa} | {mi} |")
    return "\n".join(out)


def worst_and_median(rows: list[dict]) -> str:
    out = ["| scene | seeds | miss worst (seed) | miss median | miss seen worst (seed) | FA worst (seed) | FA median | "
           "NEES r_f median | NEES theta_f median | ghost gone worst (s) | standing detected worst | "
           "standing seen worst |",
           "| --- | ---: | --- | ---: | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        rs = [r for r in rows if r["scene"] == scene]
        m = max(rs, key=lambda r: r["miss_rate"] or 0)
        f = max(rs, key=lambda r: r["false_alarm_rate"] or 0)
        seen = max(rs, key=lambda r: r.get("miss_rate_seen") or 0)
        stood = [r["standing_detected_rate"] for r in rs if r.get("standing_detected_rate") is not None]
        stood_seen = [r["standing_detected_rate_seen"] for r in rs if r.get("standing_detected_rate_seen") is not None]
        out.append(f"| {scene} | {len(rs)} | {_f(m['miss_rate'])} ({m['seed']}) | "
                   f"{_f(np.median([r['miss_rate'] or 0 for r in rs]))} | "
                   f"{_f(seen.get('miss_rate_seen'))} ({seen['seed']}) | {_f(f['false_alarm_rate'])} ({f['seed']}) | "
                   f"{_f(np.median([r['false_alarm_rate'] or 0 for r in rs]))} | "
                   f"{_f(np.median([r['nees']['all'].get('r_f_mean', np.nan) for r in rs]), 2)} | "
                   f"{_f(np.median([r['nees']['all'].get('theta_f_mean', np.nan) for r in rs]), 2)} | "
                   f"{_f(max(r.get('ghost_gone_s', 0.0) for r in rs), 2)} | "
                   f"{_f(min(stood, default=None))} | {_f(min(stood_seen, default=None))} |")
    return "\n".join(out)


def _late(row: dict) -> str:
    """`` (+N late)``: ghost false alarms at N places left long before (not ghosts that lasted)."""
    n = row.get("ghost_returns", 0)
    return f" (+{n} late)" if n else ""


def _f(v, digits: int = 3) -> str:
    return "-" if v is None or (isinstance(v, float) and np.isnan(v)) else f"{v:.{digits}f}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="mode", required=True)
    s = sub.add_parser("sweep", help="render and detect in this process, many scenes and seeds")
    s.add_argument("--scenes", nargs="+", default=["three_people", "six_people"])
    s.add_argument("--seeds", type=seeds_arg, default=seeds_arg("5000-5009"), help="e.g. 5000-5009 or 1,2,7")
    s.add_argument("--frames", type=int, default=600)
    s.add_argument("--keep", type=Path, metavar="DIR",
                   help="write each run's truth and detections to DIR/SCENE_SEED (score them again with "
                        "folders DIR/SCENE_SEED:DIR/SCENE_SEED)")
    f = sub.add_parser("folders", help="score omnijax render + omnijax detect outputs")
    f.add_argument("pairs", nargs="+", metavar="RENDER:DETECT",
                   help="render and detect output folders; one folder alone: a run kept by sweep --keep")
    for p in (s, f):
        p.add_argument("--json", type=Path, help="write every row here")
        p.add_argument("--records", type=Path,
                       help="write every matched detection here (floor radius m, r_f error px, theta_f error rad, "
                            "the detector's sigmas and bound parts): what fit_detection_sigmas.py --records fits")
    args = ap.parse_args()
    rows = sweep(args) if args.mode == "sweep" else folders(args)
    print(table(rows))
    print()
    print(worst_and_median(rows))
    print("\nFA causes:", ", ".join(FA_CAUSES), "| miss causes:", ", ".join(MISS_CAUSES),
          "\nmiss seen: misses over person-frames without the never_seen_free ones (people standing on their "
          "spot since before the learning's first frame: no change detector sees them until they move); "
          "standing seen: the same for the standing figure; ghost gone: the longest a ghost lasted after its "
          "person walked 1 m away (+N late: ghost false alarms that began at a place left more than 0.5 s "
          "before, counted in the false alarms but not ghosts that lasted; runtime/validation/perception.py)")
    if args.records:
        args.records.parent.mkdir(parents=True, exist_ok=True)
        args.records.write_text(json.dumps({f"{r['scene']}:{r['seed']}": r["records"] for r in rows}) + "\n")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps([{k: v for k, v in r.items() if k != "records"} for r in rows], indent=1)
                             + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
