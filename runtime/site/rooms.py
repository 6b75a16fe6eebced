"""One room of a site, as a task a worker runs: the k-camera layout for every candidate k, the choice of
k, and a cheap check of the chosen layout. Everything comes in the :class:`RoomSpec` and goes back as
a JSON-able dict; a room that fails comes back as ``status: failed`` with one line saying why.

The check of a chosen layout (``validation``), without rendering:

- ``floor``: the objective and the framing at the chosen placements on a floor grid shifted by half a
  step (points the search never saw), against those the search reported;
- ``containment``: a Monte Carlo of pointing containment. Each trial picks a point of the shifted
  grid, with the probability the objective weighs it by (none in the PTZs' near zones), and its best
  camera (largest face); draws that PTZ's true rig from
  the calibration sigmas (:func:`omnijax.world.draw_true_rig`), the person's height and head from the
  priors, and the foot's detection error from the rig's default sigmas; aims with the configured rig
  (:func:`omnijax.aim_detection`: pan, tilt and the rule's zoom) and asks the true geometry whether
  the whole head is in the frame (:func:`omnijax.world.head_in_view`). The rate over the trials
  where the zoom meets ``p_contain`` is compared with ``p_contain`` (Clopper-Pearson 95 % interval).
"""

from __future__ import annotations

import os
import socket
import time

from runtime.site.sitefile import RoomSpec

#: Seed of every room's Monte Carlo (with the room's name hashed in): a rerun gives the same figures.
SEED = 26


def setup_jax(cache_dir: str | None) -> None:
    """float64, and the persistent compilation cache shared by every task of the machine (a worker's
    first room compiles, its next rooms of the same sizes, and other workers, reuse the programs)."""
    import jax

    from runtime.compile_cache import use_cache

    jax.config.update("jax_enable_x64", True)
    if cache_dir:
        try:
            os.makedirs(cache_dir, exist_ok=True)
        except OSError:
            return  # a worker on another machine without that folder: compile afresh
        use_cache(cache_dir)


def choose(results: dict, target: float) -> tuple[int, bool]:
    """The fewest PTZs whose framing reaches ``target``; else the most framing (fewest among equals)."""
    for k in sorted(results):
        if results[k].summary["framing"] >= target:
            return k, True
    return max(sorted(results), key=lambda k: results[k].summary["framing"]), False


def _cameras(layouts: dict, k: int) -> list[dict]:
    import math

    return [{"D_c_m": float(layouts["D_c"][i]), "H_f_m": float(layouts["H_f"][i]),
             "theta_c_deg": math.degrees(float(layouts["theta_c"][i]))} for i in range(k)]


def _containment_kernel():
    import jax
    import jax.numpy as jnp

    from omnijax import aim_detection
    from omnijax.geometry import floor_to_image
    from omnijax.world import draw_true_rig, head_in_view

    @jax.jit
    def trials(rigs, X, Y, which, keys):
        """Per trial (point ``X, Y``, camera ``which``, key): whether the head is in the frame, and whether
        the zoom met p_contain."""

        def one(x, y, c, key):
            rig = jax.tree.map(lambda a: a[c], rigs)
            k_rig, k_h, k_r, k_det = jax.random.split(key, 4)
            true = draw_true_rig(rig, k_rig)
            H_p = rig.person.H_p + rig.sigmas.H_p * jax.random.normal(k_h)
            R_h = jnp.maximum(rig.person.R_h + rig.sigmas.R_h * jax.random.normal(k_r), 0.02)
            rt = floor_to_image(true, jnp.stack([x, y]))
            noise = jax.random.normal(k_det, (2,)) * jnp.stack([rig.detection.sigma_r_f, rig.detection.sigma_theta_f])
            a = aim_detection(rig, rt[0] + noise[0], rt[1] + noise[1])
            view = head_in_view(true, a.pointing.pan, a.pointing.tilt, a.zoom.zoom, jnp.stack([x, y, H_p - R_h]), R_h)
            return view.inside, a.zoom.feasible

        return jax.vmap(one)(X, Y, which, keys)

    return trials


_TRIALS = None


