"""From a foot detection to a PTZ command: pointing, its covariance, and the zoom."""

from __future__ import annotations

from typing import Literal

import equinox as eqx
from jaxtyping import Array, Float

from ..config import Rig
from ..geometry import Pointing, pointing
from ..uncertainty import PointingCovariance, pointing_covariance
from ..zoom import ZoomChoice, choose_zoom


class Aim(eqx.Module):
    """Pan/tilt/zoom for one person, with the geometry and uncertainty behind it."""

    pointing: Pointing
    covariance: PointingCovariance
    zoom: ZoomChoice


def aim_with_covariance(rig: Rig, x: Float[Array, "9"], covariance: PointingCovariance) -> Aim:
    """Pointing at ``x`` and the zoom that ``covariance`` allows under the rig's zoom rule."""
    p = pointing(x, rig.omni.profile)
    zoom = choose_zoom(
        rig.foveal.lens, rig.zoom_rule, covariance.cov, p.distance, p.tilt, p.slant,
        rig.person.R_h, rig.p_contain,
    )
    return Aim(pointing=p, covariance=covariance, zoom=zoom)


@eqx.filter_jit
def aim(
    rig: Rig,
    r_f,
    theta_f,
    sigma_r_f=None,
    sigma_theta_f=None,
    method: Literal["autodiff", "analytic", "second_order"] = "autodiff",
) -> Aim:
    """PTZ command for the foot detected at (``r_f`` px, ``theta_f`` rad), jitted.

    Sigmas default to the rig's ``[detection]`` values; vmap it for many people.
    """
    x = rig.input_mean(r_f, theta_f)
    sigma = rig.input_sigma(sigma_r_f, sigma_theta_f)
    return aim_with_covariance(rig, x, pointing_covariance(x, sigma, rig.omni.profile, method))
