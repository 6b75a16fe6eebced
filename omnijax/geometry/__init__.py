"""Dual-camera geometry (eq 1-4): image radius -> floor -> pan and tilt; floor <-> image conversions;
angle wrapping."""

from ._angles import (
    wrap_2pi as wrap_2pi,
    wrap_pi as wrap_pi,
)
from ._floor import (
    floor_measurement as floor_measurement,
    floor_to_image as floor_to_image,
    image_position as image_position,
)
from ._person import (
    SHOULDER as SHOULDER,
    person_image_extent as person_image_extent,
)
from ._pointing import (
    D_P_MIN as D_P_MIN,
    PHI_FLOOR_MAX as PHI_FLOOR_MAX,
    Pointing as Pointing,
    floor_radius as floor_radius,
    foveal_offsets as foveal_offsets,
    head_image_radius as head_image_radius,
    image_to_floor as image_to_floor,
    point_image_radius as point_image_radius,
    pointing as pointing,
    pointing_from_floor as pointing_from_floor,
    world_to_image as world_to_image,
)
