"""The person model the detector and the world share: the paper's upright cylinder (footnote 3) with a head."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array

from ._pointing import point_image_radius

#: Shoulder height over body height (adult anthropometry, ~0.82): where the body cylinder ends.
SHOULDER = 0.82


def person_image_extent(R, omni, H_p, R_h, body_radius) -> tuple[Array, Array]:
    """Radial extent ``(r_in, r_out)`` (px) in the omni image of an upright person whose axis stands
    at floor distance ``R`` (m): the paper's cylinder (footnote 3) with a head.

    The body is a cylinder of radius ``body_radius`` from the floor to the shoulders at
    ``SHOULDER * H_p`` (as the synthetic world draws people), topped by a head sphere of radius ``R_h``
    whose top is at ``H_p``.
    The inner end is the body's foot nearest the omni axis (r_f of eq 1 for the floor
    point ``R - body_radius``); the outer end is the farthest imaged point of the
    shoulders or head (eq 2's r_h, generalised to the head's outline).
    """
    R, H_p, R_h = jnp.broadcast_arrays(jnp.asarray(R, float), jnp.asarray(H_p, float), jnp.asarray(R_h, float))
    r_in = point_image_radius(jnp.maximum(R - body_radius, 0.0), 0.0, omni.r_m, omni.H_o, omni.profile)
    a = jnp.linspace(0.0, jnp.pi, 13)
    R, H_p, R_h = R[..., None], H_p[..., None], R_h[..., None]
    rho = jnp.concatenate([jnp.broadcast_to(body_radius, R.shape), R_h * jnp.sin(a)], -1)
    z = jnp.concatenate([SHOULDER * H_p, H_p - R_h + R_h * jnp.cos(a)], -1)
    r_out = point_image_radius(R + rho, z, omni.r_m, omni.H_o, omni.profile).max(-1)
    return r_in, r_out
