"""Calibration runs: observation files, set-up checks, calibrated rig and profile files, simulations.

The kernels (rim fit, rig fit, simulated calibrations) are in ``omnijax``; this
module reads and writes the files around them and decides, with one line of
explanation, when a set-up cannot determine the rig.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import tomlkit
from annotated_types import Len
from pydantic import Field
from scipy.stats import chi2 as chi2_dist

from omnijax import (
    GLOBAL_NAMES,
    PARAM_NAMES,
    PARAM_UNITS,
    CalibrationProblem,
    ConfigError,
    Observations,
    Rig,
    RigFit,
    RimFit,
    RimPrior,
    SimulationSettings,
    aim_at_floor,
    face_pixels,
    fit_rig,
    simulate_calibration,
)
from omnijax.config import Section, validate

#: Smallest ratio of the whitened Jacobian's smallest to largest singular value for a determined rig.
MIN_CONDITION = 1e-10
#: Largest acceptable sigma of a fitted length (m) and angle (deg), unless the command says otherwise.
MAX_SIGMA_M = 0.10
MAX_SIGMA_DEG = 2.0
#: chi-square p-value below which the readings disagree with their stated sigmas.
CHI2_P_MIN = 0.01
#: Floor positions (m, world frame, relative to the rig) where the zoom comparison is made.
ZOOM_POINTS_M = ((1.0, 0.5), (2.0, -1.0), (-2.0, 1.5), (-3.5, -2.0), (2.5, 2.5), (0.0, -2.5))


class CalibrationError(ConfigError):
    """Observations that cannot give a trustworthy rig (one line: what and what to do; exit 2)."""


# --------------------------------------------------------------------------------------
# Observation files (OBS.json)
# --------------------------------------------------------------------------------------

Finite = Annotated[float, Field(allow_inf_nan=False)]
PosFinite = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class AimEntry(Section):
    height_m: Annotated[float, Field(ge=0, allow_inf_nan=False)] = Field(
        description="height of the mark the PTZ was centred on, above the floor (m)")
    pan_deg: Finite = Field(description="the PTZ's pan reading, device degrees")
    tilt_deg: Finite = Field(description="the PTZ's tilt reading, device degrees")


class PositionEntry(Section):
    label: str | None = None
    r_f: Annotated[float, Field(ge=0, allow_inf_nan=False)] = Field(description="foot image radius, px")
    theta_f: Finite = Field(description="foot azimuth, rad")
    sigma_r_f: PosFinite | None = None
    sigma_theta_f: PosFinite | None = None
    aims: Annotated[list[AimEntry], Len(1)]


class ObservationsFile(Section):
    comment: str | None = None
    sigma_pan_deg: PosFinite = 0.1
    sigma_tilt_deg: PosFinite = 0.1
    sigma_height_m: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 0.005
    positions: Annotated[list[PositionEntry], Len(1)]


def parse_observations(data, rig: Rig, direction: tuple[int, int], source: str = "observations") -> Observations:
    """Validate an OBS.json mapping (see docs/calibration.md) and build :class:`Observations`.

    Positions without sigmas take the rig's ``[detection]`` ones; readings become radians.
    """
    f = validate(ObservationsFile, data, source)
    pos = f.positions
    aims = [(k, a) for k, p in enumerate(pos) for a in p.aims]
    A = len(aims)
    return Observations(
        r_f=jnp.array([p.r_f for p in pos]), theta_f=jnp.array([p.theta_f for p in pos]),
        sigma_r_f=jnp.array([p.sigma_r_f or float(rig.detection.sigma_r_f) for p in pos]),
        sigma_theta_f=jnp.array([p.sigma_theta_f or float(rig.detection.sigma_theta_f) for p in pos]),
        position=jnp.array([k for k, _ in aims], dtype=jnp.int32),
        height=jnp.array([a.height_m for _, a in aims]),
        pan=jnp.radians(jnp.array([a.pan_deg for _, a in aims])),
        tilt=jnp.radians(jnp.array([a.tilt_deg for _, a in aims])),
        sigma_pan=jnp.full(A, math.radians(f.sigma_pan_deg)), sigma_tilt=jnp.full(A, math.radians(f.sigma_tilt_deg)),
        sigma_height=jnp.asarray(f.sigma_height_m), direction=jnp.array(direction, float),
    )


def check_setup(obs: Observations, rig: Rig, source: str) -> None:
    """Set-ups that cannot determine the rig, refused before any fit (one-line CalibrationError)."""
    K, A = obs.r_f.shape[0], obs.pan.shape[0]
    if K < 3:
        raise CalibrationError(f"{source}: {K} floor position(s); at least 3 are needed (6 or more recommended), "
                               "spread over the room")
    heights = np.unique(np.round(np.asarray(obs.height), 3))
    if heights.size < 2:
        raise CalibrationError(
            f"{source}: every mark is at height {heights[0]:g} m; with marks at one height the scale is not "
            "determined (H_o, D_c and the mark-to-PTZ height scale together): aim at marks at two heights "
            "at least, e.g. one on the floor and one at 1.5 m above it")
    if 2 * A < 8:
        raise CalibrationError(f"{source}: {A} aims give {2 * A} readings for 6 rig unknowns; at least 4 aims are "
                               "needed")
    far = np.asarray(obs.r_f) >= float(rig.omni.rim)
    if far.any():
        k = int(np.argmax(far))
        raise CalibrationError(f"{source}: positions[{k}].r_f = {float(obs.r_f[k]):g} px lies outside the image "
                               f"circle (rim {float(rig.omni.rim):g} px)")


def check_limits(obs: Observations, profile, source: str) -> None:
    """Refuse a reading at a limit of the PTZ's range (within a device unit): the PTZ stopped there, not on
    the mark, and the fit would take it for an aim at the mark (one-line CalibrationError). ``profile``:
    the device profile of the readings (``None``: nothing to check)."""
    if profile is None:
        return
    for axis, readings in (("pan", obs.pan), ("tilt", obs.tilt)):
        per_deg = getattr(profile, axis).units_per_deg
        for j, v in enumerate(np.degrees(np.asarray(readings))):
            limit = profile.at_limit(axis, v * per_deg)
            if limit is not None:
                k, h = int(obs.position[j]), float(obs.height[j])
                raise CalibrationError(
                    f"{source}: position {k + 1}'s aim at {h:g} m reads {axis} {v:g} deg, the PTZ's {axis} limit "
                    f"({limit:g} deg): it stopped there, not on the mark; leave that aim out (a mark it cannot centre)")


def check_fit(fit: RigFit, max_sigma_m: float = MAX_SIGMA_M, max_sigma_deg: float = MAX_SIGMA_DEG) -> str | None:
    """Why a fitted rig is not trustworthy (one line), or None.

    Not converged; the data leave a direction undetermined (relative singular value
    below :data:`MIN_CONDITION`: names the parameters of that direction); a geometry
    that is singular at an aim (at the horizon or at the PTZ's foot); or a sigma
    beyond the bounds (too few, too close or collinear positions).
    """
    if not bool(fit.converged):
        return f"the least squares did not converge in {int(fit.steps)} steps"
    s = np.asarray(fit.singular)
    if s[-1] < MIN_CONDITION * s[0]:
        w = np.asarray(fit.weakest)
        names = [PARAM_NAMES[i] for i in np.argsort(-np.abs(w)) if abs(w[i]) > 0.2 * np.abs(w).max()]
        return (f"the observations do not determine {', '.join(names)} (condition {s[-1] / s[0]:.1e}): "
                "use more positions spread over the room, not on one line, and marks at two heights")
    valid = np.asarray(fit.valid)
    if not valid.all():
        return (f"aim {int(np.argmin(valid))} is at a singular place (foot at the horizon or at the PTZ's foot): "
                "leave that position out")
    sigma = np.asarray(fit.sigma)
    for i, name in enumerate(GLOBAL_NAMES):
        angle = PARAM_UNITS[name] == "rad"
        value, bound = (math.degrees(sigma[i]), max_sigma_deg) if angle else (sigma[i], max_sigma_m)
        if not value <= bound:
            unit = "deg" if angle else "m"
            return (f"{name} is determined only to sigma {value:.3g} {unit} (bound {bound:g} {unit}): too few "
                    "positions, or positions too close together or on one line; add positions spread over the room")
    return None


def chi2_p_value(fit: RigFit) -> float:
    """P(chi-square with the fit's degrees of freedom >= its chi2): small when readings disagree with their sigmas."""
    return float(chi2_dist.sf(float(fit.chi2), fit.dof)) if fit.dof > 0 else 1.0


# --------------------------------------------------------------------------------------
# The omni image: rim prior
# --------------------------------------------------------------------------------------


def config_prior(rig: Rig) -> RimPrior:
    """The configured centre and ``r_m``, with the configured ``sigma_r_m`` per coordinate."""
    c = np.asarray(rig.omni.center)
    return RimPrior(mean=jnp.array([c[0], c[1], float(rig.omni.r_m)]), chol=jnp.eye(3) * float(rig.sigmas.r_m))


def rim_prior(rig: Rig, rim: RimFit) -> tuple[RimPrior, dict]:
    """The prior of (x_c, y_c, r_m) for the rig fit, and the rim report.

    The rim's radius maps to ``r_m`` by the configured ratio ``r_m / rim`` (the
    paraboloid: 1; a fisheye: ``1 / u(fov / 2)``). For OCamCalib the calibration
    file's centre and ``r_m`` (from a checkerboard calibration, more accurate than
    a rim) are kept, with the configured ``sigma_r_m`` per coordinate, and the fit
    is reported against them.
    """
    ratio = float(rig.omni.r_m) / float(rig.omni.rim)
    J = np.diag([1.0, 1.0, ratio])
    cov = J @ np.asarray(rim.cov) @ J.T
    report = {
        "center": np.asarray(rim.center), "radius_px": float(rim.radius),
        "sigma": {"center_x": math.sqrt(rim.cov[0, 0]), "center_y": math.sqrt(rim.cov[1, 1]),
                  "radius": math.sqrt(rim.cov[2, 2])},
        "covariance": np.asarray(rim.cov), "scale_px": float(rim.scale), "inliers": int(rim.inliers),
        "rays": int(rim.weights.shape[0]), "r_m_over_rim": ratio,
    }
    if rig.omni.model == "ocamcalib":
        c = np.asarray(rig.omni.center)
        report["ocamcalib"] = {
            "file_center": c, "file_rim_px": float(rig.omni.rim),
            "center_offset_px": float(np.hypot(*(np.asarray(rim.center) - c))),
            "radius_minus_file_rim_px": float(rim.radius) - float(rig.omni.rim),
        }
        return config_prior(rig), report
    mean = jnp.array([float(rim.center[0]), float(rim.center[1]), ratio * float(rim.radius)])
    return RimPrior(mean=mean, chol=jnp.linalg.cholesky(jnp.asarray(cov) + 1e-18 * jnp.eye(3))), report


def fit_observations(rig: Rig, obs: Observations, prior: RimPrior, zero: tuple[float, float]) -> RigFit:
    """The rig fit, started from the configured rig and the profile's zero offsets (rad)."""
    start = jnp.array([float(rig.omni.H_o), float(rig.foveal.D_c), float(rig.foveal.theta_c),
                       float(rig.foveal.H_f), zero[0], zero[1]])
    return fit_rig(CalibrationProblem(omni=rig.omni, obs=obs, rim=prior, start=start))


# --------------------------------------------------------------------------------------
# Output files
# --------------------------------------------------------------------------------------


def _num(x: float, decimals: int) -> float:
    return round(float(x), decimals)


def _sig(x: float) -> float:
    return float(f"{float(x):.3g}")


def _set(table, key: str, value) -> None:
    """Set ``key`` keeping the comment that followed its old value, in its old column."""
    old = table.get(key) if key in table else None
    table[key] = value
    if old is not None and hasattr(old, "trivia") and old.trivia.comment:
        column = len(f"{key} = {old.as_string()}") + len(old.trivia.comment_ws)
        new = table[key]
        new.trivia.comment = old.trivia.comment
        new.trivia.comment_ws = " " * max(1, column - len(f"{key} = {new.as_string()}"))


def calibrated_toml(config_path: Path, out_dir: Path, rig: Rig, values: np.ndarray, sigmas: np.ndarray,
                    header: str) -> str:
    """The rig file with the fitted values and sigmas in place, comments kept (tomlkit).

    ``values``/``sigmas`` in :data:`PARAM_NAMES` order. The image centre and
    ``r_m`` are written for the ideal models; OCamCalib keeps its file's. A
    relative ``calib_file`` is rewritten relative to ``out_dir``.
    """
    doc = tomlkit.parse(config_path.read_text())
    v = dict(zip(PARAM_NAMES, values))
    s = dict(zip(PARAM_NAMES, sigmas))
    omni, fov = doc["omni"], doc["foveal"]
    _set(omni, "H_o", _num(v["H_o"], 5))
    _set(omni, "sigma_H_o", _sig(s["H_o"]))
    if rig.omni.model == "ocamcalib":
        calib = Path(str(omni["calib_file"]))
        if not calib.is_absolute():
            target = (config_path.parent / calib).resolve()
            _set(omni, "calib_file", os.path.relpath(target, out_dir.resolve()))
    else:
        _set(omni, "center", [_num(v["center_x"], 3), _num(v["center_y"], 3)])
        _set(omni, "r_m", _num(v["r_m"], 3))
        _set(omni, "sigma_r_m", _sig(s["r_m"]))
        if "rim" in omni:
            _set(omni, "rim", _num(float(rig.omni.rim) / float(rig.omni.r_m) * v["r_m"], 3))
    _set(fov, "D_c", _num(v["D_c"], 5))
    _set(fov, "sigma_D_c", _sig(s["D_c"]))
    _set(fov, "theta_c_deg", _num(math.degrees(v["theta_c"]), 4))
    _set(fov, "sigma_theta_c_deg", _sig(math.degrees(s["theta_c"])))
    _set(fov, "H_f", _num(v["H_f"], 5))
    _set(fov, "sigma_H_f", _sig(s["H_f"]))
    layout = doc.get("layout")
    if layout is not None and "H_f" in layout and "H_o" not in layout:
        # The optimiser's H_f range stops at the omni camera: a fitted H_o a few mm below the
        # nominal one must not leave the range reaching above it (the rig would be refused).
        top = math.floor(v["H_o"] * 1e5) / 1e5
        low, high = (float(b) for b in layout["H_f"])
        if high > top:
            _set(layout, "H_f", [low, top])
    lines = "".join(f"# {line}\n" for line in header.splitlines())
    return lines + tomlkit.dumps(doc)


def calibrated_profile(profile_path: Path, pan_zero_deg: float, tilt_zero_deg: float, header: str) -> str:
    """The device profile with the fitted ``[mounting]`` zero offsets, comments kept."""
    doc = tomlkit.parse(profile_path.read_text())
    if "mounting" not in doc:
        doc["mounting"] = tomlkit.table()
    _set(doc["mounting"], "pan_zero_deg", _num(pan_zero_deg, 4))
    _set(doc["mounting"], "tilt_zero_deg", _num(tilt_zero_deg, 4))
    return "".join(f"# {line}\n" for line in header.splitlines()) + tomlkit.dumps(doc)


def params_report(values, sigmas) -> dict:
    """``params`` of calibration.json: {name: {value, sigma, unit}} (SI; px for image quantities)."""
    return {n: {"value": float(v), "sigma": float(s), "unit": PARAM_UNITS[n]}
            for n, v, s in zip(PARAM_NAMES, values, sigmas)}


# --------------------------------------------------------------------------------------
# What the sigmas do to the zoom
# --------------------------------------------------------------------------------------


def with_sigmas(rig: Rig, sigmas: dict[str, float]) -> Rig:
    """The rig with some calibration sigmas replaced (``H_o``, ``H_f``, ``D_c``, ``theta_c``, ``r_m``)."""
    names = tuple(sigmas)
    return eqx.tree_at(lambda r: tuple(getattr(r.sigmas, n) for n in names), rig,
                       tuple(jnp.asarray(sigmas[n], float) for n in names))


@jax.jit
def _zoom_at(rig: Rig, xy, zero_sigma):
    """Zoom, head width (px) and feasibility at floor points ``xy`` (m), through the aim pipeline (a
    detection there with the rig's default sigmas), the zero offsets' sigmas included."""

    def one(p):
        a = aim_at_floor(rig, p, None, zero_sigma=zero_sigma)
        return a.zoom.zoom, face_pixels(rig.foveal.lens, a.zoom.zoom, a.pointing.slant, rig.person.R_h), a.zoom.feasible

    return jax.vmap(one)(xy)


def face_widths(rig: Rig, zero_sigma: tuple[float, float] = (0.0, 0.0)) -> list[dict]:
    """Head width in foveal pixels at the zoom the rig's rule chooses, at :data:`ZOOM_POINTS_M` in the room.

    ``zero_sigma``: sigmas (rad) of the PTZ's pan/tilt zero offsets, added to the
    pointing covariance (the geometry's nine inputs do not include them).
    """
    pts = np.array([p for p in ZOOM_POINTS_M if bool(rig.room.contains(*p))])
    zoom, px, feasible = _zoom_at(rig, jnp.asarray(pts, float), jnp.asarray(zero_sigma, float))
    return [{"floor_m": list(map(float, p)), "zoom": float(z), "face_px": float(f), "feasible": bool(ok)}
            for p, z, f, ok in zip(pts, zoom, px, feasible)]


# --------------------------------------------------------------------------------------
# Simulated calibrations
# --------------------------------------------------------------------------------------


def simulate_many(rig: Rig, settings: SimulationSettings, n_positions: int, n_runs: int, seed: int,
                  max_sigma_m: float, max_sigma_deg: float, batch: int = 50,
                  progress: Callable[[int], None] | None = None) -> dict:
    """``n_runs`` simulated calibrations with ``n_positions`` floor positions each (vmapped in batches).

    A run counts when its set-up was drawn (enough valid floor positions) and
    :func:`check_fit` accepts it, as the command would. Returns, over the counted
    runs: ``nees_mean`` per parameter (mean of (estimate - truth)^2 / sigma^2),
    the median reported ``sigma``, the ``rmse`` against the truth, the mean
    chi2 / dof, and how many runs were counted.
    """
    keys = jax.random.split(jax.random.key(seed), -(-n_runs // batch) * batch)  # whole batches: one shape
    values, truths, covs, counted, chi2 = [], [], [], [], []
    for start in range(0, n_runs, batch):
        n = min(batch, n_runs - start)
        fits, truth, drawn = jax.tree_util.tree_map(
            lambda a, n=n: a[:n], _simulate_batch(keys[start:start + batch], rig, settings, n_positions))
        for i in range(n):
            fit_i = jax.tree_util.tree_map(lambda a, i=i: a[i], fits)
            counted.append(bool(drawn[i]) and check_fit(fit_i, max_sigma_m, max_sigma_deg) is None)
        values.append(np.asarray(fits.values))
        truths.append(np.asarray(truth))
        covs.append(np.asarray(fits.cov))
        chi2.append(np.asarray(fits.chi2) / fits.dof)
        if progress:
            progress(n)
    values, truths, covs = np.concatenate(values), np.concatenate(truths), np.concatenate(covs)
    ok = np.array(counted)
    sig = np.sqrt(np.diagonal(covs, axis1=1, axis2=2))
    err = values - truths
    nees = err**2 / sig**2
    return {
        "positions": n_positions, "aims": n_positions * int(settings.heights.shape[0]), "runs": n_runs,
        "counted": int(ok.sum()),
        "nees_mean": {n: float(nees[ok, i].mean()) for i, n in enumerate(PARAM_NAMES)},
        "nees_joint_mean": float(np.mean([e @ np.linalg.solve(c[:6, :6], e) for e, c in
                                          zip(err[ok, :6], covs[ok])]) / 6) if ok.any() else None,
        "sigma_median": {n: float(np.median(sig[ok, i])) for i, n in enumerate(PARAM_NAMES)},
        "rmse": {n: float(np.sqrt(np.mean(err[ok, i] ** 2))) for i, n in enumerate(PARAM_NAMES)},
        "chi2_per_dof_mean": float(np.concatenate(chi2)[ok].mean()),
    }


@eqx.filter_jit
def _simulate_batch(keys, rig: Rig, settings: SimulationSettings, n_positions: int):
    return jax.vmap(lambda k: _simulate_one(k, rig, settings, n_positions))(keys)


def _simulate_one(key, rig, settings, n_positions):
    problem, truth, drawn = simulate_calibration(key, rig, settings, n_positions)
    return fit_rig(problem), truth, drawn

