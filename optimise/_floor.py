"""The floor region the layout objectives run over: a square grid of points inside the room."""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from omnijax import Room

#: The objectives' point arrays are padded to a multiple of this many points.
PAD_TO = 128


@dataclass(frozen=True)
class FloorGrid:
    """Cell centres of a ``step``-metre grid over the room's bounding box, and which lie in the room.

    ``xs`` (nx,) and ``ys`` (ny,) are the cell centres (m, world frame); ``inside``
    (ny, nx) marks those inside the outline and outside every excluded zone
    (:meth:`omnijax.Room.contains`). The objectives run over the inside points;
    :meth:`to_map` puts per-point values back on the grid for plotting.
    """

    xs: np.ndarray
    ys: np.ndarray
    inside: np.ndarray
    step: float

    def _points(self) -> tuple[np.ndarray, np.ndarray]:
        """The inside points' (X, Y) on the host."""
        return (np.broadcast_to(self.xs[None, :], self.inside.shape)[self.inside],
                np.broadcast_to(self.ys[:, None], self.inside.shape)[self.inside])

    @property
    def X(self) -> Float[Array, " n"]:
        return jnp.asarray(self._points()[0])

    @property
    def Y(self) -> Float[Array, " n"]:
        return jnp.asarray(self._points()[1])

    @property
    def size(self) -> int:
        return int(self.inside.sum())

    def padded(self, multiple: int = PAD_TO) -> tuple[Float[Array, " m"], Float[Array, " m"], Bool[Array, " m"]]:
        """``(X, Y, live)``: the points, repeated at the end up to a multiple of ``multiple``, and which
        are real. Rooms of similar size then share one compiled program (and its cache entry). Built on
        the host: indexing device arrays is an eager program (to compile) per shape."""
        n = self.size
        m = -(-n // multiple) * multiple
        pad = np.arange(m) % n
        X, Y = self._points()
        return jnp.asarray(X[pad]), jnp.asarray(Y[pad]), jnp.asarray(np.arange(m) < n)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(left, right, bottom, top) of the grid's cells, for ``imshow``."""
        h = 0.5 * self.step
        return self.xs[0] - h, self.xs[-1] + h, self.ys[0] - h, self.ys[-1] + h

    def to_map(self, values) -> np.ndarray:
        """Per-point values (n,) as a (ny, nx) array, NaN outside the room."""
        out = np.full(self.inside.shape, np.nan)
        out[self.inside] = np.asarray(values)
        return out


def floor_grid(room: Room, step: float, offset: float = 0.0) -> FloorGrid:
    """The room's floor sampled every ``step`` metres (cell centres inside the room); ``offset`` (a share
    of the step) shifts the grid in x and y, e.g. 0.5 for points between those of the unshifted grid."""
    outline = np.asarray(room.outline)
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    nx, ny = (max(1, math.ceil((b - a) / step - 1e-9)) for a, b in zip(lo, hi))
    mid = 0.5 * (lo + hi) + offset * step
    xs = mid[0] + (np.arange(nx) - 0.5 * (nx - 1)) * step
    ys = mid[1] + (np.arange(ny) - 0.5 * (ny - 1)) * step
    inside = np.asarray(room.contains(xs[None, :], ys[:, None]))
    if not inside.any():
        raise ValueError(f"no floor point of a {step} m grid lies inside the room")
    return FloorGrid(xs=xs, ys=ys, inside=inside, step=float(step))
