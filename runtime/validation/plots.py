"""Figures (matplotlib, files only): the paper's figures 9 and 10 and what goes beyond them."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import SymLogNorm

from omnijax import Rig, world_to_image
from omnijax.uncertainty import METHODS

from .theory import PtzMaps

QUANTITY_LABEL = {
    "sin_pan": r"var(sin pan)",
    "tan_tilt": r"var(tan tilt)",
    "pan": r"var(pan) [rad$^2$]",
    "tilt": r"var(tilt) [rad$^2$]",
}


def draw_rig(ax, rig: Rig, min_distance: float | None = None, floor: bool = False, colour: str = "w") -> None:
    """Omni centre, PTZ foot, room outline and excluded zones, drawn in omni-image pixels
    (or, with ``floor``, in floor metres of the world frame)."""
    omni = rig.omni

    def project(X, Y):
        return (np.asarray(X), np.asarray(Y)) if floor else world_to_image(omni, X, Y, 0.0)

    cx, cy = (0.0, 0.0) if floor else np.asarray(omni.center)
    ax.plot(cx, cy, "+", color=colour, ms=10, mew=2)
    D_c, th = float(rig.foveal.D_c), float(rig.foveal.theta_c)
    px, py = (float(v) for v in project(D_c * np.cos(th), D_c * np.sin(th)))
    ax.plot(px, py, "o", mfc="none", mec=colour, ms=9, mew=2)
    ax.annotate("PTZ", (px, py), xytext=(6, 6), textcoords="offset points", color=colour, fontsize=8)
    if floor:
        ax.annotate("omni", (cx, cy), xytext=(6, -12), textcoords="offset points", color=colour, fontsize=8)
    for poly, style in [(rig.room.outline, "-")] + [(z, ":") for z in rig.room.exclude]:
        pts = np.asarray(poly)
        loop = np.vstack([pts, pts[:1]])
        t = np.linspace(0, 1, 50)[:, None]
        dense = np.vstack([a + t * (b - a) for a, b in zip(loop[:-1], loop[1:])])
        ix, iy = project(dense[:, 0], dense[:, 1])
        ax.plot(np.asarray(ix), np.asarray(iy), style, color=colour, lw=1)
    if min_distance:
        a = np.linspace(0, 2 * np.pi, 100)
        ix, iy = project(D_c * np.cos(th) + min_distance * np.cos(a), D_c * np.sin(th) + min_distance * np.sin(a))
        ax.plot(np.asarray(ix), np.asarray(iy), "--", color=colour, lw=0.8)


def chroma_figure(maps: dict, path: Path, blue: float, sigma: float) -> None:
    """Figure 9: eq 5's ``var r + var g + cov rg`` over (R, G) at fixed B, and Monte Carlo minus it."""
    lv = maps["levels"]
    ext = (lv[0], lv[-1], lv[0], lv[-1])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    im = axes[0].imshow(maps["eq5"], origin="lower", extent=ext, cmap="viridis", norm="log")
    fig.colorbar(im, ax=axes[0], label="variance (chromaticity units$^2$)")
    axes[0].set_title(f"eq 5: var r + var g + cov rg  (B = {blue:g}, sigma = {sigma:g})")
    d = maps["mc_minus_eq5"]
    lim = np.abs(d).max()
    im = axes[1].imshow(d, origin="lower", extent=ext, cmap="RdBu_r", vmin=-lim, vmax=lim)
    fig.colorbar(im, ax=axes[1], label="Monte Carlo - eq 5 (chromaticity units$^2$)")
    axes[1].set_title("difference: simulation - theory")
    for ax in axes:
        ax.set_xlabel("R (grey level)")
        ax.set_ylabel("G (grey level)")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def ptz_figure(maps: PtzMaps, rig: Rig, quantity: str, path: Path, min_distance: float) -> None:
    """Figure 10 and beyond: ``quantity``'s variance by the four methods and their differences.

    Top row: log10 of the variance by autodiff, analytic (eq 13/14), second order
    and Monte Carlo. Bottom row: relative differences in percent (symmetric log
    colour scale) against Monte Carlo, and analytic against autodiff.
    """
    W, H = rig.omni.image_size
    ext = (0, W, H, 0)
    region = maps.region
    v = maps.var
    fig, axes = plt.subplots(2, 4, figsize=(19, 8.6), constrained_layout=True)
    ref = np.log10(v["montecarlo"][quantity][region & (v["montecarlo"][quantity] > 0)])
    lo, hi = np.percentile(ref, [1, 99.5]) if ref.size else (None, None)
    for ax, method in zip(axes[0], METHODS):
        var = v[method][quantity]
        img = np.where(region & (var > 0), np.log10(np.where(var > 0, var, 1.0)), np.nan)
        im = ax.imshow(img, extent=ext, cmap="viridis", vmin=lo, vmax=hi)
        fig.colorbar(im, ax=ax, shrink=0.85, label=f"log10 {QUANTITY_LABEL[quantity]}")
        ax.set_title(f"{method}")
    diffs = [
        ("analytic vs Monte Carlo", v["analytic"][quantity], v["montecarlo"][quantity]),
        ("autodiff vs Monte Carlo", v["autodiff"][quantity], v["montecarlo"][quantity]),
        ("second order vs Monte Carlo", v["second_order"][quantity], v["montecarlo"][quantity]),
        ("analytic vs autodiff", v["analytic"][quantity], v["autodiff"][quantity]),
    ]
    norm = SymLogNorm(linthresh=1.0, vmin=-1000, vmax=1000)
    for ax, (title, a, ref) in zip(axes[1], diffs):
        rel = np.where(region, 100.0 * (a - ref) / ref, np.nan)
        im = ax.imshow(rel, extent=ext, cmap="RdBu_r", norm=norm)
        fig.colorbar(im, ax=ax, shrink=0.85, label="relative difference (%)")
        ax.set_title(title)
    rows, cols = np.nonzero(region)
    pad = 3 * abs(maps.x[0, 1] - maps.x[0, 0])
    x0, x1 = maps.x[0, cols.min()] - pad, maps.x[0, cols.max()] + pad
    y0, y1 = maps.y[rows.min(), 0] - pad, maps.y[rows.max(), 0] + pad
    for ax in axes.flat:
        draw_rig(ax, rig, min_distance)
        ax.set_xlim(max(x0, 0), min(x1, W))
        ax.set_ylim(min(y1, H), max(y0, 0))
        ax.set_xlabel("omni image x (px)")
        ax.set_ylabel("omni image y (px)")
        ax.set_facecolor("0.15")
    fig.suptitle(f"{QUANTITY_LABEL[quantity]} over the room's floor, in omni-image coordinates "
                 f"(+: omni axis; dashed: {min_distance:g} m around the PTZ's foot; grey: outside "
                 f"the room or non-positive)")
    fig.savefig(path, dpi=90)
    plt.close(fig)


