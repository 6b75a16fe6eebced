"""Writing matplotlib figures (files only), one way for every command's figures."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def save(fig, path: Path, dpi: int) -> None:
    """Write ``fig`` to ``path`` and close it. The constrained layout places axes, labels, titles and
    colour bars only: what is drawn inside an axes (images, contours and their labels, lines, marks)
    is left out of it, since measuring each of those artists' extents was half of ``omnijax optimise``'s
    figures' time (contour labels and room outlines, about 1 s of its 2.2 s of maps) and moved nothing."""
    for ax in fig.axes:
        for artist in (*ax.images, *ax.collections, *ax.lines, *ax.texts, *ax.patches):
            artist.set_in_layout(False)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
