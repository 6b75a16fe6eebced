"""Table 1 and containment under the sigma rule, without the maps: ``omnijax validate``'s end-to-end
trials (the same functions, seed and positions), saved once, then scored for any rig's coefficients.

    .venv/bin/python benchmarks/table1_sigmas.py run --config configs/paper.toml --trials 40 \
        --fresh-trials 24 --seed 0 --save OUT.pkl
    .venv/bin/python benchmarks/table1_sigmas.py score --config configs/paper.toml --load OUT.pkl

``score`` prints per position the predicted / empirical var(tan tilt) and var(sin pan) (fixed rig,
fresh person: the paper's Table 1) with the ratio's sampling error, and the containment rate per
rule and p_contain (fresh rig and person), the rig's sigma rule applied to the detector's sigmas.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax

jax.config.update("jax_enable_x64", True)  # as the omnijax command runs
import numpy as np


def main() -> int:
    from runtime.files import load_rig
    from runtime.validation import endtoend as e

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=("run", "score"))
    ap.add_argument("--config", required=True)
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--fresh-trials", type=int, default=24)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--save")
    ap.add_argument("--load")
    args = ap.parse_args()
    rig = load_rig(args.config)
    if args.mode == "run":
        bench = e.prepare(rig, e.table1_scenario(rig, args.seed), seed=args.seed, foot_mc_profiles=64)
        key = jax.random.key(args.seed)
        fixed = [e.trials(bench, foot, args.trials, jax.random.fold_in(key, k), "person")
                 for k, foot in enumerate(bench.positions)]
        fresh = [e.trials(bench, foot, args.fresh_trials, jax.random.fold_in(key, 100 + k), "rig")
                 for k, foot in enumerate(bench.positions)]
        fixed, fresh = (jax.tree.map(np.asarray, v) for v in (fixed, fresh))
        Path(args.save).write_bytes(pickle.dumps({"positions": np.asarray(bench.positions), "fixed": fixed,
                                                  "fresh": fresh}))
        return 0
    data = pickle.loads(Path(args.load).read_bytes())
    for k, (foot, t) in enumerate(zip(data["positions"], data["fixed"])):
        row = e.table_row(rig, f"P{k + 1}", foot, t, True)
        print(f"P{k + 1} n={row['trials']}: tan tilt {row['ratio_tan_tilt']:.3f} +- {row['ratio_tan_tilt_se']:.3f}, "
              f"sin pan {row['ratio_sin_pan']:.3f} +- {row['ratio_sin_pan_se']:.3f}")
    fresh = e.concat(data["fresh"])
    for c in e.containment(rig, fresh):
        print(f"containment {c['rule']} p={c['p_contain']}: {c['rate']:.3f} of {c['trials']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
