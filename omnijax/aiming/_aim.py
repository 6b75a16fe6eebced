"""The one aim pipeline: a detection with its sigmas (or a tracked floor position with its covariance)
-> pointing, its covariance, and the zoom of each rule (docs/design.md section 4.12; the sigma rule
is section 4.8, the propagation 4.10, the zoom 4.11).

The stages, written once and used by the loop, validation, calibration and the optimiser:

1. :func:`detection_sigmas`, the sigma rule: a detection's (sigma_r_f, sigma_theta_f) are the
   detector's own, scaled and widened by the rig's fitted ``[detection]`` coefficients; without
   the detector's, the rig's defaults.
2. :func:`floor_from_detections`: detections -> floor positions (m) with their 2 x 2 covariance
   under the sigma rule (the tracker's measurements; eq 1, autodiff).
3. :func:`aim_from_image`, the core: the foot at (r_f, theta_f) with a full 2 x 2 covariance joins
   the rig's calibration sigmas and the person priors in the nine inputs' covariance
   (docs/design.md section 3.2), ``J Sigma J^T`` (autodiff) gives the pointing covariance, and
4. :func:`aim_with_covariance`: pan/tilt and the zoom of each rule asked for (``paper``,
   ``calibrated``; :data:`omnijax.zoom.ZOOM_RULES`) from a pointing covariance.

Entry points: :func:`aim_detection` (a detection: stage 1, then 3), :func:`aim_at_floor` (a floor
point with its covariance, e.g. the tracker's prediction: back to the image, then 3; without a
covariance, a detection there with the rig's default sigmas), and :func:`aim` (``omnijax
variance``: one foot with the sigmas as given and a choice of propagation method).

Every entry point aims at one person and is jitted; ``jax.vmap`` it for many. Geometry and
covariances are meant for float64; everything is differentiable (the calibrated zoom through its
implicit-function-theorem JVP), which the layout optimiser relies on.
"""

from __future__ import annotations

import functools
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..calibration import with_mounting_sigma
from ..config import INPUT_NAMES, Rig
from ..geometry import Pointing, floor_measurement, floor_radius, floor_to_image, image_position, pointing
from ..uncertainty import PointingCovariance, pointing_covariance, pointing_covariance_full
from ..zoom import ZOOM_RULES, ZoomChoice, choose_zoom


class Aim(eqx.Module):
    """Pan/tilt/zoom for one person, with the geometry and uncertainty behind it.

    ``x``: the nine inputs' means (``INPUT_NAMES`` order: the foot's (r_f, theta_f) first);
    ``zooms``: the zoom of each rule computed, by rule name; ``zoom``: the rig's rule's.
    """

    pointing: Pointing
    covariance: PointingCovariance
    zooms: dict[str, ZoomChoice]
    x: Float[Array, "*b 9"]
    rule: str = eqx.field(static=True)

    @property
    def zoom(self) -> ZoomChoice:
        """The zoom under the rig's rule (``rule``)."""
        return self.zooms[self.rule]


def _rules(rig: Rig, rules) -> tuple[str, ...]:
    """The rules to compute: the rig's, then those asked for, each once, all known."""
    out = tuple(dict.fromkeys((rig.zoom_rule, *(() if rules is None else rules))))
    unknown = [r for r in out if r not in ZOOM_RULES]
    if unknown:
        raise ValueError(f"zoom rules must be among {ZOOM_RULES}, got {unknown}")
    return out


