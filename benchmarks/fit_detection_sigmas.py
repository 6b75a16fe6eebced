"""Fit and check the sigma rule (:func:`omnijax.aiming.detection_sigmas`) on rendered scenarios.

Each detection's sigma handed to the pointing covariance is

    sigma_r_f^2     = (sigma_gain_r_f     * detector's sigma_r_f)^2     + bound_r_f^2     + sigma_extra_r_f^2
                      + (sigma_extra_r_f_per_m * R)^2
    sigma_theta_f^2 = (sigma_gain_theta_f * detector's sigma_theta_f)^2 + bound_theta_f^2 + sigma_extra_theta_f^2
                      + (sigma_lateral_m / R)^2

with ``R`` the foot's floor distance (m, at least ``min_floor_radius``)
(``[detection]`` keys; the detector's sigmas carry the per-detection quality: its foot Monte Carlo
for the contrast and radius, and the sector's width beyond one person's for merged sectors and
partial occlusion; the bound parts, a foot the detector could not see, are added as they are).
This script reads pairs of ``omnijax render`` and ``omnijax detect`` output
folders, matches every visible person to the detection whose sector holds them (the convention of
benchmarks/detection_accuracy.py: the true foot azimuth within half the sector's width + 0.05 rad;
isolated = no other person within 0.35 rad), and

- ``fit``: finds the six coefficients by maximum likelihood of a Gaussian in each error (every
  error counts, so the NEES is honest over all detections; ``--outliers`` mixes in a uniform
  outlier share and prints it: errors the detector's quality features do not flag), printing the
  TOML lines for the rig's ``[detection]``; from ``--records`` that carry the people's true heights,
  also ``height_share_r_f`` and ``height_share_head_r_f``, a seen foot's and a foot from the head's
  coupling to the height (:func:`fit_height_share`);
- ``score``: the normalised estimation error squared of r_f and theta_f under the rig's rule
  (mean and share above 6.63, the chi-square(1) 99 % point), overall and for isolated people,
  per folder pair and pooled.

Run (see docs/detection.md, "Honest sigmas"):

    omnijax render --scenario three_people --frames 400 --seed 101 --out R
    omnijax detect R/omni.avi --config configs/paper.toml --out D
    .venv/bin/python benchmarks/fit_detection_sigmas.py fit --config configs/paper.toml R:D ...
    .venv/bin/python benchmarks/fit_detection_sigmas.py score --config configs/paper.toml R2:D2 ...

or on the perception sweep's matched detections (its floor-gated matching, many scenes and seeds):

    .venv/bin/python benchmarks/perception_sweep.py sweep --scenes ... --seeds ... --records out/rec.json
    .venv/bin/python benchmarks/fit_detection_sigmas.py fit --config configs/paper.toml --records out/rec.json
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
from scipy.optimize import minimize

#: NEES of one Gaussian coordinate exceeds this with probability 0.01 (chi-square(1) 99 % point).
NEES_99 = 6.63
#: Matching: the true azimuth within half the sector's width plus this (rad); isolated: no other person this near (rad).
SECTOR_MARGIN, ISOLATED = 0.05, 0.35


def wrap_pi(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def matched(render_dir: Path, detect_dir: Path) -> dict[str, np.ndarray]:
    """Per matched (person, detection): errors, the detector's own sigmas, and whether isolated.

    A person counts where the world says the foot is visible and inside the image; each detection
    matches at most one person (nearest centre first)."""
    truth = {}
    with (render_dir / "truth.jsonl").open() as f:
        for line in f:
            t = json.loads(line)
            truth[t["frame"]] = t["persons"]
    rows = []
    with (detect_dir / "detections.jsonl").open() as f:
        for line in f:
            d = json.loads(line)
            persons = truth.get(d["frame"], [])
            th_all = np.array([p["theta_f"] for p in persons])
            used = set()
            for i, p in enumerate(persons):
                if not (p["in_image"] and p["foot_visible"]):
                    continue
                best, bk = None, None
                for k, q in enumerate(d["people"]):
                    if k in used:
                        continue
                    dth = abs(float(wrap_pi(q["theta_f"] - p["theta_f"])))
                    half = 0.5 * abs(float(wrap_pi(q["theta_r"] - q["theta_l"]))) + SECTOR_MARGIN
                    if dth <= half and (best is None or dth < best):
                        best, bk = dth, k
                if bk is None:
                    continue
                used.add(bk)
                q = d["people"][bk]
                others = np.abs(wrap_pi(np.delete(th_all, i) - p["theta_f"]))
                rows.append((q["r_f"] - p["r_f"], float(wrap_pi(q["theta_f"] - p["theta_f"])),
                             q.get("detector_sigma_r_f", q["sigma_r_f"]),
                             q.get("detector_sigma_theta_f", q["sigma_theta_f"]),
                             float(others.min(initial=math.inf) > ISOLATED),
                             q.get("detector_bound_r_f", 0.0), q.get("detector_bound_theta_f", 0.0), q["r_f"]))
    a = np.array(rows, float).reshape(-1, 8)
    return {"e_r": a[:, 0], "e_t": a[:, 1], "s_r": a[:, 2], "s_t": a[:, 3], "isolated": a[:, 4] > 0,
            "b_r": a[:, 5], "b_t": a[:, 6], "r_f": a[:, 7]}


def pooled(pairs: list[tuple[Path, Path]]) -> dict[str, np.ndarray]:
    parts = [matched(r, d) for r, d in pairs]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def fit_component(e: np.ndarray, s: np.ndarray, bound: np.ndarray | float = 0.0,
                  outliers: bool = False, ranged: np.ndarray | float = 0.0) -> tuple[float, float, float, float]:
    """(gain, extra, range coefficient, outlier share) maximising the likelihood of errors ``e`` under a
    Gaussian with sigma^2 = (gain s)^2 + bound^2 + extra^2 + (coefficient ranged)^2 (``ranged``: R for
    r_f, 1 / R for theta_f; 0: no range term, coefficient 0); with ``outliers``, mixed with a uniform
    outlier over the errors' range. Without (the default), every error counts, so the NEES's mean is honest over all
    detections, gross ones included (what the zoom must survive); with, the fit describes the clean
    core and the outlier share says how much the detector's quality features do not flag."""
    width = 2 * np.max(np.abs(e))
    use_range = bool(np.any(np.asarray(ranged) != 0))
    def nll(p):
        var = (np.exp(2 * p[0]) * s**2 + bound**2 + np.exp(2 * p[1])
               + (np.exp(2 * p[3]) if use_range else 0.0) * ranged**2)
        eps = 1 / (1 + np.exp(-p[2])) if outliers else 0.0
        dens = (1 - eps) * np.exp(-0.5 * e**2 / var) / np.sqrt(2 * np.pi * var) + eps / width
        return -np.sum(np.log(dens))
    scale = np.log(max(np.median(np.abs(e)), 1e-6))
    per = scale - np.log(max(np.median(np.abs(ranged)), 1e-9)) if use_range else 0.0
    # a few starts: from one alone, a term whose log runs off to -inf (a coefficient of 0) stays there
    starts = [np.array([0.0, scale + a, -3.0, per + b]) for a in (0.0, -1.0, -2.0) for b in (0.0, -1.0, -2.0)]
    res = min((minimize(nll, x0, method="Nelder-Mead", options={"xatol": 1e-7, "fatol": 1e-9, "maxiter": 20000})
               for x0 in (starts if use_range else starts[:3])), key=lambda r: r.fun)
    share = float(1 / (1 + np.exp(-res.x[2]))) if outliers else 0.0
    return float(np.exp(res.x[0])), float(np.exp(res.x[1])), float(np.exp(res.x[3])) if use_range else 0.0, share