def positions_figure(rig: Rig, positions: np.ndarray, path: Path) -> None:
    """Table 1's positions P1-P8 on the floor plan, with the omni axis, the PTZ and the room."""
    fig, ax = plt.subplots(figsize=(7, 5.6), constrained_layout=True)
    draw_rig(ax, rig, floor=True, colour="k")
    for i, (x, y) in enumerate(positions):
        ax.plot(x, y, "o", color="C3", ms=7)
        ax.annotate(f"P{i + 1}", (x, y), xytext=(5, 5), textcoords="offset points", color="C3", fontsize=10)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("Table 1 positions (person standing still), omni axis (+) and PTZ (o)")
    fig.savefig(path, dpi=100)
    plt.close(fig)


def table1_figure(variants: dict[str, list[dict]], path: Path) -> None:
    """Predicted / empirical variance per position, with +-2 sampling errors, for each variant
    (columns) and quantity (rows); the band marks +-10 %. Log scale: the ratios span decades."""
    quantities = (("tan_tilt", "var(tan tilt)"), ("sin_pan", "var(sin pan)"))
    fig, axes = plt.subplots(2, len(variants), figsize=(6.5 * len(variants), 7.5), constrained_layout=True,
                             squeeze=False)
    for col, (title, rows) in enumerate(variants.items()):
        names = [r["position"] for r in rows]
        x = np.arange(len(rows))
        for row_i, (q, label) in enumerate(quantities):
            ax = axes[row_i, col]
            ratio = np.array([r[f"ratio_{q}"] or np.nan for r in rows], float)
            se = np.array([r[f"ratio_{q}_se"] or np.nan for r in rows], float)
            alt = np.array([r[f"pred_var_{q}_measured_detection_sigma"] / r[f"emp_var_{q}"]
                            if r[f"emp_var_{q}"] > 0 else np.nan for r in rows], float)
            ax.axhspan(0.9, 1.1, color="C2", alpha=0.25, lw=0, label="+-10 %")
            ax.errorbar(x, ratio, yerr=2 * se, fmt="o", color="C0", capsize=3,
                        label="predicted with the detector's sigmas")
            ax.plot(x, alt, "x", color="C1", ms=8, mew=2, label="predicted with the measured detection spread")
            ax.axhline(1.0, color="k", lw=0.8)
            ax.set_yscale("log")
            ax.set_xticks(x, names)
            ax.set_ylabel(f"{label}: predicted / empirical")
            ax.set_title(f"{title}: {label}")
            ax.grid(True, which="both", axis="y", alpha=0.3)
            if row_i == 0 and col == 0:
                ax.legend(fontsize=8, loc="best")
    fig.savefig(path, dpi=100)
    plt.close(fig)


def containment_figure(curve: list[dict], path: Path) -> None:
    """Measured containment rate against p_contain for both zoom rules (95 % intervals), and the
    median face width each gives."""
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.6), constrained_layout=True)
    rules = sorted({c["rule"] for c in curve})
    for i, rule in enumerate(rules):
        pts = [c for c in curve if c["rule"] == rule]
        p = np.array([c["p_contain"] for c in pts])
        rate = np.array([c["rate"] for c in pts])
        err = np.array([[c["rate"] - c["lower"], c["upper"] - c["rate"]] for c in pts]).T
        ax.errorbar(p + (i - 0.5) * 0.002, rate, yerr=err, fmt="o-", capsize=3, label=f"rule = {rule}")
        bx.plot(p, [c["face_px_median"] for c in pts], "o-", label=f"rule = {rule}")
    lo = min(min(c["lower"] for c in curve), min(c["p_contain"] for c in curve)) - 0.01
    ax.plot([lo, 1], [lo, 1], "k--", lw=0.8, label="rate = p_contain")
    ax.set_xlabel("p_contain (asked)")
    ax.set_ylabel("measured containment rate")
    ax.set_title("head disc inside the foveal frame (fresh rig per trial)")
    ax.legend()
    ax.grid(alpha=0.3)
    bx.set_xlabel("p_contain (asked)")
    bx.set_ylabel("median face width (px)")
    bx.set_title("what the zoom gives: face pixels")
    bx.legend()
    bx.grid(alpha=0.3)
    fig.savefig(path, dpi=100)
    plt.close(fig)