def containment_check(rig, cams, x, trials: int, seed: int) -> tuple[dict, dict]:
    """The shifted floor check and the Monte Carlo of pointing containment at box values ``x`` (k, 3) of
    :class:`optimise.Cameras` ``cams`` (see the module docstring)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from optimise import Cameras, best_camera, floor_grid, place, stack
    from runtime.validation.endtoend import binomial

    global _TRIALS
    k = len(x)
    shifted = floor_grid(rig.room, cams.floor.step, offset=0.5)
    other = Cameras(rig, shifted, rigs=cams.slots, cells=cams.cells)
    fv, summ, layouts = other.evaluate(x)
    floor = {"points": shifted.size, "objective": summ[cams.key], "framing": summ["framing"]}
    _, weight, which = (np.asarray(a) for a in best_camera(jax.tree.map(jnp.asarray, fv), rig.layout.objective))
    rng = np.random.default_rng(seed)  # points as the objective weighs them (the PTZs' near zones left out)
    pick = rng.choice(len(weight), size=trials, p=weight / weight.sum())
    placed = stack([place(r, _layout(layouts, rig, i)) for i, r in enumerate(cams.rigs(k))])
    _TRIALS = _TRIALS or _containment_kernel()
    keys = jax.random.split(jax.random.PRNGKey(seed), trials)
    inside, feasible = (np.asarray(a) for a in _TRIALS(placed, jnp.asarray(np.asarray(shifted.X)[pick]),
                                                       jnp.asarray(np.asarray(shifted.Y)[pick]),
                                                       jnp.asarray(which[pick]), keys))
    b = binomial(int(inside[feasible].sum()), int(feasible.sum()))
    containment = {"p_contain": float(rig.p_contain), "rate": b["rate"], "trials": b["n"], "lower": b["lower"],
                   "upper": b["upper"], "feasible_share": float(feasible.mean()), "drawn": trials}
    return floor, containment


def _layout(layouts: dict, rig, i: int):
    import jax.numpy as jnp

    from optimise import Layout

    return Layout(D_c=jnp.asarray(layouts["D_c"][i]), H_f=jnp.asarray(layouts["H_f"][i]),
                  theta_c=jnp.asarray(layouts["theta_c"][i]), H_o=rig.omni.H_o)


def plan_room(spec: RoomSpec, cache_dir: str | None = None) -> dict:
    """Optimise, choose and check one room (a worker's task); never raises: a failure is a result."""
    t0 = time.perf_counter()
    head = {"name": spec.name, "fingerprint": spec.fingerprint, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        setup_jax(cache_dir)
        return {**head, **_plan(spec), "seconds": time.perf_counter() - t0}
    except Exception as exc:  # the room's failure is reported; the site goes on
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        return {**head, "status": "failed", "error": f"{type(exc).__name__}: {text}" if text else type(exc).__name__,
                "seconds": time.perf_counter() - t0}


def _plan(spec: RoomSpec) -> dict:
    import zlib

    from omnijax.config import ConfigError
    from optimise import Cameras, floor_grid
    from runtime.files import build_rig

    if spec.error is not None:
        raise ConfigError(spec.error)

    def calib_text(name: str) -> str:
        if name not in spec.files:
            raise ConfigError(f"{spec.source}: omni.calib_file: {name!r} was not read with the site")
        return spec.files[name]

    rig = build_rig(spec.rig, spec.source, calib_text)
    floor = floor_grid(rig.room, rig.layout.grid_step)
    cams = Cameras(rig, floor, cells=spec.candidates)
    results = {k: cams.search(k) for k in spec.cameras}
    k, met = choose(results, spec.framing_target)
    res = results[k]
    seed = SEED + zlib.crc32(spec.name.encode())
    floor_check, containment = containment_check(rig, cams, res.x, spec.trials, seed)
    floor_check["objective_rel_diff"] = (floor_check["objective"] - res.objective) / abs(res.objective)
    floor_check["framing_diff"] = floor_check["framing"] - res.summary["framing"]
    sense_max = rig.layout.objective == "face_px"
    return {
        "status": "ok",
        "k": k,
        "cameras": _cameras(res.layouts, k),
        "objective": res.objective,
        "objective_name": f"{rig.layout.objective}_{rig.layout.statistic}",
        "units": "px" if sense_max else "rad^2",
        "framing": res.summary["framing"],
        "framing_target": spec.framing_target,
        "target_met": met,
        "cost": k * spec.ptz_price,
        "floor_points": floor.size,
        "candidates": [{"k": kk, "objective": r.objective, "framing": r.summary["framing"],
                        "grid_objective": r.grid_objective, "grid_method": r.grid_method,
                        "cameras": _cameras(r.layouts, kk), "seconds": sum(r.seconds.values())}
                       for kk, r in sorted(results.items())],
        "validation": {"floor": floor_check, "containment": containment},
    }
