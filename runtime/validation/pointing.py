"""The pointing actually made against the truth: its NEES under the aim's covariance, and containment.

For a frame on which the PTZ points at (pan, tilt) (the loop's command it has arrived at, or in
``omnijax validate`` a trial's aim) with the aim's predicted 2 x 2 covariance ``C`` of (pan, tilt),
and the true head direction (pan*, tilt*): eq 1-4 with the world's true rig and the true person,
the pan/tilt that put the true head's centre at the foveal image's centre (:func:`head_direction`),
the normalised estimation error squared is

    NEES = e^T C^-1 e,  e = (wrap(pan - pan*), tilt - tilt*),

chi-square with 2 degrees of freedom when ``C`` is right: mean 2, P(NEES > 5.99) = 0.05.
:func:`nees_summary` reports ``nees_mean`` per degree of freedom (the mean NEES over 2: 1 when
``C`` is right) and ``nees_over_5_99`` (0.05 when right).

Containment (:func:`containment_at`): whether the true head disc lies in the foveal frame at the
pan/tilt held and the zoom each rule chooses from ``C`` for each p_contain.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from omnijax import Rig, pointing
from omnijax.geometry import floor_to_image, wrap_pi
from omnijax.world import head_in_view
from omnijax.zoom import ZOOM_RULES, choose_zoom

#: Containment of the pointing is measured at these p_contain.
P_CONTAIN = (0.9, 0.95, 0.99)
#: chi-square(2)'s 95 % point: a right covariance's NEES exceeds it in 5 % of the frames.
NEES_95_2DOF = -2.0 * math.log(0.05)


@jax.jit
def head_direction(true_rig: Rig, foot, H_p, R_h) -> tuple[jax.Array, jax.Array]:
    """Pan and tilt (rad) that put the head centre of a person standing at ``foot`` (m, (..., 2)) with
    height ``H_p`` and head radius ``R_h`` (m) at the foveal image's centre, in ``true_rig`` (eq 1-4)."""
    o, f = true_rig.omni, true_rig.foveal
    rt = floor_to_image(true_rig, foot)
    r_f, theta_f = rt[..., 0], rt[..., 1]
    c = lambda v: jnp.broadcast_to(jnp.asarray(v, float), r_f.shape)
    x = jnp.stack([r_f, theta_f, c(o.H_o), c(f.H_f), c(f.D_c), c(f.theta_c), c(o.r_m), c(H_p), c(R_h)], -1)
    p = pointing(x, o.profile)
    return p.pan, p.tilt


@jax.jit
def nees(pan, tilt, cov2, pan_true, tilt_true) -> jax.Array:
    """NEES of the pointing (pan, tilt) rad against the truth under ``cov2`` ((..., 2, 2) of pan, tilt)."""
    e = jnp.stack([wrap_pi(pan - pan_true), tilt - tilt_true], -1)
    return jnp.einsum("...i,...i->...", e, jnp.linalg.solve(cov2, e[..., None])[..., 0])


def nees_summary(values, pan_sq=None, tilt_sq=None) -> dict:
    """``pointing`` figures of NEES ``values`` (2 degrees of freedom): ``nees_mean`` (per degree of
    freedom, 1 when the covariance is right) with its standard error, ``nees_over_5_99`` (0.05 when
    right), ``frames``; with ``pan_sq``, ``tilt_sq`` (each axis's squared error over its variance) their
    means (1 each when right)."""
    v = np.asarray(values, float).reshape(-1)
    n = v.size
    out = {"nees_mean": float(v.mean() / 2) if n else None,
           "nees_mean_se": float(v.std(ddof=1) / 2 / math.sqrt(n)) if n > 1 else None,
           "nees_over_5_99": float(np.mean(v > NEES_95_2DOF)) if n else None, "frames": int(n),
           "dof": 2, "expected": {"nees_mean": 1.0, "nees_over_5_99": 0.05}}
    if pan_sq is not None:
        out["pan_nees_mean"] = float(np.mean(pan_sq)) if n else None
        out["tilt_nees_mean"] = float(np.mean(tilt_sq)) if n else None
    return out


@jax.jit
def pointing_errors(pan, tilt, cov2, pan_true, tilt_true):
    """NEES, and each axis's squared error over its variance, per frame."""
    e_pan, e_tilt = wrap_pi(pan - pan_true), tilt - tilt_true
    return (nees(pan, tilt, cov2, pan_true, tilt_true), e_pan**2 / cov2[..., 0, 0], e_tilt**2 / cov2[..., 1, 1])


@jax.jit
def containment_at(rig: Rig, true_rig: Rig, pan, tilt, cov4, distance, slant, head, R_h_true, p_contain):
    """Whether the true head (centre ``head`` m, radius ``R_h_true``) lies in the foveal frame of
    ``true_rig`` at (``pan``, ``tilt``) and the zoom each rule of :data:`~omnijax.zoom.ZOOM_RULES` chooses
    from the pointing covariance ``cov4`` (4 x 4) for each ``p_contain``: (..., p, rule) booleans."""
    lens, R_h = rig.foveal.lens, rig.person.R_h

    def one(p):
        zooms = [choose_zoom(lens, rule, cov4, distance, tilt, slant, R_h, p).zoom for rule in ZOOM_RULES]
        return jnp.stack([head_in_view(true_rig, pan, tilt, z, head, R_h_true).inside for z in zooms])

    return jax.vmap(one)(jnp.asarray(p_contain, float))