def from_records(paths: list[Path]) -> dict[str, np.ndarray]:
    """Matched detections written by ``perception_sweep.py --records`` (its floor-gated matching):
    the same keys as :func:`matched`, ``isolated`` all true (the sweep's records do not say)."""
    rows = [r for p in paths for recs in json.loads(p.read_text()).values() for r in recs]
    # older records: no bounds (7 columns), no true r_f (8)
    a = np.array([list(r[:8]) + [np.nan] * (8 - len(r)) for r in rows], float).reshape(-1, 8)
    a[:, 5:7] = np.nan_to_num(a[:, 5:7])
    data = {"e_r": a[:, 1], "e_t": a[:, 2], "s_r": a[:, 3], "s_t": a[:, 4], "isolated": np.ones(len(a), bool),
            "b_r": a[:, 5], "b_t": a[:, 6]}
    if rows and all(len(r) >= 16 for r in rows):  # the person's true height, the foot's height slope, from the head
        h = np.array([r[13:16] for r in rows], float)
        data |= {"H": h[:, 0], "height_r_f": h[:, 1], "from_head": h[:, 2] > 0}
    if np.all(np.isfinite(a[:, 7])):  # the detection's r_f (the true one plus the error): what the rule sees
        return {**data, "r_f": a[:, 7] + a[:, 1]}
    return {**data, "R": a[:, 0]}  # the true foot's floor distance


