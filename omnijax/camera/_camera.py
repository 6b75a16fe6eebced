"""Omnidirectional camera models behind one interface: image radius r <-> ray angle phi.

Every radial camera maps a ray at angle ``phi`` from the downward optical axis to
an image radius ``r = r_m * u(phi)``, with ``u(pi/2) = 1``: ``r_m`` is the horizon
circle of docs/design.md section 4.1. The profile ``u`` is what distinguishes the models;
``r_m`` stays an explicit input so that its calibration uncertainty propagates.

- :class:`Paraboloid`: the paper's parabolic mirror, ``u = tan(phi / 2)`` (eq 1, 2).
- :class:`Equidistant`: fisheye ``r = f phi``, ``u = phi / (pi / 2)``.
- :class:`Equisolid`: fisheye ``r = 2 f sin(phi / 2)``, ``u = sin(phi / 2) / sin(pi / 4)``.
- :class:`OCamCalib`: Scaramuzza's polynomial model read from ``calib_results.txt``.

Azimuth ``theta`` is measured in the image around the centre, from the image x
axis (columns) towards the image y axis (rows); the world frame takes its x and y
axes from the image, so a world point at azimuth theta images at azimuth theta.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

HALF_PI = math.pi / 2


class RadialProfile(eqx.Module):
    """Normalised radial profile ``u(phi) = r / r_m`` of a camera and its inverse."""

    name: eqx.AbstractClassVar[str]

    @abc.abstractmethod
    def u(self, phi: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
        """Normalised image radius of a ray at angle ``phi`` (rad) from the optical axis."""

    @abc.abstractmethod
    def phi(self, u: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
        """Ray angle (rad) of the normalised image radius ``u = r / r_m``."""

    def tan_phi(self, u: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
        """``tan(phi(u))``: floor distance over height, the factor ``a`` of eq 1."""
        return jnp.tan(self.phi(u))


class Paraboloid(RadialProfile):
    """Orthographic camera looking into a parabolic mirror: ``r = r_m tan(phi / 2)``.

    With ``tan(phi) = R_p / H_o`` this is the paper's eq 1,
    ``R_p = H_o * 2 r_m r_f / (r_m^2 - r_f^2)``.
    """

    name: ClassVar[str] = "paraboloid"

    def u(self, phi):
        return jnp.tan(0.5 * jnp.asarray(phi))

    def phi(self, u):
        return 2.0 * jnp.arctan(jnp.asarray(u))

    def tan_phi(self, u):
        """Eq 1's ``a = 2 r_m r_f / (r_m^2 - r_f^2)``, written in ``u = r_f / r_m``."""
        u = jnp.asarray(u)
        return 2.0 * u / (1.0 - u * u)


class Equidistant(RadialProfile):
    """Equidistant fisheye, ``r = f phi`` with ``f = r_m / (pi / 2)``."""

    name: ClassVar[str] = "equidistant"

    def u(self, phi):
        return jnp.asarray(phi) / HALF_PI

    def phi(self, u):
        return jnp.asarray(u) * HALF_PI


class Equisolid(RadialProfile):
    """Equisolid-angle fisheye, ``r = 2 f sin(phi / 2)`` with ``f = r_m / (2 sin(pi / 4))``."""

    name: ClassVar[str] = "equisolid"

    def u(self, phi):
        return jnp.sin(0.5 * jnp.asarray(phi)) / math.sin(math.pi / 4)

    def phi(self, u):
        s = jnp.asarray(u) * math.sin(math.pi / 4)
        inside = jnp.abs(s) < 1.0  # beyond it the ray would pass 180 deg: pinned there
        return jnp.where(inside, 2.0 * jnp.arcsin(jnp.where(inside, s, 0.0)), jnp.pi * jnp.sign(s))


class OCamCalib(RadialProfile):
    """Scaramuzza's OCamCalib model, as written by its toolbox in ``calib_results.txt``.

    ``cam2world``: a sensor point at radius ``rho`` has the ray ``(x', y', ss(rho))``;
    with ``ss(0) < 0`` the optical axis is ``-z``, so ``phi = atan2(rho, -ss(rho))``.
    ``world2cam``: ``rho = invpol(theta)`` with elevation ``theta = phi - pi/2``.
    ``rho0`` is the horizon radius of the file (``invpol(0)``); the camera's ``r_m``
    scales the whole profile, ``rho = u * rho0`` with ``u = r / r_m``.
    """

    name: ClassVar[str] = "ocamcalib"
    ss: Float[Array, " n_ss"]
    invpol: Float[Array, " n_inv"]
    rho0: float = eqx.field(static=True)

    def u(self, phi):
        theta = jnp.asarray(phi) - HALF_PI
        return jnp.polyval(self.invpol[::-1], theta) / self.rho0

    def phi(self, u):
        rho = jnp.asarray(u) * self.rho0
        return jnp.arctan2(rho, -jnp.polyval(self.ss[::-1], rho))


PROFILES: dict[str, type[RadialProfile]] = {
    p.name: p for p in (Paraboloid, Equidistant, Equisolid, OCamCalib)
}


