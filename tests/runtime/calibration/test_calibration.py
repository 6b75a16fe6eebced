"""Calibration: the rig fit's model against plain world geometry, exact recovery, honest sigmas (NEES),
the rim fit on synthetic and real frames, refused set-ups, and `omnijax calibrate`'s contract."""

from __future__ import annotations

import json
import math

import cv2
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from omnijax import GLOBAL_NAMES, PARAM_NAMES, SimulationSettings, fit_rig, fit_rim, simulate_calibration
from runtime.calibration.runs import check_fit, simulate_many
from runtime.cli import main
from runtime.files import load_rig
from tests.paths import CONFIGS, shared_data
from tests.runtime.calibration.helpers import disc_frame, observations_json

PAPER = CONFIGS / "paper.toml"
EXAMPLE = CONFIGS / "observations_example.json"


def _settings(rig, heights=(0.0, 1.5), sigma_ptz_deg=0.1, sigma_height=0.005, sigma_center=None, zero_deg=2.0):
    return SimulationSettings(
        heights=jnp.asarray(heights, float), sigma_ptz=jnp.asarray(math.radians(sigma_ptz_deg)),
        sigma_height=jnp.asarray(sigma_height), sigma_zero=jnp.asarray(math.radians(zero_deg)), zero=jnp.zeros(2),
        sigma_center=rig.sigmas.r_m if sigma_center is None else jnp.asarray(sigma_center),
        direction=jnp.ones(2), min_ptz_distance=jnp.asarray(0.5),
    )


def _noiseless(rig):
    """The rig with (nearly) noiseless detections and rim, and settings with (nearly) noiseless readings."""
    rig = eqx.tree_at(lambda r: (r.detection.sigma_r_f, r.detection.sigma_theta_f, r.sigmas.r_m), rig,
                      (jnp.asarray(1e-7), jnp.asarray(1e-9), jnp.asarray(0.0)))
    return rig, _settings(rig, sigma_ptz_deg=1e-7, sigma_height=0.0, sigma_center=0.0)


# --------------------------------------------------------------------------------------
# The model and the fit
# --------------------------------------------------------------------------------------


@pytest.mark.slow
def test_readings_match_plain_world_geometry(paper_rig):
    """Simulated pan/tilt readings against pan/tilt computed from world points with vectors.

    The PTZ sits at D_c (cos theta_c, sin theta_c, H_f); pan is measured from its direction
    towards the omni axis, positive towards the omni image's increasing azimuth; tilt up.
    The foot pixel is the paraboloid's r = r_m tan(phi / 2) about the true centre.
    """
    rig, settings = _noiseless(paper_rig)
    problem, truth, drawn = simulate_calibration(jax.random.key(5), rig, settings, 6)
    assert bool(drawn)
    H_o, D_c, theta_c, H_f, pan0, tilt0, x_c, y_c, r_m = np.asarray(truth)
    o = problem.obs
    # foot: detector (r, theta) about the configured centre -> pixel -> world floor point, by hand
    c = np.asarray(rig.omni.center)
    px = c[0] + np.asarray(o.r_f) * np.cos(np.asarray(o.theta_f))
    py = c[1] + np.asarray(o.r_f) * np.sin(np.asarray(o.theta_f))
    r, th = np.hypot(px - x_c, py - y_c), np.arctan2(py - y_c, px - x_c)
    rho = H_o * np.tan(2 * np.arctan(r / r_m))
    foot = np.stack([rho * np.cos(th), rho * np.sin(th)], axis=1)[np.asarray(o.position)]
    ptz = D_c * np.array([np.cos(theta_c), np.sin(theta_c)])
    d = foot - ptz
    toward_axis = -ptz / D_c
    across = np.array([-np.sin(theta_c), np.cos(theta_c)])
    pan = np.arctan2(d @ across, d @ toward_axis)
    tilt = np.arctan2(np.asarray(o.height) - H_f, np.hypot(d[:, 0], d[:, 1]))
    np.testing.assert_allclose(np.asarray(o.pan), pan + pan0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(o.tilt), tilt + tilt0, atol=1e-6)


@pytest.mark.slow
def test_levenberg_marquardt_recovers_a_noiseless_rig(paper_rig):
    rig, settings = _noiseless(paper_rig)
    problem, truth, _ = simulate_calibration(jax.random.key(11), rig, settings, 6)
    fit = fit_rig(problem)
    assert bool(fit.converged)
    np.testing.assert_allclose(np.asarray(fit.values), np.asarray(truth), rtol=0, atol=1e-6)
    assert fit.dof == 2 * 12 - 6  # 6 positions, marks at two heights: 12 aims


