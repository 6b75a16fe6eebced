"""The rig's ``[[zones]]`` in the running loop: the priority zones as floor polygons for the target
selector, and a new set of zones made ready off the control thread (:func:`zone_swap`).

A priority zone is drawn on the omni image; whether a person stands in it is asked of their floor
position (the tracker's), so each zone's outline is mapped to the floor once, every edge subdivided
(a straight edge in the image is a curve on the floor), points beyond the floor's horizon pulled in
to just inside it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from omnijax import Rig, image_to_floor
from omnijax.config import Zone, polygon_contains
from omnijax.detection import with_zones
from runtime.realtime.operator import ZoneSwap

#: Points per edge of a zone's outline when it is mapped to the floor.
EDGE_POINTS = 16
#: Image radius, as a share of the horizon's (r_m), beyond which outline points are pulled in.
HORIZON_SHARE = 0.98


def floor_polygon(rig: Rig, zone: Zone) -> np.ndarray:
    """The floor outline (n, 2) m of a zone drawn on the omni image."""
    pts = np.asarray(zone.points, float)
    s = np.arange(EDGE_POINTS)[:, None] / EDGE_POINTS
    dense = np.concatenate([a + s * (b - a) for a, b in zip(pts, np.roll(pts, -1, 0))])
    omni = rig.omni
    r, theta = (np.asarray(v) for v in omni.to_polar(dense[:, 0], dense[:, 1]))
    r = np.minimum(r, HORIZON_SHARE * float(min(omni.r_m, omni.rim)))
    x, y = omni.to_pixel(r, theta)
    X, Y, _ = image_to_floor(omni, x, y)
    return np.stack([np.asarray(X), np.asarray(Y)], -1)


def priority_test(rig: Rig, zones: tuple[Zone, ...] | None = None) -> Callable[[np.ndarray], bool] | None:
    """``inside(xy) -> bool`` for a floor point (m): in any priority zone of ``zones`` (default the rig's);
    ``None`` when there is none."""
    polygons = [floor_polygon(rig, z) for z in (rig.zones if zones is None else zones) if z.kind == "priority"]
    if not polygons:
        return None
    return lambda xy: any(bool(polygon_contains(p, xy[0], xy[1])) for p in polygons)


def zone_swap(rig: Rig, detector, zones: tuple[Zone, ...], version: int) -> ZoneSwap:
    """Everything the loop needs to take ``zones`` in (seconds of work: run it off the control thread)."""
    zoned = dataclasses.replace(rig, zones=tuple(zones))
    return ZoneSwap(detector=with_zones(detector, zoned), priority=priority_test(zoned), zones=tuple(zones),
                    version=version)
