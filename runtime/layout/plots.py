"""Figures of ``omnijax optimise`` (matplotlib, files only): objective maps over the floor before and
after, in the manner of the paper's figure 12, and the objective's landscape over the layout box."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

from omnijax import Rig
from optimise import FloorGrid, FloorValues, SearchResult, place
from runtime.validation.plots import draw_rig

#: Per-point quantity shown by each map, its label and how it is scaled.
MAP_QUANTITIES = {
    "face_px": ("face width (px)", lambda fv: fv.face_px),
    "variance": ("log10 [var(pan) + var(tilt)] (rad$^2$)", lambda fv: np.log10(fv.var_pan + fv.var_tilt)),
    "var_sin_pan": ("log10 var(sin pan) (eq 14)", lambda fv: np.log10(fv.var_sin_pan)),
    "var_tan_tilt": ("log10 var(tan tilt) (eq 13)", lambda fv: np.log10(fv.var_tan_tilt)),
}
_LABELS = {"D_c": "D_c (m)", "H_f": "H_f (m)", "theta_c": "theta_c (deg)", "H_o": "H_o (m)"}


def _layout_text(rig: Rig) -> str:
    f = rig.foveal
    return (f"D_c {float(f.D_c):.2f} m, H_f {float(f.H_f):.2f} m, theta_c {math.degrees(float(f.theta_c)):.0f} deg"
            f", H_o {float(rig.omni.H_o):.2f} m")


def operational(fv: FloorValues, rig: Rig) -> np.ndarray:
    """Floor points served (outside the PTZ's near zone) where p_contain is met and the face target reached."""
    return (np.asarray(fv.weight) > 0) & (np.asarray(fv.feasible) > 0) & (
        np.asarray(fv.face_px) >= float(rig.layout.face_target_px))


def floor_figure(grid: FloorGrid, rig: Rig, result: SearchResult, quantities: list[str], path: Path) -> None:
    """The paper's figure 12: per-point maps over the floor at the configured layout (left) and the
    optimised one (right), cameras and room drawn, the PTZ's left-out near zone dashed and the
    operational region (p_contain met, face >= target) outlined in red.

    One quantity: its map (top) and its contour lines (bottom), as in the paper.
    Several: one row each, map and contour lines together.
    """
    cases = [("configured", place(rig, result.configured), result.values_start, result.summary_start),
             ("optimised", place(rig, result.best), result.values_best, result.summary_best)]
    rows = [(quantities[0], "image"), (quantities[0], "contour")] if len(quantities) == 1 else \
        [(q, "both") for q in quantities]
    ext = grid.extent
    aspect = (ext[3] - ext[2]) / (ext[1] - ext[0])
    if aspect < 0.4:  # a corridor: before and after one above the other, full width
        fig, grid_axes = plt.subplots(2 * len(rows), 1, figsize=(12, 2 * len(rows) * (12 * aspect + 1.6)),
                                      constrained_layout=True, squeeze=False)
        axes = grid_axes.reshape(len(rows), 2)
    else:
        fig, axes = plt.subplots(len(rows), 2, figsize=(12, 4.75 * len(rows)), constrained_layout=True,
                                 squeeze=False)
    for row, (quantity, style) in enumerate(rows):
        label, pick = MAP_QUANTITIES[quantity]
        maps = [grid.to_map(np.where(np.asarray(fv.weight) > 0, pick(fv), np.nan)) for _, _, fv, _ in cases]
        finite = np.concatenate([m[np.isfinite(m)] for m in maps])
        lo, hi = np.percentile(finite, [1, 99]) if finite.size else (0.0, 1.0)
        levels = np.linspace(lo, hi, 9)
        for col, ((name, r, fv, summ), m) in enumerate(zip(cases, maps)):
            ax = axes[row, col]
            if style in ("image", "both"):
                im = ax.imshow(m, origin="lower", extent=ext, cmap="viridis", vmin=lo, vmax=hi,
                               interpolation="nearest")
                fig.colorbar(im, ax=ax, shrink=0.85, label=label, aspect=20 if aspect >= 0.4 else 5)
            if style == "contour":
                ax.imshow(np.where(np.isfinite(m), 1.0, 0.75), origin="lower", extent=ext, cmap="gray", vmin=0,
                          vmax=1, interpolation="nearest")
            if style in ("contour", "both"):
                cs = ax.contour(grid.xs, grid.ys, m, levels=levels, cmap="viridis" if style == "contour" else None,
                                colors="k" if style == "both" else None, linewidths=1.0)
                ax.clabel(cs, fmt="%.3g", fontsize=7)
            colour = "k" if style == "contour" else "w"
            draw_rig(ax, r, min_distance=float(r.layout.near_radius), floor=True, colour=colour)
            ok = grid.to_map(operational(fv, r).astype(float))
            if np.nanmax(ok) > 0 and np.nanmin(ok) < 1:
                ax.contour(grid.xs, grid.ys, np.nan_to_num(ok, nan=0.0), levels=[0.5], colors="r", linewidths=2)
            ax.set_aspect("equal")
            ax.set_xlim(ext[0], ext[1])
            ax.set_ylim(ext[2], ext[3])
            ax.set_xlabel("floor x (m)")
            ax.set_ylabel("floor y (m)")
            ax.set_facecolor("0.75" if style != "contour" else "w")
            if row == 0 or aspect < 0.4:
                ax.set_title(f"{name}: {_layout_text(r)}\nface mean {summ['face_px_mean']:.1f} px, worst "
                             f"{summ['face_px_worst']:.1f} px; operational {100 * summ['operational_fraction']:.0f} %"
                             f"\nvar(pan) + var(tilt) mean {summ['variance_mean']:.3g}, worst "
                             f"{summ['variance_worst']:.3g} rad$^2$", fontsize=9)
    fig.suptitle(f"{' and '.join(MAP_QUANTITIES[q][0] for q in quantities)} over the floor (figure 12 style)\n"
                 f"red: operational region (p_contain met, face >= {float(rig.layout.face_target_px):g} px); "
                 f"dashed: {float(rig.layout.near_radius):g} m around the PTZ's foot, left out; grey: outside the "
                 "room or left out; +: omni axis", fontsize=10)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _panel_axes(result: SearchResult) -> list[str]:
    names = list(result.box.names)
    preferred = [n for n in ("D_c", "H_f") if n in names]
    return (preferred + [n for n in names if n not in preferred])[:2]


def _slice(result: SearchResult, key: str, shown: list[str]) -> np.ndarray:
    """``key`` over the shown variables, the others held at the landscape's best cell for the objective."""
    ls = result.landscape
    names = list(result.box.names)
    best = result.box.values(result.best)
    index = []
    for n, v in zip(names, best):
        index.append(slice(None) if n in shown else int(np.argmin(np.abs(ls.axes[n] - v))))
    arr = ls.summaries[key][tuple(index)]
    order = [n for n in names if n in shown]
    return arr.T if order != shown else arr


def _shown(name: str, values) -> np.ndarray:
    return np.degrees(values) if name == "theta_c" else np.asarray(values)


def landscape_figure(result: SearchResult, rig: Rig, path: Path) -> None:
    """The landscape grid over (D_c, H_f) (or the first varied variables): the objective, mean var(pan),
    mean var(tilt) and the other objective, with the configured layout, the grid's best cell, the
    optimum and every start's end marked."""
    spec = rig.layout
    key = f"{spec.objective}_{spec.statistic}"
    other = ("variance" if spec.objective == "face_px" else "face_px") + f"_{spec.statistic}"
    panels = [(key, f"objective: {key} ({'max' if spec.objective == 'face_px' else 'min'})"),
              ("var_sin_pan_mean", "mean var(sin pan) (eq 14's quantity)"),
              ("var_tan_tilt_mean", "mean var(tan tilt) (eq 13's quantity)"), (other, other)]
    shown = _panel_axes(result)
    names = list(result.box.names)
    fig, axes = plt.subplots(2, 2, figsize=(12, 9.5), constrained_layout=True)
    marks = [(result.configured, "o", "w", "configured"), (result.grid_best, "s", "c", "grid best"),
             (result.best, "*", "r", "optimum")]
    for ax, (k, title) in zip(axes.flat, panels):
        z = _slice(result, k, shown)
        log = k.startswith("var")
        zz = np.log10(z) if log else z
        if len(shown) == 2:
            xs, ys = (_shown(n, result.landscape.axes[n]) for n in shown)
            im = ax.contourf(xs, ys, zz.T, levels=20, cmap="viridis")
            cs = ax.contour(xs, ys, zz.T, levels=10, colors="k", linewidths=0.6)
            ax.clabel(cs, fmt="%.3g", fontsize=7)
            fig.colorbar(im, ax=ax, shrink=0.85, label=("log10 " if log else "") + k)
            for s in result.starts:
                ax.plot(*(_shown(n, s.x[names.index(n)]) for n in shown), "x", color="0.8", ms=6)
            for lay, m, c, lab in marks:
                ax.plot(*(_shown(n, float(getattr(lay, n))) for n in shown), m, color=c, mec="k", ms=11, label=lab)
            if "H_f" in shown and k == "var_tan_tilt_mean":
                h = float(rig.person.H_p - rig.person.R_h)
                line = ax.axhline if shown[1] == "H_f" else ax.axvline
                line(h, color="w", ls="--", lw=1)
            for values, limit in ((xs, ax.set_xlim), (ys, ax.set_ylim)):  # room for markers on the bounds
                pad = 0.03 * (values[-1] - values[0])
                limit(values[0] - pad, values[-1] + pad)
            ax.set_xlabel(_LABELS[shown[0]])
            ax.set_ylabel(_LABELS[shown[1]])
        else:
            xs = _shown(shown[0], result.landscape.axes[shown[0]])
            ax.plot(xs, zz, "k-")
            for lay, _, c, lab in marks:
                x = float(getattr(lay, shown[0]))
                ax.axvline(_shown(shown[0], x), color=c if c != "w" else "0.5", ls="--", label=lab)
            ax.set_xlabel(_LABELS[shown[0]])
            ax.set_ylabel(("log10 " if log else "") + k)
        ax.set_title(title, fontsize=10)
    axes.flat[0].legend(fontsize=8, loc="best")
    held = [n for n in names if n not in shown]
    note = (" (others held at the optimum's grid cell: " + ", ".join(held) + ")") if held else ""
    keys = "x: where each start ended; dashed: H_p - R_h" if len(shown) == 2 else "dashed: the layouts marked"
    fig.suptitle(f"landscape: {result.evaluations['landscape_layouts']} layouts x "
                 f"{result.evaluations['floor_points']} floor points{note}; {keys}", fontsize=10)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _draw_room(ax, rig: Rig, colour: str = "w") -> None:
    """The room's outline and excluded zones, and the omni axis, in floor metres."""
    ax.plot(0.0, 0.0, "+", color=colour, ms=10, mew=2)
    for poly, style in [(rig.room.outline, "-")] + [(z, ":") for z in rig.room.exclude]:
        pts = np.asarray(poly)
        loop = np.vstack([pts, pts[:1]])
        ax.plot(loop[:, 0], loop[:, 1], style, color=colour, lw=1)


def cameras_figure(grid: FloorGrid, rig: Rig, result, path: Path) -> None:
    """k cameras (``optimise.CamerasResult``): each camera's per-point objective where it serves the floor
    (its near zone left out), and the best camera's, with which camera is best outlined; every PTZ
    drawn and numbered, the framed region (p_contain met, face >= target) outlined in red."""
    from optimise import best_camera, framed

    objective = rig.layout.objective
    label, pick = MAP_QUANTITIES[objective]
    fv = result.values
    k = result.k
    per = [grid.to_map(np.where(np.asarray(fv.weight[i]) > 0, np.asarray(pick(_camera(fv, i))), np.nan))
           for i in range(k)]
    arrays = jax.tree.map(jnp.asarray, fv)
    best, weight, which = (np.asarray(a) for a in best_camera(arrays, objective))
    scale = (lambda v: np.log10(v)) if objective == "variance" else (lambda v: v)
    best_map = grid.to_map(np.where(weight > 0, scale(best), np.nan))
    which_map = grid.to_map(which.astype(float))
    ok_map = grid.to_map(np.asarray(framed(rig, arrays)).astype(float))
    finite = np.concatenate([m[np.isfinite(m)] for m in per + [best_map]])
    lo, hi = np.percentile(finite, [1, 99]) if finite.size else (0.0, 1.0)
    panels = [(f"camera {i + 1}", m) for i, m in enumerate(per)] + [("best camera", best_map)]
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    ext = grid.extent
    aspect = (ext[3] - ext[2]) / (ext[1] - ext[0])
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 5.2 * rows * max(aspect, 0.35) + 1.2),
                             constrained_layout=True, squeeze=False)
    for ax in axes.flat[len(panels):]:
        ax.axis("off")
    xs = result.layouts["D_c"] * np.cos(result.layouts["theta_c"])
    ys = result.layouts["D_c"] * np.sin(result.layouts["theta_c"])
    for n, (ax, (title, m)) in enumerate(zip(axes.flat, panels)):
        im = ax.imshow(m, origin="lower", extent=ext, cmap="viridis", vmin=lo, vmax=hi, interpolation="nearest")
        fig.colorbar(im, ax=ax, shrink=0.8, label=label)
        _draw_room(ax, rig)
        for i in range(k):
            ax.plot(xs[i], ys[i], "o", mfc="r" if i == n or n == k else "0.6", mec="k", ms=10, mew=1.5, clip_on=False)
            ax.annotate(str(i + 1), (xs[i], ys[i]), xytext=(7, 7), textcoords="offset points", color="k",
                        fontsize=9, fontweight="bold", annotation_clip=False)
        if n == k:
            for i in range(k if k > 1 else 0):  # each camera's region outlined: one line where two meet
                ax.contour(grid.xs, grid.ys, (which_map == i).astype(float), levels=[0.5], colors="k",
                           linewidths=1.2)
            if np.nanmax(ok_map) > 0 and np.nanmin(ok_map) < 1:
                ax.contour(grid.xs, grid.ys, np.nan_to_num(ok_map, nan=0.0), levels=[0.5], colors="r", linewidths=2)
        ax.set_aspect("equal")
        ax.set_facecolor("0.75")
        pad = 0.04 * max(ext[1] - ext[0], ext[3] - ext[2])  # cameras on the walls stay in view
        ax.set_xlim(ext[0] - pad, ext[1] + pad)
        ax.set_ylim(ext[2] - pad, ext[3] + pad)
        ax.set_title(title, fontsize=10)
    s = result.summary
    fig.suptitle(f"{k} PTZ camera{'s' if k > 1 else ''}: {label} per camera where it serves the floor, and the best "
                 f"camera's (black: where the best camera changes; red: framed region, {100 * s['framing']:.0f} % "
                 f"of the floor)\n{objective} {rig.layout.statistic} over the floor of the best camera: "
                 f"{result.objective:.4g}", fontsize=10)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _camera(fv: FloorValues, i: int) -> FloorValues:
    """Camera ``i``'s per-point values of stacked :class:`~optimise.FloorValues` (NumPy)."""
    return jax.tree.map(lambda a: np.asarray(a)[i], fv)


