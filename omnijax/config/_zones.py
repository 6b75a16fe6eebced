"""Zones of the omni image: polygons (pixels) the detector ignores or whose people are targeted first.

A rig file may hold ``[[zones]]`` tables::

    [[zones]]
    kind = "ignore"                          # ignore | priority
    points = [[412, 80], [470, 96], [452, 150], [398, 130]]   # omni image pixels (x, y), >= 3
    name = "screen"                          # optional

- ``ignore``: no detection there. The detector's polar index drops every line sample (and psi2
  window pixel) inside the polygon when it is built, so nothing is computed there and the
  thresholds count only the samples left (:func:`omnijax.detection.build_polar_index`).
- ``priority``: people standing there (their foot) are chosen before others by the target selector.

A polygon has at least 3 points, all inside the image, encloses some area and does not cross
itself. :func:`parse_zones` checks a list of such tables (from a rig file or from the operator's
console) and raises a one-line :class:`ConfigError` naming the key.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal, get_args

import numpy as np
from annotated_types import Len
from pydantic import Field, field_validator

from ._schema import MAX_IMAGE_SIDE_PX, ConfigError, Section, validate, within

ZoneKind = Literal["ignore", "priority"]
#: What a zone does (``kind``).
ZONE_KINDS: tuple[str, ...] = get_args(ZoneKind)
#: Most points of one zone's polygon, and most zones of a rig.
MAX_ZONE_POINTS, MAX_ZONES = 256, 64

PixelCoord = Annotated[float, within(-1.0, MAX_IMAGE_SIDE_PX, "pixels", why="larger than any camera sensor")]
PixelPoint = Annotated[list[PixelCoord], Len(2, 2)]


@dataclass(frozen=True)
class Zone:
    """One zone: ``kind`` (:data:`ZONE_KINDS`), ``points`` ((x, y) omni image pixels) and an optional ``name``."""

    kind: str
    points: tuple[tuple[float, float], ...]
    name: str | None = None

    def contains(self, x, y) -> np.ndarray:
        """Whether pixel positions (x, y) lie inside the polygon (even-odd rule)."""
        return polygon_contains(np.asarray(self.points, float), x, y)

    def as_dict(self) -> dict:
        """The zone as a ``[[zones]]`` table (and the console's JSON)."""
        out: dict = {"kind": self.kind, "points": [[float(x), float(y)] for x, y in self.points]}
        if self.name is not None:
            out["name"] = self.name
        return out


def polygon_contains(poly: np.ndarray, x, y) -> np.ndarray:
    """Even-odd rule: a horizontal ray from (x, y) crosses the polygon's edges an odd number of times."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    inside = np.zeros(np.broadcast(x, y).shape, bool)
    for (x0, y0), (x1, y1) in zip(poly, np.roll(poly, -1, 0)):
        if y0 == y1:
            continue
        straddles = (y0 > y) != (y1 > y)
        inside ^= straddles & (x < x0 + (y - y0) * (x1 - x0) / (y1 - y0))
    return inside


def _crosses(p, q, r, s) -> bool:
    """Whether segments pq and rs share a point (touching and overlapping included)."""
    def orient(a, b, c):
        v = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        return 0 if abs(v) < 1e-12 else (1 if v > 0 else -1)

    def on(a, b, c):  # c on segment ab, given collinear
        return min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(a[1], b[1])

    o1, o2, o3, o4 = orient(p, q, r), orient(p, q, s), orient(r, s, p), orient(r, s, q)
    if o1 != o2 and o3 != o4:
        return True
    return ((o1 == 0 and on(p, q, r)) or (o2 == 0 and on(p, q, s)) or (o3 == 0 and on(r, s, p))
            or (o4 == 0 and on(r, s, q)))


def self_intersection(points) -> tuple[int, int] | None:
    """The first pair of edges (by their first point's index) of the closed polygon that cross or
    touch other than at their shared corner, or ``None`` for a simple polygon."""
    n = len(points)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue  # neighbours share a corner
            if _crosses(points[i], points[(i + 1) % n], points[j], points[(j + 1) % n]):
                return i, j
    return None


class ZoneSection(Section):
    kind: ZoneKind = Field(description="ignore: no detections there; priority: its people are targeted first")
    points: Annotated[list[PixelPoint], Len(3, MAX_ZONE_POINTS)] = Field(
        description="polygon corners [[x, y], ...] in omni image pixels")
    name: Annotated[str, Len(1, 100)] | None = None

    @field_validator("points")
    @classmethod
    def _simple(cls, points):
        crossing = self_intersection(points)
        if crossing is not None:
            i, j = crossing
            n = len(points)
            raise ValueError(f"edges {i}-{(i + 1) % n} and {j}-{(j + 1) % n} cross; expected a polygon "
                             "that does not cross itself")
        x, y = np.asarray(points, float).T
        area = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
        if area < 1.0:
            raise ValueError(f"points enclose {area:.3g} px^2; expected a polygon around some pixels "
                             "(its corners not all on one line)")
        return points


class _ZoneList(Section):
    zones: Annotated[list[ZoneSection], Len(0, MAX_ZONES)]


def parse_zones(items, image_size: tuple[int, int], source: str = "zones") -> tuple[Zone, ...]:
    """Validated zones from ``[[zones]]`` tables (a list of mappings); each point must lie in the
    ``image_size`` (W, H) image. One-line :class:`ConfigError` naming ``zones.K.key`` otherwise."""
    if not isinstance(items, list):
        raise ConfigError(f"{source}: zones: expected a list of tables (kind, points, name), got "
                          f"{type(items).__name__}")
    return zones_in_image(validate(_ZoneList, {"zones": items}, source).zones, image_size, source)


def zones_in_image(sections: list[ZoneSection], image_size: tuple[int, int], source: str) -> tuple[Zone, ...]:
    """:class:`Zone` s of validated sections, each point checked to lie in the ``image_size`` (W, H) image."""
    W, H = image_size
    zones = []
    for k, z in enumerate(sections):
        for j, (x, y) in enumerate(z.points):
            if not (0 <= x <= W and 0 <= y <= H):
                raise ConfigError(f"{source}: zones.{k}.points: point {j} ({x:g}, {y:g}) lies outside the "
                                  f"{W}x{H} omni image (omni.image_size); expected pixels inside it")
        zones.append(Zone(kind=z.kind, points=tuple((float(x), float(y)) for x, y in z.points), name=z.name))
    return tuple(zones)


def zone_mask(zones: tuple[Zone, ...], kind: str, image_size: tuple[int, int]) -> np.ndarray:
    """Pixels (H, W) whose centres lie inside a zone of ``kind``."""
    W, H = image_size
    mask = np.zeros((H, W), bool)
    for z in zones:
        if z.kind != kind:
            continue
        pts = np.asarray(z.points, float)
        x0, y0 = np.maximum(np.floor(pts.min(0)).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(pts.max(0)).astype(int) + 1, (W, H))
        if x1 <= x0 or y1 <= y0:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1]
        mask[y0:y1, x0:x1] |= polygon_contains(pts, xx, yy)
    return mask
