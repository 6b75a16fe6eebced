"""The zoom rules' names, defined once: the config's schema, the aim pipeline and every command import them.

A module of its own, without imports from the rest of ``omnijax``, so that the config (which
the zoom kernels take) can use the names without an import cycle.
"""

from __future__ import annotations

from typing import Literal, get_args

#: ``paper``: eq 15 as printed (and its horizontal twin); ``calibrated``: the largest zoom that keeps
#: the whole head in frame with probability ``p_contain`` (DESIGN.md section 4, "Zoom").
ZoomRule = Literal["paper", "calibrated"]
ZOOM_RULES: tuple[str, ...] = get_args(ZoomRule)
