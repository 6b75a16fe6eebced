"""Figures of a calibration (matplotlib, files only): rim fit, reading residuals, sigmas against K."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from omnijax import GLOBAL_NAMES, PARAM_UNITS, Observations, RigFit, RimEdges, RimFit


def rim_figure(gray: np.ndarray, rim: RimFit, edges: RimEdges, path: Path, file_circle=None) -> None:
    """The frame with the rim's edge points (inliers green, down-weighted red) and the fitted circle;
    ``file_circle`` = (x, y, radius) of a calibration file's centre and rim, drawn dashed."""
    fig, ax = plt.subplots(figsize=(8, 8 * gray.shape[0] / gray.shape[1] + 0.6))
    ax.imshow(gray, cmap="gray", vmin=0, vmax=255)
    pts, w, ok = np.asarray(edges.points), np.asarray(rim.weights), np.asarray(edges.ok)
    good = ok & (w > 0.5)
    ax.plot(pts[good, 0], pts[good, 1], ".", color="lime", ms=2, label="edge points (weight > 0.5)")
    ax.plot(pts[ok & ~good, 0], pts[ok & ~good, 1], ".", color="red", ms=2, label="down-weighted")
    t = np.linspace(0, 2 * np.pi, 721)
    cx, cy, r = float(rim.center[0]), float(rim.center[1]), float(rim.radius)
    ax.plot(cx + r * np.cos(t), cy + r * np.sin(t), "-", color="cyan", lw=0.8,
            label=f"fit: centre ({cx:.1f}, {cy:.1f}), radius {r:.1f} px")
    ax.plot([cx], [cy], "+", color="cyan", ms=12)
    if file_circle is not None:
        fx, fy, fr = file_circle
        ax.plot(fx + fr * np.cos(t), fy + fr * np.sin(t), "--", color="orange", lw=0.8,
                label=f"calibration file: centre ({fx:.1f}, {fy:.1f}), rim {fr:.0f} px")
        ax.plot([fx], [fy], "x", color="orange", ms=10)
    ax.set_xlim(0, gray.shape[1])
    ax.set_ylim(gray.shape[0], 0)
    ax.legend(loc="lower left", fontsize=8, framealpha=0.8)
    ax.set_title("rim fit")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def residual_figure(fit: RigFit, obs: Observations, path: Path, rim: RimFit | None = None,
                    edges: RimEdges | None = None) -> None:
    """Reading residuals (reading minus fitted model, deg) per aim with their 1- and 2-sigma bands,
    and, with a rim fit, the rim's edge residuals (px) around the circle."""
    n = 2 if rim is not None else 1
    fig, axes = plt.subplots(1, n, figsize=(6.5 * n, 4.2), squeeze=False)
    ax = axes[0, 0]
    k = np.arange(obs.pan.shape[0])
    for res, sig, name, marker, dx in ((fit.pan_residual, obs.sigma_pan, "pan", "o", -0.12),
                                       (fit.tilt_residual, obs.sigma_tilt, "tilt", "s", 0.12)):
        ax.errorbar(k + dx, np.degrees(np.asarray(res)), yerr=np.degrees(np.asarray(sig)), fmt=marker,
                    ms=4, capsize=2, label=f"{name}")
    s = math.degrees(float(np.median(np.asarray(obs.sigma_pan))))
    ax.axhspan(-2 * s, 2 * s, color="0.9", zorder=0, label="2 sigma (pan)")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("aim")
    ax.set_ylabel("reading - model (deg)")
    ax.set_title(f"PTZ readings: chi2 {float(fit.chi2):.1f} on {fit.dof} dof")
    ax.legend(fontsize=8)
    if rim is not None:
        ax = axes[0, 1]
        pts, ok, w = np.asarray(edges.points), np.asarray(edges.ok), np.asarray(rim.weights)
        ang = np.degrees(np.arctan2(pts[:, 1] - float(rim.center[1]), pts[:, 0] - float(rim.center[0])))
        res = np.asarray(rim.residuals)
        sc = ax.scatter(ang[ok], res[ok], c=w[ok], s=4, cmap="viridis", vmin=0, vmax=1)
        fig.colorbar(sc, ax=ax, label="Cauchy weight")
        lim = 8 * float(rim.scale)
        ax.set_ylim(-lim, lim)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel("angle around the fitted centre (deg, image x towards y)")
        ax.set_ylabel("edge point - circle (px)")
        ax.set_title(f"rim: residual scale {float(rim.scale):.2f} px, {int(rim.inliers)} inliers")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def sigma_figure(by_positions: list[dict], assumed: dict[str, float], path: Path) -> None:
    """Median calibrated sigma of each rig parameter against the number of floor positions K,
    beside the sigma the rig file assumes (dashed, where it assumes one)."""
    Ks = [b["positions"] for b in by_positions]
    fig, (ax_m, ax_a) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name in GLOBAL_NAMES:
        angle = PARAM_UNITS[name] == "rad"
        ax = ax_a if angle else ax_m
        conv = math.degrees if angle else (lambda v: 100 * v)
        line, = ax.plot(Ks, [conv(b["sigma_median"][name]) for b in by_positions], "o-", label=name)
        if assumed.get(name, 0) > 0:
            ax.axhline(conv(assumed[name]), ls="--", color=line.get_color(), lw=0.8,
                       label=f"{name} assumed in the rig file")
    for ax, unit in ((ax_m, "cm"), (ax_a, "deg")):
        ax.set_xscale("log", base=2)
        ax.set_xticks(Ks, [str(k) for k in Ks])
        ax.set_yscale("log")
        ax.set_xlabel("floor positions K")
        ax.set_ylabel(f"median sigma ({unit})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    ax_m.set_title("lengths")
    ax_a.set_title("angles")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