def marginal_gain_figure(rows: list[dict], rig: Rig, units: str, path: Path) -> None:
    """The objective (left) and the framed share of the floor (right) against the number of PTZs, with
    each added camera's gain written beside its point: how many to buy."""
    k = [r["k"] for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    axes[0].plot(k, [r["objective"] for r in rows], "o-", color="k", label="optimum")
    axes[0].plot(k, [r["grid_objective"] for r in rows], "s--", color="c", mfc="none", label="grid's best set")
    for r in rows[1:]:
        axes[0].annotate(f"{100 * r['gain_rel']:+.1f} %", (r["k"], r["objective"]), xytext=(5, -12),
                         textcoords="offset points", fontsize=8)
    axes[0].set_ylabel(f"{rig.layout.objective} {rig.layout.statistic} of the best camera ({units})")
    axes[0].legend(fontsize=8)
    axes[1].plot(k, [100 * r["framing"] for r in rows], "o-", color="r")
    axes[1].set_ylabel(f"framed floor (%): p_contain met, face >= {float(rig.layout.face_target_px):g} px")
    axes[1].set_ylim(0, 105)
    for ax in axes:
        ax.set_xticks(k)
        ax.set_xlabel("PTZ cameras")
        ax.grid(alpha=0.3)
    fig.suptitle("marginal gain of each added PTZ camera (each k optimised on its own)", fontsize=10)
    fig.savefig(path, dpi=80)
    plt.close(fig)
