"""Conversions between a detection in the omni image and a position on the floor, with covariances
by autodiff (the tracker's measurements, and its predictions back to the pointing's inputs).

A detection (r_f, theta_f) with its sigmas becomes a floor measurement z = (X, Y) = R_p (cos, sin)
(eq 1) with ``R = J diag(sigma^2) J^T``. Only detection noise enters the filter: calibration
errors are systematic (the same at every frame) and are added when pointing. A predicted floor
state goes back to the image as (r_f, theta_f) with a full 2 x 2 covariance for the pointing.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..config import Rig
from ._pointing import floor_radius, point_image_radius


def _floor_point(rt, r_m, H_o, profile):
    R, _ = floor_radius(rt[0], r_m, H_o, profile)
    return jnp.stack([R * jnp.cos(rt[1]), R * jnp.sin(rt[1])])


def _image_point(xy, r_m, H_o, profile):
    rho = jnp.hypot(xy[0], xy[1])
    return jnp.stack([point_image_radius(rho, 0.0, r_m, H_o, profile), jnp.arctan2(xy[1], xy[0])])


@jax.jit
def floor_measurement(
    rig: Rig, r_f, theta_f, sigma_r_f, sigma_theta_f
) -> tuple[Float[Array, "*b 2"], Float[Array, "*b 2 2"]]:
    """Floor position (m) of detections and its covariance from the detection sigmas (eq 1, autodiff)."""
    o = rig.omni
    rt = jnp.stack(jnp.broadcast_arrays(jnp.asarray(r_f, float), jnp.asarray(theta_f, float)), -1)
    s2 = jnp.stack(jnp.broadcast_arrays(jnp.asarray(sigma_r_f, float) ** 2, jnp.asarray(sigma_theta_f, float) ** 2), -1)
    f = lambda v: _floor_point(v, o.r_m, o.H_o, o.profile)
    flat, s2f = rt.reshape(-1, 2), s2.reshape(-1, 2)
    z = jax.vmap(f)(flat)
    J = jax.vmap(jax.jacfwd(f))(flat)
    R = jnp.einsum("kai,ki,kbi->kab", J, s2f, J)
    return z.reshape(*rt.shape[:-1], 2), R.reshape(*rt.shape[:-1], 2, 2)


@jax.jit
def floor_to_image(rig: Rig, xy: Float[Array, "*b 2"]) -> Float[Array, "*b 2"]:
    """(r_f, theta_f) (px, rad) at which the omni camera sees floor points ``xy`` (m): eq 1 inverted."""
    o = rig.omni
    xy = jnp.asarray(xy, float)
    return jnp.moveaxis(_image_point(jnp.moveaxis(xy, -1, 0), o.r_m, o.H_o, o.profile), 0, -1)


@jax.jit
def image_position(rig: Rig, xy: Float[Array, "*b 2"], cov: Float[Array, "*b 2 2"]) -> tuple[Array, Array]:
    """(r_f, theta_f) of floor positions and their 2 x 2 covariance (autodiff of the projection)."""
    o = rig.omni
    f = lambda v: _image_point(v, o.r_m, o.H_o, o.profile)
    flat, cf = xy.reshape(-1, 2), cov.reshape(-1, 2, 2)
    rt = jax.vmap(f)(flat)
    J = jax.vmap(jax.jacfwd(f))(flat)
    C = J @ cf @ jnp.swapaxes(J, -1, -2)
    return rt.reshape(*xy.shape[:-1], 2), C.reshape(*xy.shape[:-1], 2, 2)
