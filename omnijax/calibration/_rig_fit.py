"""The rig from data: H_o, D_c, theta_c, H_f and the PTZ's pan/tilt zero offsets by least squares.

An observation is one floor position: the detector's foot image point
``(r_f, theta_f)`` (px, rad, about the image centre the detector used, with its
sigmas), and one or more *aims*: the PTZ centred on a mark of known height above
that foot, with the device's pan/tilt reading (rad). The model of a reading is
eqs 1-4 (:func:`pointing`, aimed at the mark: ``H_p`` = mark height, ``R_h`` = 0)
through the mounting, ``reading = direction * geometry + zero`` (the device
profile's ``[mounting]``).

The inputs are noisy too (errors in variables), so they are unknowns with priors:
the true foot image points (detector sigmas), the image centre and ``r_m`` (the
rim fit's mean and covariance) and one shared offset of the marks' heights
(tape measure). Each enters as ``value = measured + L e`` with a whitened
``e ~ N(0, I)`` whose prior residual is ``e`` itself, so the augmented, weighted
least squares (optimistix Levenberg-Marquardt) has unit-variance residuals and the
covariance of the estimate is ``(J^T J)^-1`` at the solution. Its residual sum of
squares is chi-square with ``2 A - 6`` degrees of freedom (A aims) when the
sigmas are right: a check, not a fudge factor.

Identifiability: the angles are unchanged when ``H_o``, ``D_c`` and ``h - H_f``
are scaled together, so marks at one height only cannot fix the scale; aims at
two heights at least (e.g. a mark on the floor and one at 1.5 m) do.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from ..camera import OmniCamera
from ..config import Rig
from ..geometry import pointing, world_to_image, wrap_pi

#: The rig's unknowns, in the order of every vector and matrix here.
GLOBAL_NAMES: tuple[str, ...] = ("H_o", "D_c", "theta_c", "H_f", "pan_zero", "tilt_zero")
#: The omni image's unknowns (the rim fit's), estimated jointly as nuisance parameters with priors.
RIM_NAMES: tuple[str, ...] = ("center_x", "center_y", "r_m")
#: Every reported parameter: values, sigmas, covariance and NEES use this order.
PARAM_NAMES: tuple[str, ...] = GLOBAL_NAMES + RIM_NAMES
PARAM_UNITS: dict[str, str] = {
    "H_o": "m", "D_c": "m", "theta_c": "rad", "H_f": "m", "pan_zero": "rad", "tilt_zero": "rad",
    "center_x": "px", "center_y": "px", "r_m": "px",
}


class Observations(eqx.Module):
    """K floor positions and A aims (pan/tilt readings at marks above them).

    Positions: ``r_f``, ``theta_f`` (px, rad about the detector's image centre)
    and their sigmas. Aims: ``position`` (index into the positions), ``height``
    (m, of the mark above the floor), ``pan``, ``tilt`` (device readings, rad) and
    their sigmas (rad). ``sigma_height`` (m) is the error shared by all marks'
    heights; ``direction`` the mounting's (pan, tilt) directions (+-1).
    """

    r_f: Float[Array, " K"]
    theta_f: Float[Array, " K"]
    sigma_r_f: Float[Array, " K"]
    sigma_theta_f: Float[Array, " K"]
    position: Int[Array, " A"]
    height: Float[Array, " A"]
    pan: Float[Array, " A"]
    tilt: Float[Array, " A"]
    sigma_pan: Float[Array, " A"]
    sigma_tilt: Float[Array, " A"]
    sigma_height: Float[Array, ""]
    direction: Float[Array, "2"]


class RimPrior(eqx.Module):
    """What is known of (x_c, y_c, r_m) before the rig fit: mean (px) and the Cholesky factor
    of its covariance (lower triangular, px)."""

    mean: Float[Array, "3"]
    chol: Float[Array, "3 3"]


class CalibrationProblem(eqx.Module):
    """Everything the rig fit needs: the detector's camera (its image centre defines
    ``(r_f, theta_f)``; its profile and affinity are kept), the observations, the
    rim prior and the starting rig ``(H_o, D_c, theta_c, H_f, pan_zero, tilt_zero)``."""

    omni: OmniCamera
    obs: Observations
    rim: RimPrior
    start: Float[Array, "6"]


class RigFit(eqx.Module):
    """The fitted rig: ``values`` and ``cov`` in :data:`PARAM_NAMES` order (m, rad, px).

    ``chi2`` (the whitened residual sum of squares) has ``dof = 2 A - 6`` degrees
    of freedom; ``singular`` holds the whitened Jacobian's singular values, largest
    first, and ``weakest`` the parameter combination of the smallest one (what the
    data determine worst). ``pan_residual`` and ``tilt_residual`` (rad, reading
    minus model) and ``valid`` (the geometry is regular at every aim) are per aim.
    """

    values: Float[Array, "9"]
    cov: Float[Array, "9 9"]
    chi2: Float[Array, ""]
    dof: int = eqx.field(static=True)
    singular: Float[Array, " P"]
    weakest: Float[Array, "9"]
    pan_residual: Float[Array, " A"]
    tilt_residual: Float[Array, " A"]
    valid: Bool[Array, " A"]
    converged: Bool[Array, ""]
    steps: Array

    @property
    def sigma(self) -> Float[Array, "9"]:
        return jnp.sqrt(jnp.diagonal(self.cov, axis1=-2, axis2=-1))


class _Unknowns(eqx.Module):
    g: Float[Array, "6"]
    e_rim: Float[Array, "3"]
    e_h: Float[Array, ""]
    e_r: Float[Array, " K"]
    e_t: Float[Array, " K"]


def _params(z: _Unknowns, problem: CalibrationProblem) -> Float[Array, "9"]:
    """The reported parameters (rig and rim) of the unknowns."""
    return jnp.concatenate([z.g, problem.rim.mean + problem.rim.chol @ z.e_rim])


def _model(z: _Unknowns, problem: CalibrationProblem):
    """Modelled pan/tilt readings (rad) of every aim, and whether its geometry is regular."""
    obs, omni = problem.obs, problem.omni
    H_o, D_c, theta_c, H_f, pan_zero, tilt_zero = z.g
    x_c, y_c, r_m = problem.rim.mean + problem.rim.chol @ z.e_rim
    # true foot points in the detector's polar frame -> pixels -> polar about the true centre
    px, py = omni.to_pixel(obs.r_f + obs.sigma_r_f * z.e_r, obs.theta_f + obs.sigma_theta_f * z.e_t)
    r, theta = eqx.tree_at(lambda c: c.center, omni, jnp.stack([x_c, y_c])).to_polar(px, py)
    h = obs.height + obs.sigma_height * z.e_h
    k = obs.position
    rig = jnp.broadcast_to(jnp.stack([H_o, H_f, D_c, theta_c, r_m]), (k.shape[0], 5))
    x = jnp.concatenate([r[k, None], theta[k, None], rig, h[:, None], jnp.zeros_like(h)[:, None]], axis=1)
    p = pointing(x, omni.profile)
    return obs.direction[0] * p.pan + pan_zero, obs.direction[1] * p.tilt + tilt_zero, p.valid


def _residuals(z: _Unknowns, problem: CalibrationProblem) -> Float[Array, " M"]:
    """Whitened residuals: readings against the model, then the priors of the nuisance unknowns."""
    obs = problem.obs
    pan, tilt, _ = _model(z, problem)
    return jnp.concatenate([
        wrap_pi(obs.pan - pan) / obs.sigma_pan,
        (obs.tilt - tilt) / obs.sigma_tilt,
        z.e_rim, z.e_h[None], z.e_r, z.e_t,
    ])


def _start(problem: CalibrationProblem) -> _Unknowns:
    """The starting rig, with the zero offsets set to the mean misfit of the readings there."""
    K = problem.obs.r_f.shape[0]
    z = _Unknowns(g=problem.start, e_rim=jnp.zeros(3), e_h=jnp.zeros(()), e_r=jnp.zeros(K), e_t=jnp.zeros(K))
    pan, tilt, _ = _model(z, problem)
    d_pan = wrap_pi(problem.obs.pan - pan)
    pan0 = problem.start[4] + jnp.arctan2(jnp.mean(jnp.sin(d_pan)), jnp.mean(jnp.cos(d_pan)))
    tilt0 = problem.start[5] + jnp.mean(problem.obs.tilt - tilt)
    return eqx.tree_at(lambda u: u.g, z, problem.start.at[4].set(pan0).at[5].set(tilt0))


@eqx.filter_jit
def fit_rig(problem: CalibrationProblem, max_steps: int = 200) -> RigFit:
    """Least-squares rig from the observations (Levenberg-Marquardt), with its covariance.

    The covariance of all unknowns is ``(J^T J)^-1`` of the whitened residuals'
    Jacobian at the solution (from its singular values; a direction the data do
    not determine gets a huge sigma, never a silently dropped one); the
    reported parameters are a linear map of the unknowns, so their covariance
    follows exactly. Vmap it over problems of one shape.
    """
    z0 = _start(problem)
    solver = optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12)
    sol = optx.least_squares(_residuals, solver, z0, args=problem, max_steps=max_steps, throw=False)
    z = sol.value
    flat, unravel = ravel_pytree(z)
    J = jax.jacfwd(lambda f: _residuals(unravel(f), problem))(flat)
    T = jax.jacfwd(lambda f: _params(unravel(f), problem))(flat)
    _, s, vt = jnp.linalg.svd(J, full_matrices=False)
    TV = T @ vt.T
    cov = (TV / jnp.maximum(s, s[0] * 1e-15) ** 2) @ TV.T  # a null direction shows as a huge sigma
    weakest = T @ vt[-1]
    res = _residuals(z, problem)
    A = problem.obs.pan.shape[0]
    pan, tilt, valid = _model(z, problem)
    return RigFit(
        values=_params(z, problem), cov=cov, chi2=jnp.sum(res**2), dof=2 * A - 6, singular=s, weakest=weakest,
        pan_residual=wrap_pi(problem.obs.pan - pan), tilt_residual=problem.obs.tilt - tilt, valid=valid,
        converged=sol.result == optx.RESULTS.successful, steps=sol.stats["num_steps"],
    )


def with_mounting_sigma(cov: Float[Array, "*b 4 4"], pan, tilt, sigma_pan_zero, sigma_tilt_zero):
    """Pointing covariance of ``(pan, tilt, sin pan, tan tilt)`` plus the PTZ's zero-offset errors.

    A zero offset error adds to the pan (tilt) the device turns to, so to first
    order ``cov + G diag(sigma^2) G^T`` with ``G = d(pan, tilt, sin pan, tan tilt) /
    d(pan, tilt)``.
    """
    one, zero = jnp.ones_like(pan), jnp.zeros_like(pan)
    g_pan = jnp.stack([one, zero, jnp.cos(pan), zero], axis=-1)
    g_tilt = jnp.stack([zero, one, zero, 1.0 / jnp.cos(tilt) ** 2], axis=-1)
    outer = lambda g, s: s[..., None, None] ** 2 * g[..., :, None] * g[..., None, :]
    return cov + outer(g_pan, jnp.asarray(sigma_pan_zero)) + outer(g_tilt, jnp.asarray(sigma_tilt_zero))


# --------------------------------------------------------------------------------------
# Simulated calibrations (docs/design.md section 5: a true rig drawn per run)
# --------------------------------------------------------------------------------------


class SimulationSettings(eqx.Module):
    """How simulated calibrations are drawn (SI units; angles in rad).

    ``heights``: the marks aimed at above each floor position; ``sigma_ptz``: the
    reading (aiming) noise per axis; ``sigma_height``: the marks' shared height
    error; ``sigma_zero``: the spread of the true pan/tilt zero offsets around
    ``zero`` (the profile's); ``sigma_center``: the spread of the true image centre
    about the configured one and the rim fit's error per coordinate (px);
    ``direction``: the mounting's; ``min_ptz_distance``: positions closer to the
    PTZ's foot are not used (m).
    """

    heights: Float[Array, " H"]
    sigma_ptz: Float[Array, ""]
    sigma_height: Float[Array, ""]
    sigma_zero: Float[Array, ""]
    zero: Float[Array, "2"]
    sigma_center: Float[Array, ""]
    direction: Float[Array, "2"]
    min_ptz_distance: Float[Array, ""]


def draw_calibration_truth(key: PRNGKeyArray, rig: Rig, settings: SimulationSettings) -> Float[Array, "9"]:
    """One true rig around the configured one (its calibration sigmas), in :data:`PARAM_NAMES` order."""
    s = rig.sigmas
    mean = jnp.concatenate([
        jnp.stack([rig.omni.H_o, rig.foveal.D_c, rig.foveal.theta_c, rig.foveal.H_f]), settings.zero,
        rig.omni.center, rig.omni.r_m[None],
    ])
    sd = jnp.stack([s.H_o, s.D_c, s.theta_c, s.H_f, settings.sigma_zero, settings.sigma_zero,
                    settings.sigma_center, settings.sigma_center, s.r_m])
    return mean + sd * jax.random.normal(key, (9,))


def _floor_positions(key, rig: Rig, truth, n: int, min_ptz_distance, candidates: int = 4096):
    """``n`` floor points uniform in the room, seen inside the rim and away from the PTZ's foot."""
    lo, hi = jnp.min(rig.room.outline, axis=0), jnp.max(rig.room.outline, axis=0)
    xy = lo + (hi - lo) * jax.random.uniform(key, (candidates, 2))
    r_image = rig.omni.radius(jnp.arctan2(jnp.hypot(xy[:, 0], xy[:, 1]), truth[0]), truth[8])
    ptz = truth[1] * jnp.stack([jnp.cos(truth[2]), jnp.sin(truth[2])])
    ok = (rig.room.contains(xy[:, 0], xy[:, 1]) & (r_image < 0.95 * rig.omni.rim * truth[8] / rig.omni.r_m)
          & (jnp.hypot(*(xy - ptz).T) > min_ptz_distance))
    order = jnp.argsort(~ok, stable=True)
    return xy[order[:n]], jnp.all(ok[order[:n]])


def simulate_calibration(
    key: PRNGKeyArray, rig: Rig, settings: SimulationSettings, n_positions: int
) -> tuple[CalibrationProblem, Float[Array, "9"], Bool[Array, ""]]:
    """One simulated calibration: a true rig, ``n_positions`` floor positions with every mark
    of ``settings.heights`` above each, noisy detections, readings and rim fit.

    Returns the problem (as :func:`fit_rig` takes it, starting from the configured
    rig), the truth (:data:`PARAM_NAMES` order) and whether enough valid floor
    positions were found. The detector measures about the configured image centre.
    """
    k_rig, k_pos, k_r, k_t, k_pan, k_tilt, k_h, k_rim = jax.random.split(key, 8)
    truth = draw_calibration_truth(k_rig, rig, settings)
    H_o, D_c, theta_c, H_f, pan0, tilt0, x_c, y_c, r_m = truth
    xy, enough = _floor_positions(k_pos, rig, truth, n_positions, settings.min_ptz_distance)
    true_omni = eqx.tree_at(lambda c: (c.center, c.r_m, c.H_o), rig.omni, (jnp.stack([x_c, y_c]), r_m, H_o))
    px, py = world_to_image(true_omni, xy[:, 0], xy[:, 1], jnp.zeros(n_positions))
    r_det, t_det = rig.omni.to_polar(px, py)
    sig_r = jnp.full(n_positions, rig.detection.sigma_r_f)
    sig_t = jnp.full(n_positions, rig.detection.sigma_theta_f)
    r_true, t_true = true_omni.to_polar(px, py)
    n_h = settings.heights.shape[0]
    position = jnp.repeat(jnp.arange(n_positions), n_h)
    height = jnp.tile(settings.heights, n_positions)
    true_height = height + settings.sigma_height * jax.random.normal(k_h, ())
    rig_in = jnp.broadcast_to(jnp.stack([H_o, H_f, D_c, theta_c, r_m]), (position.shape[0], 5))
    x = jnp.concatenate([r_true[position, None], t_true[position, None], rig_in, true_height[:, None],
                         jnp.zeros_like(height)[:, None]], axis=1)
    p = pointing(x, rig.omni.profile)
    A = position.shape[0]
    obs = Observations(
        r_f=r_det + sig_r * jax.random.normal(k_r, (n_positions,)),
        theta_f=t_det + sig_t * jax.random.normal(k_t, (n_positions,)),
        sigma_r_f=sig_r, sigma_theta_f=sig_t, position=position, height=height,
        pan=wrap_pi(settings.direction[0] * p.pan + pan0 + settings.sigma_ptz * jax.random.normal(k_pan, (A,))),
        tilt=settings.direction[1] * p.tilt + tilt0 + settings.sigma_ptz * jax.random.normal(k_tilt, (A,)),
        sigma_pan=jnp.full(A, settings.sigma_ptz), sigma_tilt=jnp.full(A, settings.sigma_ptz),
        sigma_height=settings.sigma_height, direction=settings.direction,
    )
    rim_sd = jnp.stack([settings.sigma_center, settings.sigma_center, rig.sigmas.r_m])
    rim = RimPrior(mean=truth[6:] + rim_sd * jax.random.normal(k_rim, (3,)), chol=jnp.diag(rim_sd))
    start = jnp.concatenate([jnp.stack([rig.omni.H_o, rig.foveal.D_c, rig.foveal.theta_c, rig.foveal.H_f]),
                             settings.zero])
    problem = CalibrationProblem(omni=rig.omni, obs=obs, rim=rim, start=start)
    return problem, truth, enough & jnp.all(p.valid)
