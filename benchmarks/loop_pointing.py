"""The loop's own pointing over many people: ``omnijax demo`` on each (scene, seed), its ``summary.json``
``pointing`` pooled over every person of every run (issue 23 item 4).

A run's pointing NEES averages over the frames the PTZ had arrived on a target, but those frames are a
few people's, and most of a person's pointing error is theirs for the whole run (their height against the
prior's, the foot their clothing leaves the detector): a run of three to six people is a sample of three
to six draws, not of its 800-900 frames. So the honest test of the covariance is over the people:

- ``nees_mean``: per degree of freedom, over all arrived frames of all runs (1 when right), with its
  standard error taken over the *people* as the independent units (a cluster-robust standard error:
  each person's frames are one cluster);
- ``pan_nees_mean``, ``tilt_nees_mean``: each axis's squared error over its variance, the same way;
- ``person_nees_median``, ``people_over_2``: the median person's NEES and the share of people whose own
  NEES (per dof) is above 2; were a person's error one persistent draw under a right covariance, their
  NEES would be chi-square(2) / 2, above 2 for ``expected_people_over_2`` = exp(-2) = 0.135 of people
  (frame-to-frame noise in the error pulls both towards 1 and 0);
- ``containment``: the calibrated rule's head-in-frame rate at p_contain 0.9 / 0.95 / 0.99, pooled
  over the runs' arrived frames;
- ``run_spread``: per scene, the standard deviation of the runs' own NEES against what drawing that
  many people at random from the pooled people of the scene gives (a bootstrap, 4000 draws, seed 0):
  equal when the runs differ only by whom they drew;
- ``each_run``: each run's own figures.

Run (sequentially, one demo at a time; nothing here is a timing):

    .venv/bin/python benchmarks/loop_pointing.py --scenes three_people six_people --seeds 9494-9503 \\
        --frames 1500 --out out/loop_pointing
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
P_CONTAIN = (0.9, 0.95, 0.99)
#: P(chi-square(2) / 2 > 2): the share of people a right covariance puts above a NEES of 2 per dof, were
#: each person's error one draw (the extreme of full persistence; independent frames put it near 0).
EXPECTED_PEOPLE_OVER_2 = math.exp(-2.0)


def seeds_arg(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def run_demo(scene: str, seed: int, frames: int, config: str | None, out: Path, extra: list[str]) -> dict:
    """``omnijax demo`` for one (scene, seed) into ``out``; its summary.json (kept: a rerun reuses it)."""
    summary = out / "summary.json"
    if not summary.exists():
        cmd = [sys.executable, "-m", "runtime.cli", "demo", "--scenario", scene, "--seed", str(seed),
               "--frames", str(frames), "--pace", "all", "--no-video", "--out", str(out)]
        if config:
            cmd += ["--config", config]
        cmd += extra
        done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"demo {scene} seed {seed} failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    return json.loads(summary.read_text())


def pool(runs: list[dict]) -> dict:
    """The pooled figures (module docstring) of ``runs``: each {scene, seed, pointing}."""
    people = [(r["scene"], r["seed"], p) for r in runs for p in r["pointing"]["people"] if p["frames"]]
    n = sum(p["frames"] for *_, p in people)
    out: dict = {"runs": len(runs), "people": len(people), "frames": n}
    for key in ("nees_mean", "pan_nees_mean", "tilt_nees_mean"):
        mean = sum(p["frames"] * p[key] for *_, p in people) / n
        # cluster-robust: the people are the units, each weighted by its frames
        var = sum((p["frames"] * (p[key] - mean)) ** 2 for *_, p in people) / n**2
        out[key] = mean
        out[key + "_se"] = math.sqrt(var * len(people) / max(len(people) - 1, 1))
    per_person = sorted(p["nees_mean"] for *_, p in people)
    out["person_nees_median"] = per_person[len(per_person) // 2]
    out["people_over_2"] = sum(v > 2 for v in per_person) / len(per_person)
    out["expected_people_over_2"] = EXPECTED_PEOPLE_OVER_2
    worst = max(people, key=lambda t: t[2]["nees_mean"])
    out["worst_person"] = {"scene": worst[0], "seed": worst[1], **worst[2]}
    curve = {}
    for r in runs:
        for c in r["pointing"]["curve"]:
            if c["rule"] == "calibrated" and c["trials"]:
                k = c["p_contain"]
                a, b = curve.get(k, (0.0, 0))
                curve[k] = (a + c["rate"] * c["trials"], b + c["trials"])
    out["containment"] = {str(k): a / b for k, (a, b) in sorted(curve.items())}
    out["run_spread"] = run_spread(runs)
    return out


def run_spread(runs: list[dict], draws: int = 4000) -> dict:
    """Per scene: the runs' NEES standard deviation, and the bootstrap's from the scene's pooled people
    (each run redrawn as as many people, with their frames, as the scene's runs had on average)."""
    rng = np.random.default_rng(0)
    by_scene = defaultdict(list)
    for r in runs:
        by_scene[r["scene"]].append(r)
    out = {}
    for scene, rs in by_scene.items():
        if len(rs) < 2:
            continue
        people = [(p["frames"], p["nees_mean"]) for r in rs for p in r["pointing"]["people"] if p["frames"]]
        f, v = np.array(people, float).T
        n = max(1, round(len(people) / len(rs)))
        pick = rng.integers(0, len(people), (draws, n))
        boot = (f[pick] * v[pick]).sum(1) / f[pick].sum(1)
        out[scene] = {"runs_sd": float(np.std([r["pointing"]["nees_mean"] for r in rs], ddof=1)),
                      "drawn_people_sd": float(boot.std()), "people_a_run": n,
                      "drawn_share_in_0_8_1_2": float(np.mean((boot >= 0.8) & (boot <= 1.2)))}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["three_people", "six_people"], help="demo scenarios")
    ap.add_argument("--seeds", type=seeds_arg, required=True, help="seeds, e.g. 9494-9503 or 1,5,9")
    ap.add_argument("--frames", type=int, default=1500, help="frames a run (default 1500)")
    ap.add_argument("--config", help="rig (default: the demo's, configs/paper.toml)")
    ap.add_argument("--out", type=Path, required=True, help="one folder a run under it, and pooled.json")
    ap.add_argument("--demo-args", default="", metavar="'ARGS'",
                    help="more arguments for every demo, one string (e.g. '--dead-zone-sd 0.5')")
    args = ap.parse_args(argv)
    runs = []
    jobs = [(s, k) for s in args.scenes for k in args.seeds]
    for scene, seed in tqdm(jobs, desc="demo runs", unit="run"):
        summary = run_demo(scene, seed, args.frames, args.config, args.out / f"{scene}_{seed}",
                           args.demo_args.split())
        pt = summary["pointing"]
        if pt.get("people") is None:
            continue
        runs.append({"scene": scene, "seed": seed, "pointing": pt, "framed": summary["containment"]["rate"]})
    pooled = pool(runs)
    pooled["each_run"] = [{"scene": r["scene"], "seed": r["seed"], "nees_mean": r["pointing"]["nees_mean"],
                           "pan": r["pointing"]["pan_nees_mean"], "tilt": r["pointing"]["tilt_nees_mean"],
                           "frames": r["pointing"]["frames"], "framed": r["framed"]} for r in runs]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "pooled.json").write_text(json.dumps(pooled, indent=1))
    print("scene seed | NEES (pan, tilt) | frames | framed")
    for r in pooled["each_run"]:
        print(f"{r['scene']} {r['seed']} | {r['nees_mean']:.3f} ({r['pan']:.2f}, {r['tilt']:.2f}) | {r['frames']} | "
              f"{r['framed']:.4f}")
    print(f"pooled over {pooled['people']} people, {pooled['frames']} frames, {pooled['runs']} runs: "
          f"NEES {pooled['nees_mean']:.3f} +- {pooled['nees_mean_se']:.3f} (pan {pooled['pan_nees_mean']:.3f} +- "
          f"{pooled['pan_nees_mean_se']:.3f}, tilt {pooled['tilt_nees_mean']:.3f} +- "
          f"{pooled['tilt_nees_mean_se']:.3f}); "
          f"median person {pooled['person_nees_median']:.3f}; people over 2: {pooled['people_over_2']:.3f}; "
          f"containment {' / '.join(f'{v:.3f}' for v in pooled['containment'].values())}")
    print(f"worst person: {pooled['worst_person']}")
    for scene, sp in pooled["run_spread"].items():
        print(f"{scene}: runs' NEES sd {sp['runs_sd']:.3f}; {sp['people_a_run']} people drawn from the pool: sd "
              f"{sp['drawn_people_sd']:.3f}, in [0.8, 1.2] for {sp['drawn_share_in_0_8_1_2']:.2f} of runs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