@pytest.mark.slow
def test_nees_is_honest_at_fixed_seed(paper_rig):
    """n = 200 simulated calibrations (K = 6 positions, marks at 0 and 1.5 m), seed 0.

    The mean NEES of a parameter is a mean of 200 chi-square(1) values if the sigmas are
    honest: sd 0.1, skewed right; the bounds [0.6, 1.45] are 4 sd below and 4.5 sd above,
    so a correct fit fails one of the six with probability < 1e-3 over seeds. The joint
    NEES / 6 (sd 0.041) gets [0.85, 1.15] (3.7 sd; < 3e-4).
    """
    res = simulate_many(paper_rig, _settings(paper_rig), 6, 200, seed=0, max_sigma_m=0.1, max_sigma_deg=2.0)
    assert res["counted"] >= 195
    for name in GLOBAL_NAMES:
        assert 0.6 < res["nees_mean"][name] < 1.45, (name, res["nees_mean"])
    assert 0.85 < res["nees_joint_mean"] < 1.15
    assert 0.9 < res["chi2_per_dof_mean"] < 1.1


@pytest.mark.slow
def test_nees_over_many_runs(paper_rig):
    """n = 1000 per K = 4, 16: the mean NEES of every parameter within [0.85, 1.15] (sd 0.045:
    3.3 sd; a correct fit fails with probability ~1e-2 over 18 values, fixed seed)."""
    for K in (4, 16):
        res = simulate_many(paper_rig, _settings(paper_rig), K, 1000, seed=1, max_sigma_m=0.1, max_sigma_deg=2.0)
        for name in PARAM_NAMES:
            assert 0.85 < res["nees_mean"][name] < 1.15, (K, name, res["nees_mean"])


@pytest.mark.slow
def test_marks_at_one_height_leave_the_scale_undetermined(paper_rig):
    """H_o, D_c and h - H_f scale together: the Jacobian is singular and check_fit says so."""
    problem, _, _ = simulate_calibration(jax.random.key(3), paper_rig, _settings(paper_rig, heights=(1.5,)), 8)
    why = check_fit(fit_rig(problem))
    assert why is not None and "do not determine" in why and "H_o" in why and "D_c" in why


@pytest.mark.slow
def test_positions_on_one_radial_line_are_refused(paper_rig):
    problem, _, _ = simulate_calibration(jax.random.key(3), paper_rig, _settings(paper_rig), 6)
    line = eqx.tree_at(lambda p: p.obs.theta_f, problem, jnp.full(6, 0.7))
    why = check_fit(fit_rig(line))
    assert why is not None and ("determined only to sigma" in why or "do not determine" in why), why


# --------------------------------------------------------------------------------------
# The rim
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("guess", [(320.0, 240.0, 220.0), (305.0, 252.0, 200.0)], ids=["near", "off"])
def test_rim_fit_on_a_synthetic_disc(guess):
    """A blurred, textured, noisy disc with an occluder over part of its rim."""
    img = disc_frame()
    fit, edges = fit_rim(img, guess[:2], guess[2])
    assert bool(fit.converged)
    np.testing.assert_allclose(np.asarray(fit.center), [321.3, 238.7], atol=0.05)
    assert float(fit.radius) == pytest.approx(220.4, abs=0.05)
    sd = np.sqrt(np.diag(np.asarray(fit.cov)))
    assert (sd > 0).all() and (sd < 0.05).all()
    assert int(fit.inliers) > 0.8 * int(np.asarray(edges.ok).sum())


def test_rim_fit_on_a_disc_leaving_the_frame():
    img = disc_frame(size=(640, 400), center=(330.2, 200.6), radius=230.0, occluder=False)
    fit, _ = fit_rim(img, (320.0, 200.0), 225.0)
    np.testing.assert_allclose(np.asarray(fit.center), [330.2, 200.6], atol=0.1)
    assert float(fit.radius) == pytest.approx(230.0, abs=0.1)


@pytest.mark.realdata
def test_rim_fit_on_the_real_catadioptric_image():
    """The mirror's bright disc: its centre lies near the OCamCalib centre, its rim near the file's
    ROI max (600 px); both are measured (see docs/calibration.md: 8.8 px and -6.5 px)."""
    img = cv2.imread(str(shared_data("catadioptric_office", "example.jpg")), cv2.IMREAD_GRAYSCALE)
    file_center = np.array([674.318875 + 300, 545.872616])
    fit, _ = fit_rim(img.astype(np.float32), tuple(file_center), 600.0)
    assert bool(fit.converged)
    assert np.hypot(*(np.asarray(fit.center) - file_center)) < 15
    assert abs(float(fit.radius) - 600.0) < 20
    assert float(fit.scale) < 8


