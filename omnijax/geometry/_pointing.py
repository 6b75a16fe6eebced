"""Dual-camera geometry, eqs 1-4: foot image radius -> floor radius -> PTZ pan and tilt.

All functions are pure, broadcast over leading axes, and keep values *and
gradients* finite at the singular places (double ``where``): under the omni
camera (``r_f = 0``), at or beyond the horizon (``r_f -> r_m``), and with the
person at the foveal camera's foot (``D_p -> 0``). Those places are flagged by a
``valid`` mask instead of returning NaN.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..camera import RadialProfile

#: Largest ray angle accepted for a floor point: R_p <= 100 H_o.
PHI_FLOOR_MAX = math.atan(100.0)
#: Smallest floor distance between the person and the PTZ for which pan is defined, m.
D_P_MIN = 0.05


def floor_radius(r_f, r_m, H_o, profile: RadialProfile) -> tuple[Array, Array]:
    """Floor distance R_p (m) of a foot imaged at radius ``r_f`` (px): eq 1, for any radial camera.

    ``R_p = H_o tan(phi(r_f / r_m))``; for the paraboloid ``tan(phi) = 2 r_m r_f / (r_m^2 - r_f^2)``,
    the paper's ``a``. Returns ``(R_p, valid)``; beyond the floor horizon
    (``phi > PHI_FLOOR_MAX``) or at negative radii R_p is pinned to its limit and
    ``valid`` is False.
    """
    u = jnp.asarray(r_f) / r_m
    valid = (u >= 0) & (u <= profile.u(PHI_FLOOR_MAX))
    u_safe = jnp.where(valid, u, 0.0)
    return jnp.where(valid, H_o * profile.tan_phi(u_safe), H_o * math.tan(PHI_FLOOR_MAX)), valid


def point_image_radius(rho, z, r_m, H_o, profile: RadialProfile) -> Array:
    """Image radius (px) of a world point at floor distance ``rho`` (m) and height ``z`` (m) below H_o."""
    return r_m * profile.u(jnp.arctan2(rho, H_o - z))


def head_image_radius(r_f, r_m, H_o, H_p, profile: RadialProfile) -> Array:
    """Image radius r_h (px) of the top of the head of a person whose foot is at ``r_f``: eq 2.

    With the person upright, the head top is at the foot's floor radius and height
    ``H_p``, so ``r_h = r_m u(atan(R_p / (H_o - H_p)))``; ``r_h > r_f`` for ``r_f > 0``.
    """
    R_p, _ = floor_radius(r_f, r_m, H_o, profile)
    return point_image_radius(R_p, H_p, r_m, H_o, profile)


@jax.custom_jvp
def sincos(a: Array) -> tuple[Array, Array]:
    """``(sin a, cos a)``, each evaluated once for the value and every tangent.

    XLA's CPU fusion counts sin and cos as cheap and copies them into every fused loop that
    reads them: a floor grid's autodiff covariance computed each of them up to sixteen times,
    most of its time. ``lax.rem(v, inf)`` is ``v`` exactly for finite ``v`` but counts as
    costly, so XLA computes it into a buffer of its own, once, and the derivative reuses those
    values. It is elementwise, so it holds under ``vmap`` too, where a conditional (the
    world's ``own_buffer``) becomes a select; ``lax.optimization_barrier``, used before, does
    nothing here (XLA's CPU pipeline removes it before fusion).
    """
    return _own_buffer(jnp.sin(a)), _own_buffer(jnp.cos(a))


def _own_buffer(v: Array) -> Array:
    return jax.lax.rem(v, jnp.inf)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (a,), (t,) = primals, tangents
    s, c = sincos(a)
    return (s, c), (c * t, -s * t)


def foveal_offsets(R_p, vartheta, D_c) -> tuple[Array, Array, Array, Array]:
    """Person position seen from the PTZ, across and along the PTZ-to-omni-axis line: eq 3.

    ``N = R_p sin(vartheta)`` across, ``M = D_c - R_p cos(vartheta)`` along, and
    ``D_p = sqrt(N^2 + M^2)``, which is eq 3's ``sqrt(D_c^2 + R_p^2 - 2 D_c R_p cos vartheta)``
    without its cancellation. Within ``D_P_MIN`` of the PTZ's foot (``near``) the
    offsets are pinned to ``(0, D_P_MIN)`` so that values and gradients stay finite.
    Returns ``(N, M, D_p, near)``.
    """
    sin_v, cos_v = sincos(vartheta)
    N, M = R_p * sin_v, D_c - R_p * cos_v
    near = N * N + M * M < D_P_MIN**2
    N_s = jnp.where(near, 0.0, N)
    M_s = jnp.where(near, D_P_MIN, M)
    return N_s, M_s, jnp.sqrt(N_s * N_s + M_s * M_s), near


class Pointing(eqx.Module):
    """Pan/tilt of the PTZ onto a person's head, with the distances behind them.

    ``pan``, ``tilt`` (rad); ``radius`` R_p and ``distance`` D_p (m, floor);
    ``slant`` (m, PTZ to the head centre, the paper's D'_p); ``valid`` is False at
    the horizon and with the person at the PTZ's foot.
    """

    pan: Float[Array, "*b"]
    tilt: Float[Array, "*b"]
    radius: Float[Array, "*b"]
    distance: Float[Array, "*b"]
    slant: Float[Array, "*b"]
    sin_pan: Float[Array, "*b"]
    tan_tilt: Float[Array, "*b"]
    valid: Bool[Array, "*b"]


def pointing(x: Float[Array, "*b 9"], profile: RadialProfile) -> Pointing:
    """PTZ pan and tilt aimed at the head centre of the person whose foot is imaged at x (eqs 1-4).

    ``x`` holds ``(r_f, theta_f, H_o, H_f, D_c, theta_c, r_m, H_p, R_h)`` in the
    order of ``INPUT_NAMES``. Eq 3: ``D_p = sqrt(D_c^2 + R_p^2 - 2 D_c R_p cos vartheta)``,
    computed as ``sqrt(N^2 + M^2)``; eq 4: ``tan(tilt) = (H_p - R_h - H_f) / D_p``,
    ``pan = atan2(R_p sin vartheta, D_c - R_p cos vartheta)`` (so ``sin(pan)`` is
    eq 4's and pan stays right beyond +-90 deg). Pan is measured at the PTZ from
    the direction of the omni camera's axis, positive towards increasing theta.
    """
    r_f, theta_f, H_o, H_f, D_c, theta_c, r_m, H_p, R_h = jnp.moveaxis(x, -1, 0)
    R_p, ok_floor = floor_radius(r_f, r_m, H_o, profile)
    p = pointing_from_floor(R_p, theta_f - theta_c, D_c, H_p - R_h - H_f)
    return eqx.tree_at(lambda p: p.valid, p, p.valid & ok_floor)


def pointing_from_floor(R_p, vartheta, D_c, aim) -> Pointing:
    """Eqs 3-4 from the person's floor radius ``R_p`` (m), the azimuth ``vartheta = theta_f - theta_c``
    between the person and the PTZ seen from the omni axis, ``D_c`` and the head's height over the
    PTZ ``aim = H_p - R_h - H_f`` (m): the second half of :func:`pointing`, whose inputs each feed
    exactly one of these four (so the first-order covariance factors through them:
    :mod:`omnijax.uncertainty`). ``valid`` is False with the person at the PTZ's foot."""
    N_s, M_s, D_p, near = foveal_offsets(R_p, vartheta, D_c)
    return Pointing(
        pan=jnp.arctan2(N_s, M_s),
        tilt=jnp.arctan2(aim, D_p),
        radius=R_p,
        distance=D_p,
        slant=jnp.hypot(D_p, aim),
        sin_pan=N_s / D_p,
        tan_tilt=aim / D_p,
        valid=~near,
    )


def world_to_image(omni, X, Y, Z) -> tuple[Array, Array]:
    """Pixel (x, y) of the world point (X, Y, Z) (m, world frame of docs/design.md section 3.1)."""
    rho = jnp.hypot(X, Y)
    r = point_image_radius(rho, Z, omni.r_m, omni.H_o, omni.profile)
    return omni.to_pixel(r, jnp.arctan2(Y, X))


def image_to_floor(omni, x, y) -> tuple[Array, Array, Array]:
    """Floor point (X, Y) (m) seen at pixel (x, y), and whether it is a valid floor point."""
    r, theta = omni.to_polar(x, y)
    R_p, valid = floor_radius(r, omni.r_m, omni.H_o, omni.profile)
    return R_p * jnp.cos(theta), R_p * jnp.sin(theta), valid & (r <= omni.rim)