class OmniCamera(eqx.Module):
    """The overview camera: radial profile, image centre, scale, rim and mounting height.

    ``affine`` holds OCamCalib's (c, d, e) sensor-to-pixel affinity; the ideal
    models use (1, 0, 0). ``rim`` is the radius of the usable image circle (the
    mirror's rim or the fisheye's image circle), in pixels.
    """

    profile: RadialProfile
    center: Float[Array, "2"]
    r_m: Float[Array, ""]
    rim: Float[Array, ""]
    H_o: Float[Array, ""]
    affine: Float[Array, "3"]
    image_size: tuple[int, int] = eqx.field(static=True)

    @property
    def model(self) -> str:
        return self.profile.name

    def radius(self, phi: Float[ArrayLike, "*b"], r_m=None) -> Float[Array, "*b"]:
        """Image radius (px) of a ray at angle ``phi`` (rad); ``r_m`` overrides the nominal one."""
        return (self.r_m if r_m is None else r_m) * self.profile.u(phi)

    def angle(self, r: Float[ArrayLike, "*b"], r_m=None) -> Float[Array, "*b"]:
        """Ray angle (rad, from the downward axis) of image radius ``r`` (px)."""
        return self.profile.phi(jnp.asarray(r) / (self.r_m if r_m is None else r_m))

    def to_pixel(self, r, theta) -> tuple[Array, Array]:
        """Pixel (x, y) of the polar image point (r px, theta rad), affinity included."""
        return self.sensor_to_pixel(r * jnp.sin(theta), r * jnp.cos(theta))

    def sensor_to_pixel(self, xs, ys) -> tuple[Array, Array]:
        """Pixel (x, y) of the sensor point ``(xs, ys) = (r sin theta, r cos theta)``.

        These are OCamCalib's row-wise and column-wise coordinates before its
        affinity (c, d, e) and centre; rotating them is how a pattern of points
        is moved around the image without a sine per point.
        """
        c, d, e = self.affine[0], self.affine[1], self.affine[2]
        return self.center[0] + e * xs + ys, self.center[1] + c * xs + d * ys

    def to_polar(self, x, y) -> tuple[Array, Array]:
        """Polar image point (r px, theta rad) of pixel (x, y); inverse of :meth:`to_pixel`."""
        c, d, e = self.affine[0], self.affine[1], self.affine[2]
        dx, dy = jnp.asarray(x) - self.center[0], jnp.asarray(y) - self.center[1]
        det = c - d * e
        xs = (dy - d * dx) / det
        ys = (-e * dy + c * dx) / det
        return jnp.hypot(xs, ys), jnp.arctan2(xs, ys)


@dataclass(frozen=True)
class OCamCalibFile:
    """The contents of an OCamCalib ``calib_results.txt`` (pixel convention: C, from 0).

    ``center_row``/``center_col`` and ``height``/``width`` are those of the image the
    toolbox saw; pyomniunwarp's files add the ROI radii and the columns cropped
    from the left and right of the original frame.
    """

    ss: tuple[float, ...]
    invpol: tuple[float, ...]
    center_row: float
    center_col: float
    affine: tuple[float, float, float]
    height: int
    width: int
    roi_max: float | None = None
    roi_min: float | None = None
    crop_left: int = 0
    crop_right: int = 0

    @property
    def horizon_radius(self) -> float:
        """``rho0 = invpol(0)``: the sensor radius of the horizontal rays."""
        return float(np.polyval(self.invpol[::-1], 0.0))


def parse_ocamcalib(text: str) -> OCamCalibFile:
    """Parse the text of an OCamCalib ``calib_results.txt``; ``ValueError`` names what is missing.

    The file is a sequence of ``#`` comment headers, each followed by one line of
    numbers; polynomials are written as their length followed by the coefficients
    in increasing order.
    """
    blocks: list[list[float]] = []
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            blocks.append([float(tok) for tok in line.split()])
        except ValueError as exc:
            raise ValueError(f"calib_results.txt: not a line of numbers: {line!r}") from exc
    names = ["ss polynomial", "invpol polynomial", "centre", "affine c d e", "image size"]
    if len(blocks) < len(names):
        raise ValueError(
            f"calib_results.txt: expected at least {len(names)} blocks "
            f"({', '.join(names)}), found {len(blocks)}"
        )

    def poly(block: list[float], what: str) -> tuple[float, ...]:
        n = int(block[0])
        if n != len(block) - 1 or n < 2:
            raise ValueError(f"calib_results.txt: {what} says {n} coefficients, has {len(block) - 1}")
        return tuple(block[1:])

    for block, what, n in zip(blocks[2:5], names[2:5], (2, 3, 2)):
        if len(block) != n:
            raise ValueError(f"calib_results.txt: {what} needs {n} numbers, found {len(block)}")
    ss, invpol = poly(blocks[0], names[0]), poly(blocks[1], names[1])
    if ss[0] >= 0:
        raise ValueError("calib_results.txt: ss[0] must be negative (optical axis along -z)")
    roi = blocks[5] if len(blocks) > 5 and len(blocks[5]) == 2 else None
    crop = blocks[6] if len(blocks) > 6 and len(blocks[6]) == 2 else (0, 0)
    return OCamCalibFile(
        ss=ss,
        invpol=invpol,
        center_row=blocks[2][0],
        center_col=blocks[2][1],
        affine=(blocks[3][0], blocks[3][1], blocks[3][2]),
        height=int(blocks[4][0]),
        width=int(blocks[4][1]),
        roi_max=roi[0] if roi else None,
        roi_min=roi[1] if roi else None,
        crop_left=int(crop[0]),
        crop_right=int(crop[1]),
    )