def fit_height_share(rig, data: dict[str, np.ndarray], from_head: bool) -> tuple[float, int]:
    """The sigma rule's ``height_share_r_f`` (seen feet) or ``height_share_head_r_f`` (``from_head``: feet the
    head placed; :func:`omnijax.aiming.height_coupling`): the least-squares slope, through 0, of those feet's
    r_f errors on ``height_r_f * (H - H_p)`` (what the geometry moves a foot from the head for the person's true
    height ``H``), held to [0, 1]; and the number of feet it used. Needs records with the true heights
    (``perception_sweep.py --records`` of this version); ``nan`` without."""
    if "H" not in data:
        return math.nan, 0
    use = (data["from_head"] == from_head) & np.isfinite(data["H"])
    x = data["height_r_f"][use] * (data["H"][use] - float(rig.person.H_p))
    return float(np.clip(np.sum(data["e_r"][use] * x) / max(np.sum(x * x), 1e-300), 0.0, 1.0)), int(use.sum())


def floor_distances(rig, data: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Each matched detection's foot floor distance R (m, at least ``min_floor_radius``, as the sigma rule
    takes it) and image radius r_f (px), from whichever of the two the data carry."""
    from omnijax.geometry import floor_radius, point_image_radius

    o = rig.omni
    if "R" in data:
        R = data["R"]
        r_f = np.asarray(point_image_radius(np.asarray(R), 0.0, o.r_m, o.H_o, o.profile))
    else:
        r_f = data["r_f"]
        R = np.asarray(floor_radius(np.asarray(r_f), o.r_m, o.H_o, o.profile)[0])
    return np.maximum(R, float(rig.detection.min_floor_radius)), r_f


def nees_figures(e: np.ndarray, s: np.ndarray) -> dict:
    n = (e / s) ** 2
    return {"n": int(n.size), "mean": float(n.mean()) if n.size else None,
            "median": float(np.median(n)) if n.size else None,
            "p_over_6.63": float(np.mean(n > NEES_99)) if n.size else None}


def score(rig, data: dict[str, np.ndarray]) -> dict:
    from omnijax.aiming import detection_sigmas

    _, r_f = floor_distances(rig, data)
    s_r, s_t = (np.asarray(a) for a in detection_sigmas(rig, data["s_r"], data["s_t"], data["b_r"], data["b_t"], r_f))
    out = {}
    for name, sel in (("all", np.ones_like(data["isolated"])), ("isolated", data["isolated"])):
        out[name] = {"r_f": nees_figures(data["e_r"][sel], s_r[sel]),
                     "theta_f": nees_figures(data["e_t"][sel], s_t[sel])}
    return out


def main() -> int:
    from runtime.files import load_rig

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=("fit", "score"))
    ap.add_argument("--config", required=True, help="rig TOML the detections were made with")
    ap.add_argument("pairs", nargs="*", metavar="RENDER:DETECT", help="render and detect output folders")
    ap.add_argument("--records", nargs="+", type=Path, default=[],
                    help="instead of folder pairs: matched detections written by perception_sweep.py --records")
    ap.add_argument("--outliers", action="store_true",
                    help="fit a uniform outlier share beside the Gaussian (the clean core's sigma; the default "
                         "fits every error)")
    args = ap.parse_args()
    pairs = [tuple(Path(x) for x in p.split(":", 1)) for p in args.pairs]
    if not pairs and not args.records:
        ap.error("give RENDER:DETECT folder pairs or --records")
    rig = load_rig(args.config)
    if args.records:
        data = from_records(args.records)
        if args.mode == "score":
            print(json.dumps({"records": score(rig, data)}, indent=1))
            return 0
    if args.mode == "fit":
        data = data if args.records else pooled(pairs)
        R, _ = floor_distances(rig, data)
        g_r, x_r, k_r, o_r = fit_component(data["e_r"], data["s_r"], data["b_r"], args.outliers, R)
        g_t, x_t, k_t, o_t = fit_component(data["e_t"], data["s_t"], data["b_t"], args.outliers, 1.0 / R)
        (share, n_seen), (share_head, n_head) = (fit_height_share(rig, data, h) for h in (False, True))
        print(json.dumps({"detections": int(data["e_r"].size), "isolated": int(data["isolated"].sum()),
                          "outlier_share_r_f": o_r, "outlier_share_theta_f": o_t, "height_share_feet": n_seen,
                          "height_share_head_feet": n_head}))
        print(f"sigma_gain_r_f = {g_r:.4g}\nsigma_extra_r_f = {x_r:.4g}\nsigma_extra_r_f_per_m = {k_r:.4g}\n"
              f"sigma_gain_theta_f = {g_t:.4g}\nsigma_extra_theta_f_deg = {math.degrees(x_t):.4g}\n"
              f"sigma_lateral_m = {k_t:.4g}" + (f"\nheight_share_r_f = {share:.4g}" if n_seen else "")
              + (f"\nheight_share_head_r_f = {share_head:.4g}" if n_head else ""))
        return 0
    per = {f"{r.name}": score(rig, matched(r, d)) for r, d in pairs}
    per["pooled"] = score(rig, pooled(pairs))
    print(json.dumps(per, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