def detection_sigmas(rig: Rig, sigma_r_f=None, sigma_theta_f=None, bound_r_f=0.0, bound_theta_f=0.0, r_f=None
                     ) -> tuple[Array, Array]:
    """The sigma rule: the (sigma_r_f px, sigma_theta_f rad) handed to the covariance for a detection.

    Per coordinate, in quadrature: ``gain * detector's sigma``, the detector's ``bound``, a constant
    ``extra``, and a term of the foot's floor distance ``R`` (from ``r_f``, px; eq 1), with the rig's
    ``[detection]`` coefficients::

        sigma_r_f^2 = (sigma_gain_r_f * s_r)^2 + bound_r^2 + sigma_extra_r_f^2 + (sigma_extra_r_f_per_m * R)^2
        sigma_theta_f^2 = (sigma_gain_theta_f * s_t)^2 + bound_t^2 + sigma_extra_theta_f^2 + (sigma_lateral_m / R)^2

    The detector's sigmas carry each detection's quality (the foot's Monte Carlo at its contrast and
    radius; a sector wider or narrower than one person there: two people or a ghost in it, partial
    occlusion; the foot at the sampled range's edge); the gains and the other terms calibrate them
    against the synthetic world's truth (benchmarks/fit_detection_sigmas.py; docs/detection.md,
    "Honest sigmas"). The range terms are what a constant could not carry: the foot's radius is worse
    the farther the person (lower contrast, the upper body against the walls), and an error across
    the line of sight of a few millimetres of floor (the legs' pose, the body's outline) is a larger
    azimuth the nearer the person (``R`` at least ``min_floor_radius``). The detector's bound part
    (``Detections.bound_r_f``, ``bound_theta_f``: a foot it could not see, of a person reaching into
    the blind disc under the camera or past the image's edge) is added as it is: it is a spread of
    where the foot can be, not a quality the gain calibrates. ``None`` (an aim without a detection:
    the layout optimiser, calibration points): the rig's ``sigma_r_f``, ``sigma_theta_f`` as they
    are. ``r_f`` ``None``: no range terms. Broadcasts.
    """
    d = rig.detection
    if r_f is None:
        range_r = range_t = 0.0
    else:
        omni = rig.omni
        R = jnp.maximum(floor_radius(jnp.asarray(r_f, float), omni.r_m, omni.H_o, omni.profile)[0], d.min_floor_radius)
        range_r, range_t = d.sigma_extra_r_f_per_m * R, d.sigma_lateral_m / R
    rule = lambda gain, s, bound, extra, ranged: jnp.sqrt(
        (gain * s) ** 2 + jnp.asarray(bound) ** 2 + extra**2 + ranged**2)
    s_r = (d.sigma_r_f if sigma_r_f is None
           else rule(d.sigma_gain_r_f, sigma_r_f, bound_r_f, d.sigma_extra_r_f, range_r))
    s_t = (d.sigma_theta_f if sigma_theta_f is None
           else rule(d.sigma_gain_theta_f, sigma_theta_f, bound_theta_f, d.sigma_extra_theta_f, range_t))
    return jnp.asarray(s_r, float), jnp.asarray(s_t, float)


@jax.jit
def floor_from_detections(rig: Rig, r_f, theta_f, sigma_r_f, sigma_theta_f, bound_r_f=0.0, bound_theta_f=0.0
                          ) -> tuple[Float[Array, "*b 2"], Float[Array, "*b 2 2"]]:
    """Floor positions (m) of detections and their covariance under :func:`detection_sigmas` (eq 1).

    Only detection noise enters (calibration errors are the same at every frame and are added
    when pointing). Broadcasts over detections.
    """
    s_r, s_t = detection_sigmas(rig, sigma_r_f, sigma_theta_f, bound_r_f, bound_theta_f, r_f)
    return floor_measurement(rig, r_f, theta_f, s_r, s_t)


def aim_with_covariance(rig: Rig, x: Float[Array, "9"], covariance: PointingCovariance,
                        rules: tuple[str, ...] | None = None) -> Aim:
    """Pointing at ``x`` and the zoom ``covariance`` allows, under the rig's rule and ``rules``."""
    p = pointing(x, rig.omni.profile)
    zooms = {rule: choose_zoom(rig.foveal.lens, rule, covariance.cov, p.distance, p.tilt, p.slant,
                               rig.person.R_h, rig.p_contain) for rule in _rules(rig, rules)}
    return Aim(pointing=p, covariance=covariance, zooms=zooms, x=x, rule=rig.zoom_rule)


def height_coupling(rig: Rig, height_r_f, from_head) -> Array:
    """The foot's coupling to the person's height (px per metre above the prior's), the sigma rule's part: a
    share of ``height_r_f`` (:attr:`~omnijax.detection.Detections.height_r_f`, how the geometry moves a foot
    that the head's top and the prior's height placed), the rig's fitted ``height_share_head_r_f`` for a
    foot the head placed (1: the geometry's; the head's top is found with the height too), and
    ``height_share_r_f`` for a foot seen (eq 12's window of the prior's length slides along a taller
    person's change)."""
    d = rig.detection
    share = jnp.where(jnp.asarray(from_head), d.height_share_head_r_f, d.height_share_r_f)
    return share * jnp.asarray(height_r_f, float)


def input_covariance(rig: Rig, cov_image: Float[Array, "2 2"], coupling=0.0) -> Float[Array, "9 9"]:
    """Covariance of the nine inputs: the foot's (r_f, theta_f) block, then the rig's calibration
    sigmas and the person priors, independent but for the foot's radius and the height.

    A foot whose error follows the person's height (``coupling`` px per metre above the prior's:
    :func:`height_coupling`) errs with the opposite sign to the aim's height, the prior's:
    ``cov(r_f, H_p) = -coupling sigma_H_p^2``, held to a correlation of at most 1 in size against the
    block's ``var(r_f)`` (the sigma rule may have narrowed the radius below the height's own part)."""
    sig = rig.input_sigma(0.0, 0.0)
    h = INPUT_NAMES.index("H_p")
    bound = jnp.sqrt(jnp.maximum(cov_image[0, 0], 0.0)) * sig[h]
    cross = jnp.clip(-jnp.asarray(coupling, float) * sig[h] ** 2, -bound, bound)
    return jnp.diag(sig**2).at[:2, :2].set(cov_image).at[0, h].set(cross).at[h, 0].set(cross)