# --------------------------------------------------------------------------------------
# The command
# --------------------------------------------------------------------------------------


def _run(capsys, *args):
    code = main(["calibrate", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_calibrate_contract_and_round_trip(tmp_path, capsys):
    frame = tmp_path / "frame.png"
    cv2.imwrite(str(frame), disc_frame(center=(320.0, 240.0), radius=220.0))
    out = tmp_path / "out"
    code, _, err = _run(capsys, "--config", PAPER, "--frame", frame, "--observations", EXAMPLE, "--out", out,
                        "--ptz-profile", "sony_evi_d70")
    assert code == 0, err
    rep = json.loads((out / "calibration.json").read_text())
    assert set(rep["params"]) == set(PARAM_NAMES)
    for v in rep["params"].values():
        assert set(v) >= {"value", "sigma"} and v["sigma"] > 0
    assert 0 < rep["rms_residual"] < math.radians(0.3)
    assert rep["rim"]["radius_px"] == pytest.approx(220.0, abs=0.1)
    assert {"pan_zero_deg", "tilt_zero_deg", "sigma_pan_zero_deg", "sigma_tilt_zero_deg"} <= set(rep["mounting"])
    for name in ("calibrated.toml", "residuals.png", "rim.png", "sony_evi_d70.toml"):
        assert (out / name).is_file()
    # calibrated.toml loads, holds the fitted values and sigmas, and keeps the user's comments
    rig = load_rig(out / "calibrated.toml")
    p = rep["params"]
    assert float(rig.omni.H_o) == pytest.approx(p["H_o"]["value"], abs=1e-5)
    assert float(rig.sigmas.H_o) == pytest.approx(p["H_o"]["sigma"], rel=1e-2)
    assert float(rig.foveal.D_c) == pytest.approx(p["D_c"]["value"], abs=1e-5)
    assert float(rig.sigmas.D_c) == pytest.approx(p["D_c"]["sigma"], rel=1e-2)
    assert float(rig.foveal.theta_c) == pytest.approx(p["theta_c"]["value"], abs=1e-5)
    assert float(rig.foveal.H_f) == pytest.approx(p["H_f"]["value"], abs=1e-5)
    assert float(rig.omni.r_m) == pytest.approx(p["r_m"]["value"], abs=1e-3)
    np.testing.assert_allclose(np.asarray(rig.omni.center), [p["center_x"]["value"], p["center_y"]["value"]],
                               atol=1e-3)
    text = (out / "calibrated.toml").read_text()
    assert "# floor distance from the omni axis to the PTZ (m)" in text
    from runtime.ptz.profile import load_profile

    prof = load_profile(out / "sony_evi_d70.toml")
    assert prof.mounting.pan_zero_deg == pytest.approx(rep["mounting"]["pan_zero_deg"], abs=1e-4)
    # the example's true rig (configs/observations_example.json: simulated, seed 2024)
    truth = {"H_o": 2.70201, "D_c": 3.04857, "H_f": 1.98975, "tilt_zero": math.radians(-1.3383)}
    for name, value in truth.items():
        assert abs(p[name]["value"] - value) < 3.5 * p[name]["sigma"], name


@pytest.mark.slow
def test_calibrate_simulate_contract(tmp_path, capsys):
    out = tmp_path / "sim"
    code, stdout, err = _run(capsys, "--simulate", "8", "--positions", "6", "--config", PAPER, "--out", out)
    assert code == 0, err
    rep = json.loads((out / "calibration.json").read_text())
    assert set(rep["nees_mean"]) == set(PARAM_NAMES)
    assert [b["positions"] for b in rep["by_positions"]] == [6]
    assert set(rep["sigma"]["D_c"]) == {"6"}
    assert (out / "sigmas.png").is_file()
    assert "mean NEES" in stdout


def _bad_observations(tmp_path, edit):
    data = json.loads(EXAMPLE.read_text())
    edit(data)
    path = tmp_path / "obs.json"
    path.write_text(json.dumps(data))
    return path


def _one_height(d):
    for p in d["positions"]:
        p["aims"] = p["aims"][1:]


def _one_line(d):
    for p in d["positions"]:
        p["theta_f"] = 0.7


@pytest.mark.parametrize("edit,expect", [
    (lambda d: d.update(positions=d["positions"][:2]), "at least 3 are needed"),
    (_one_height, "the scale is not determined"),
    (_one_line, "on one line"),
    (lambda d: d["positions"][0]["aims"][0].pop("pan_deg"), "positions.0.aims.0.pan_deg: missing key"),
    (lambda d: d.update(extra=1), "extra: unknown key"),
    (lambda d: d["positions"][0].update(r_f=500.0), "outside the image circle"),
], ids=["two-positions", "one-height", "one-line", "missing-key", "unknown-key", "beyond-rim"])
def test_bad_setups_exit_2_with_one_line(tmp_path, capsys, edit, expect):
    obs = _bad_observations(tmp_path, edit)
    code, out, err = _run(capsys, "--config", PAPER, "--observations", obs, "--out", tmp_path / "out")
    assert code == 2
    assert err.strip().count("\n") == 0 and expect in err, err
    assert not (tmp_path / "out").exists()


def test_bad_frame_and_arguments_exit_2(tmp_path, capsys):
    frame = tmp_path / "small.png"
    cv2.imwrite(str(frame), np.zeros((100, 100), np.uint8))
    for args, expect in (
        (["--frame", frame, "--observations", EXAMPLE], "the rig's omni.image_size is 640x480"),
        (["--frame", tmp_path / "none.png", "--observations", EXAMPLE], "cannot read"),
        (["--observations", tmp_path / "none.json"], "no such observations file"),
        (["--simulate", "5", "--positions", "2"], "--positions"),
        (["--simulate", "5", "--heights", "1.5"], "--heights"),
        ([], "expected --observations"),
    ):
        code, _, err = _run(capsys, "--config", PAPER, "--out", tmp_path / "o", *args)
        assert code == 2 and expect in err and err.strip().count("\n") == 0, (args, err)


@pytest.mark.slow
@pytest.mark.realdata
def test_calibrate_with_the_real_frame_and_its_ocamcalib_file(tmp_path, capsys):
    """An OCamCalib rig on the real image: the rim is fitted and reported against the file,
    whose centre and r_m are kept; observations simulated for that rig."""
    calib = shared_data("catadioptric_office", "calib_results.txt")
    frame = shared_data("catadioptric_office", "example.jpg")
    text = PAPER.read_text()
    start, end = text.index("[omni]"), text.index("[foveal]")
    omni = (f'[omni]\nmodel = "ocamcalib"\ncalib_file = "{calib}"\nH_o = 2.70\nsigma_H_o = 0.01\n'
            "sigma_r_m = 0.5\n\n")
    config = tmp_path / "ocam.toml"
    config.write_text(text[:start] + omni + text[end:])
    rig = load_rig(config)
    problem, _, _ = simulate_calibration(jax.random.key(7), rig, _settings(rig), 6)
    obs = tmp_path / "obs.json"
    obs.write_text(json.dumps(observations_json(problem)))
    out = tmp_path / "out"
    code, stdout, err = _run(capsys, "--config", config, "--frame", frame, "--observations", obs, "--out", out)
    assert code == 0, err
    rep = json.loads((out / "calibration.json").read_text())
    oc = rep["rim"]["ocamcalib"]
    assert oc["center_offset_px"] < 15 and abs(oc["radius_minus_file_rim_px"]) < 20
    assert "centre" in stdout and (out / "rim.png").is_file()
    assert load_rig(out / "calibrated.toml").omni.model == "ocamcalib"


def test_a_reading_at_the_ptzs_limit_is_refused(tmp_path, capsys):
    """A mark below the PTZ's lowest tilt: the device stops at -30 deg and reports that; taken as an aim at
    the mark it would bias the rig (docs/console.md, the assistant's benchmark), so the fit refuses it."""
    obs = _bad_observations(tmp_path, lambda d: d["positions"][2]["aims"][0].update(tilt_deg=-30.0))
    code, _, err = _run(capsys, "--config", PAPER, "--observations", obs, "--out", tmp_path / "out",
                        "--ptz-profile", "sony_evi_d70")
    assert code == 2 and err.strip().count("\n") == 0, err
    assert "position 3's aim at 0 m reads tilt -30 deg, the PTZ's tilt limit (-30 deg)" in err, err
    assert not (tmp_path / "out").exists()
    code, _, err = _run(capsys, "--config", PAPER, "--observations", obs, "--out", tmp_path / "out2")
    assert code == 0, err  # without a profile nothing says where the limits are
