"""Zoom from the propagated pointing uncertainty: eq 15 as printed and the calibrated rule."""

from ..config._config import (
    ZOOM_RULES as ZOOM_RULES,
    ZoomRule as ZoomRule,
)
from ._zoom import (
    ZoomChoice as ZoomChoice,
    choose_zoom as choose_zoom,
    containment_probability as containment_probability,
    face_pixels as face_pixels,
    head_half_size as head_half_size,
    paper_fov as paper_fov,
    rectangle_probability as rectangle_probability,
)