@functools.partial(jax.jit, static_argnames="rules")
def aim_from_image(rig: Rig, r_f, theta_f, cov_image: Float[Array, "2 2"],
                   rules: tuple[str, ...] | None = None, zero_sigma=None, coupling=0.0) -> Aim:
    """The core: pan/tilt/zoom at the head of the person whose foot is seen at (``r_f`` px,
    ``theta_f`` rad) with covariance ``cov_image`` (2 x 2, px and rad).

    The pointing covariance is ``J Sigma J^T`` (autodiff) over :func:`input_covariance` (``coupling``:
    the foot's coupling to the person's height, px per metre, :func:`height_coupling`).
    ``zero_sigma``: sigmas (rad) of the PTZ's pan and tilt zero offsets, added to it (the nine
    inputs do not include them; calibration reports them). ``rules``: zoom rules computed beside
    the rig's (e.g. :data:`~omnijax.zoom.ZOOM_RULES`).
    """
    x = rig.input_mean(r_f, theta_f)
    cov = pointing_covariance_full(x, input_covariance(rig, cov_image, coupling), rig.omni.profile)
    if zero_sigma is not None:
        p = pointing(x, rig.omni.profile)
        cov = PointingCovariance(cov=with_mounting_sigma(cov.cov, p.pan, p.tilt, *zero_sigma), valid=cov.valid)
    return aim_with_covariance(rig, x, cov, rules)


@functools.partial(jax.jit, static_argnames="rules")
def aim_detection(rig: Rig, r_f, theta_f, sigma_r_f=None, sigma_theta_f=None,
                  rules: tuple[str, ...] | None = None, zero_sigma=None, bound_r_f=0.0, bound_theta_f=0.0,
                  height_r_f=0.0, from_head=False) -> Aim:
    """Pan/tilt/zoom for a detection at (``r_f`` px, ``theta_f`` rad) with the detector's sigmas
    (and bound parts), under the sigma rule (:func:`detection_sigmas`; ``None``: the rig's defaults),
    the foot coupled to the person's height by ``height_r_f`` and ``from_head`` (:func:`height_coupling`)."""
    s_r, s_t = detection_sigmas(rig, sigma_r_f, sigma_theta_f, bound_r_f, bound_theta_f,
                                None if sigma_r_f is None else r_f)
    return aim_from_image(rig, r_f, theta_f, jnp.diag(jnp.stack([s_r**2, s_t**2])), rules, zero_sigma,
                          height_coupling(rig, height_r_f, from_head))


@functools.partial(jax.jit, static_argnames="rules")
def aim_at_floor(rig: Rig, xy: Float[Array, "2"], cov_xy: Float[Array, "2 2"] | None = None,
                 rules: tuple[str, ...] | None = None, zero_sigma=None, coupling=0.0) -> Aim:
    """Pan/tilt/zoom at the head above floor point ``xy`` (m) whose covariance is ``cov_xy`` (2 x 2, m^2).

    The floor estimate (e.g. the tracker's prediction) goes back to the image as (r_f, theta_f)
    with a full covariance and enters :func:`aim_from_image`, with ``coupling`` (px per metre: how the
    estimate's foot radius follows the person's height, :func:`height_coupling` of the detection the
    estimate took). Without ``cov_xy``: a detection at ``xy`` with the rig's default sigmas (the layout
    optimiser's and calibration's floor points).
    """
    if cov_xy is None:
        rt = floor_to_image(rig, xy)
        return aim_detection(rig, rt[0], rt[1], None, None, rules, zero_sigma)
    rt, cov_rt = image_position(rig, jnp.asarray(xy, float), jnp.asarray(cov_xy, float))
    return aim_from_image(rig, rt[0], rt[1], cov_rt, rules, zero_sigma, coupling)


@functools.partial(jax.jit, static_argnames="method")
def aim(
    rig: Rig,
    r_f,
    theta_f,
    sigma_r_f=None,
    sigma_theta_f=None,
    method: Literal["autodiff", "analytic", "second_order"] = "autodiff",
) -> Aim:
    """PTZ command for a foot at (``r_f`` px, ``theta_f`` rad) with the sigmas *as given* (``None``:
    the rig's ``[detection]`` defaults), by a chosen propagation method: ``omnijax variance``'s.

    A what-if on the propagation, not a detection: the sigma rule is not applied (a detector's
    detections go through :func:`aim_detection`). Vmap it for many people.
    """
    x = rig.input_mean(r_f, theta_f)
    sigma = rig.input_sigma(sigma_r_f, sigma_theta_f)
    return aim_with_covariance(rig, x, pointing_covariance(x, sigma, rig.omni.profile, method))
