"""Detection accuracy in the synthetic world: the figures of the detection issue.

- d^2 of background pixels on rendered noise against chi-square(2) (KS test, >= 1e5 pixels);
- the false-sector rate in the lamps-switching room emptied of people (illumination drift,
  a lamp switching off and on; background learnt from the first 30 frames),
  chromaticity against grey levels, against x_f (with a Clopper-Pearson 95 % bound);
- the miss rate of people (inside the polar range, foot visible) against x_m, and the
  normalised estimation error squared of r_f and theta_f over the matched detections (their
  sigmas under the sigma rule, :func:`omnijax.aiming.detection_sigmas`),
  all of them and the isolated ones (no other person within 0.35 rad).

Run: `.venv/bin/python benchmarks/detection_accuracy.py --json out/detection_accuracy.json`
(several minutes). Fixed seeds; every count is printed with the number of frames.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
import numpy as np
from scipy import stats
from tqdm import tqdm

from omnijax import (
    build_detector,
    change_image,
    detect,
    detection_sigmas,
    learn_background,
    polar_range,
)
from omnijax.geometry import wrap_pi
from omnijax.world import build_world, parse_scenario
from runtime.files import load_rig, load_scenario, read_toml
from runtime.realtime.perception import BackgroundKeeper
from runtime.realtime.targeting import TrustRule

SCENARIOS = Path(__file__).resolve().parent.parent / "configs" / "scenarios"


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    a = 1 - level
    lo = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def load(name: str, empty: bool = False):
    """A scenario; ``empty`` takes its people out (lighting, drift and lamp switching stay)."""
    path = SCENARIOS / f"{name}.toml"
    if not empty:
        return load_scenario(path)
    data = read_toml(path)
    data["people"]["count"] = 0
    rig = load_rig(path.parent / data["rig"])
    return rig, parse_scenario(data, rig, source=f"{path} (people removed)")


def run_scenario(name: str, n_frames: int, measure: str, seed: int, stride: int = 1, learn_every: int = 10,
                 learn_n: int = 30, empty: bool = False):
    """Detect in ``n_frames`` frames after learning the background; match to the truth."""
    rig, scenario = load(name, empty)
    start = learn_every * learn_n
    world = build_world(rig, scenario, seed=seed, n_frames=start + n_frames * stride)
    det = build_detector(rig, measure=measure)
    r0, r1 = polar_range(rig)
    bg = learn_background(np.stack([np.asarray(world.frame(i).image) for i in range(0, start, learn_every)]))
    # the background's life as the loop runs it, without a tracker (nobody is trusted: fine for runs
    # shorter than [detection] absorb_s)
    keeper = BackgroundKeeper(rig, det, bg, TrustRule(), float(scenario.fps), learn_n, stride)
    people, false, frames_with_false, lines_above, n_lines = [], 0, 0, 0, 0
    for t in tqdm(range(start, start + n_frames * stride, stride), desc=f"{name} ({measure})", leave=False):
        f = world.frame(t)
        d, trace = detect(det, f.image, keeper.lines)
        M = np.asarray(trace.M)
        lines_above += int((M > np.asarray(det.thresholds.lower)).sum())
        n_lines += M.size
        keeper.update(f.image, d, trace, np.zeros(d.valid.shape, bool))
        tr = f.truth
        valid = np.nonzero(np.asarray(d.valid))[0]
        rule_r, rule_t = (np.asarray(a) for a in detection_sigmas(rig, d.sigma_r_f, d.sigma_theta_f, d.bound_r_f,
                                                                                  d.bound_theta_f, d.r_f))
        used = set()
        th_all = np.asarray(tr.theta_f)
        for p in range(th_all.shape[0]):
            if not (bool(tr.foot_visible[p]) and bool(tr.in_image[p])
                    and float(tr.r_inner[p]) >= r0 and float(tr.r_head[p]) <= r1):
                continue
            th = float(th_all[p])
            others = [abs(wrap_pi(th - th_all[q])) for q in range(th_all.shape[0]) if q != p]
            best = bk = None
            for k in valid:
                if k in used:
                    continue
                dth = abs(wrap_pi(float(d.theta_f[k]) - th))
                half = 0.5 * abs(wrap_pi(float(d.theta_r[k] - d.theta_l[k]))) + 0.05
                if dth <= half and (best is None or dth < best):
                    best, bk = dth, k
            row = {"isolated": min(others, default=math.inf) > 0.35, "found": bk is not None}
            if bk is not None:
                used.add(bk)
                row.update(dr=float(d.r_f[bk]) - float(tr.r_f[p]), sr=float(rule_r[bk]),
                           dth=wrap_pi(float(d.theta_f[bk]) - th), st=float(rule_t[bk]))
            people.append(row)
        false += len(valid) - len(used)
        frames_with_false += int(len(valid) > len(used))
    return rig, {"frames": n_frames, "false_sectors": false, "frames_with_false": frames_with_false,
                 "lines_above_lower": lines_above / max(n_lines, 1)}, people


def chi2_fit(seed: int) -> dict:
    rig, scenario = load_scenario(SCENARIOS / "empty_room.toml")
    world = build_world(rig, scenario, seed=seed, n_frames=40)
    bg = learn_background(np.stack([np.asarray(world.frame(i).image) for i in range(30)]))
    W, H = rig.omni.image_size
    r = np.hypot(*np.meshgrid(np.arange(W) - rig.omni.center[0], np.arange(H) - rig.omni.center[1]))
    inside = r < 0.9 * float(rig.omni.rim)
    mean = np.asarray(bg.mean)
    inside &= np.all((mean > 1) & (mean < 254), -1)  # clipped samples count at 2 by design: not a test of eq 5
    d2 = []
    for i in range(30, 40):
        img = np.asarray(world.frame(i).image)
        ok = inside & np.all((img > 0) & (img < 255), -1)
        d2.append(np.asarray(change_image(img, bg))[ok])
    d2 = np.concatenate(d2)
    sub = np.random.default_rng(seed).choice(d2, 200_000, replace=False)
    ks = stats.kstest(sub, "chi2", args=(2,))
    return {"pixels": int(sub.size), "mean": float(sub.mean()), "ks_D": float(ks.statistic), "ks_p": float(ks.pvalue)}


def nees(rows: list[dict]) -> dict:
    m = [r for r in rows if r["found"]]
    e_r = np.array([(r["dr"] / r["sr"]) ** 2 for r in m])
    e_t = np.array([(r["dth"] / r["st"]) ** 2 for r in m])
    return {"detections": len(m), "nees_r_f": float(e_r.mean()), "nees_theta_f": float(e_t.mean()),
            "median_nees_r_f": float(np.median(e_r)), "median_nees_theta_f": float(np.median(e_t))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=600, help="frames per scenario (default 600)")
    ap.add_argument("--json", metavar="FILE", help="write the figures here")
    args = ap.parse_args()
    out = {"chi2_fit": chi2_fit(seed=7)}
    print("d2 vs chi2(2):", out["chi2_fit"])
    for measure in ("chromaticity", "grey"):
        rig, fa, _ = run_scenario("lamps_switching", args.frames, measure, seed=11, learn_every=1, empty=True)
        fa["x_f"] = float(rig.detection.x_f)
        fa["frame_rate_95"] = clopper_pearson(fa["frames_with_false"], fa["frames"])
        out[f"empty_{measure}"] = fa
        print(f"empty room, {measure}:", fa)
    people = []
    for name, seed in (("one_person", 5), ("three_people", 5)):
        rig, fa, rows = run_scenario(name, args.frames, "chromaticity", seed=seed, stride=2)
        people += rows
        out[f"false_{name}"] = fa
    misses = sum(not r["found"] for r in people)
    iso = [r for r in people if r["isolated"]]
    miss_iso = sum(not r["found"] for r in iso)
    out["misses"] = {"x_m": float(rig.detection.x_m), "person_frames": len(people), "misses": misses,
                     "rate": misses / len(people), "rate_95": clopper_pearson(misses, len(people)),
                     "isolated_person_frames": len(iso), "isolated_misses": miss_iso,
                     "isolated_rate_95": clopper_pearson(miss_iso, len(iso))}
    out["nees_all"] = nees(people)
    out["nees_isolated"] = nees(iso)
    print(json.dumps({k: out[k] for k in ("misses", "nees_all", "nees_isolated")}, indent=1))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
