"""A reference for the foot that a head's top places: the person model inverted by bisection, independent of
the detector's tables (tests/omnijax/test_aim.py, test_detection.py)."""

from __future__ import annotations

import jax.numpy as jnp


def head_placed_foot(rig, offset: float = 0.0):
    """``placed(R, H)``: the image radius (px) of the axis foot that a person of the prior's height would
    need to show the outer end (omnijax.geometry.person_image_extent) of a person of height ``H`` whose
    axis stands at floor radius ``R`` (m); the outer end taken at ``R + offset`` (the detector's window
    sees the body ``pi rho / 4`` before the axis: ``offset = (pi / 4 - 1) rho``). Broadcasts."""
    from omnijax import person_image_extent, point_image_radius
    from omnijax.detection._polar import body_radius

    o, rho, R_h, H_p = rig.omni, float(body_radius(rig)), float(rig.person.R_h), float(rig.person.H_p)
    outer = lambda R, H: person_image_extent(R + offset, o, H, R_h, rho)[1]

    def placed(R, H):
        out = outer(jnp.asarray(R, float), jnp.asarray(H, float))
        lo, hi = jnp.zeros_like(out), jnp.full_like(out, 20.0)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            big = outer(mid, H_p) > out
            lo, hi = jnp.where(big, lo, mid), jnp.where(big, mid, hi)
        return point_image_radius(0.5 * (lo + hi), 0.0, o.r_m, o.H_o, o.profile)

    return placed
