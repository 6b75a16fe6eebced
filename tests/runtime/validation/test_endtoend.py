"""Pieces of `omnijax validate`'s end-to-end part: Table 1's positions, its statistics, matching."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import binomtest

from runtime.validation import endtoend as e


@pytest.fixture(scope="module")
def scenario(paper_rig):
    return e.table1_scenario(paper_rig)


def test_positions_are_walkable_and_spread(paper_rig, scenario):
    p = e.table1_positions(paper_rig, scenario)
    assert p.shape == (8, 2)
    fo = paper_rig.foveal
    ptz = np.array([float(fo.D_c * np.cos(fo.theta_c)), float(fo.D_c * np.sin(fo.theta_c))])
    dist = np.hypot(*(p - ptz).T)
    assert np.all(dist >= e.NEAR_PTZ) and np.all(np.hypot(*p.T) >= e.NEAR_AXIS)
    assert np.all(np.asarray(paper_rig.room.contains(p[:, 0], p[:, 1])))
    # pairs share a direction from the PTZ, the second one farther; four different directions
    bearing = np.arctan2(p[:, 1] - ptz[1], p[:, 0] - ptz[0])
    assert np.allclose(bearing[0::2], bearing[1::2], atol=1e-9) and np.all(dist[1::2] > dist[0::2])
    assert len(np.unique(np.round(bearing, 6))) == 4


def test_positions_fail_cleanly_in_a_tiny_room(paper_rig, scenario):
    import equinox as eqx

    tiny = jnp.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    rig = eqx.tree_at(lambda r: (r.room.outline, r.room.exclude), paper_rig, (tiny, ()))
    with pytest.raises(ValueError, match="too small"):
        e.table1_positions(rig, scenario)


def test_sample_variance_and_its_standard_error():
    # Gaussian samples: var(s^2) = 2 sigma^4 / (n - 1); 400 repetitions of n = 200 at sigma = 2:
    # the mean of the s^2 lies within 4 standard errors of 4 (false failure ~6e-5)
    rng = np.random.default_rng(0)
    x = 2.0 * rng.standard_normal((400, 200))
    est = np.array([e.sample_variance(v) for v in x])
    assert abs(est[:, 0].mean() - 4.0) < 4 * math.sqrt(2 * 16 / 199 / 400)
    assert np.median(est[:, 1]) == pytest.approx(math.sqrt(2 * 16 / 199), rel=0.1)
    ms, _ = e.sample_variance(x[0] + 1.0, about_zero=True)
    assert ms == pytest.approx(np.mean((x[0] + 1.0) ** 2))


@pytest.mark.parametrize("k,n", [(0, 50), (3, 200), (50, 50), (7, 1000)])
def test_binomial_is_clopper_pearson(k, n):
    b = e.binomial(k, n)
    ci = binomtest(k, n).proportion_ci(0.95, method="exact")
    assert b["rate"] == k / n and b["lower"] == pytest.approx(ci.low) and b["upper"] == pytest.approx(ci.high)


def test_match_takes_the_sector_that_covers_the_person():
    from omnijax.detection import Detections

    z = jnp.zeros(3)
    dets = Detections(valid=jnp.array([True, True, False]), r_f=jnp.array([10.0, 20.0, 30.0]),
                      theta_f=jnp.array([1.0, 3.1, 0.5]), sigma_r_f=z + 1, sigma_theta_f=z + 0.01,
                      bound_r_f=z, bound_theta_f=z, height_r_f=z, from_head=z > 0, contrast=z + 9,
                      r_in=z, r_out=z, theta_l=jnp.array([0.9, 3.0, 0.4]), theta_r=jnp.array([1.1, -3.0, 0.6]),
                      peak=z, region=jnp.zeros((3, 4), jnp.int32))
    m, others = e.match(dets, -3.1)  # the second sector wraps around +-pi
    assert bool(m.found) and float(m.r_f) == 20.0 and int(others) == 1
    m, others = e.match(dets, 0.5)  # only an invalid sector there: a miss, two false alarms
    assert not bool(m.found) and int(others) == 2


def test_jitter_randomises_the_quantisation(paper_rig, scenario):
    # 2000 jittered feet around each of two positions: the foot's azimuth falls uniformly across one radial
    # line (its phase between the polar grid's lines is uniform) and its image radius across one pixel, with
    # the foot within a few centimetres of the position (KS at the 1e-3 level; fixed seed)
    import jax
    from scipy.stats import kstest

    from omnijax.geometry import floor_to_image

    n_lines = 360
    keys = jax.random.split(jax.random.key(3), 2000)
    for foot in e.table1_positions(paper_rig, scenario)[[0, 5]]:
        feet = np.asarray(e.jittered_feet(paper_rig, foot, keys, n_lines))
        rt = np.asarray(floor_to_image(paper_rig, feet))
        r0, t0 = np.asarray(floor_to_image(paper_rig, np.asarray(foot)))
        phase = (rt[:, 1] * n_lines / (2 * np.pi)) % 1.0
        assert kstest(phase, "uniform").pvalue > 1e-3
        assert kstest(rt[:, 0] - r0 + 0.5, "uniform").pvalue > 1e-3
        assert np.abs(np.asarray(e.wrap_pi(rt[:, 1] - t0))).max() <= np.pi / n_lines + 1e-12
        assert np.hypot(*(feet - foot).T).max() < 0.05


def test_ratio_of_means_and_its_standard_error_against_the_closed_form():
    # errors e = b + s z (z standard normal), the prediction p = s^2 + b^2 every trial: the ratio p / mean(e^2)
    # is 1 with standard error sqrt(2 s^4 + 4 s^2 b^2) / (s^2 + b^2) / sqrt(n) to first order. 500 samples of
    # n = 1600 (seed 0): the ratios' mean within 4 standard errors of its mean of 1 (plus the O(1/n) bias of
    # a ratio), their spread and the median estimated standard error within 10 % of the closed form (the
    # spread of 500 values has a relative sampling error of 3 %: false failure < 1e-3)
    rng = np.random.default_rng(0)
    s, b, n = 2.0, 1.0, 1600
    p = s * s + b * b
    se = math.sqrt(2 * s**4 + 4 * s * s * b * b) / p / math.sqrt(n)
    err = b + s * rng.standard_normal((500, n))
    est = np.array([e.ratio_of_means(np.full(n, p), v * v) for v in err])
    assert abs(est[:, 0].mean() - 1) < 4 * se / math.sqrt(500) + 2 * se * se
    assert est[:, 0].std(ddof=1) == pytest.approx(se, rel=0.1)
    assert np.median(est[:, 1]) == pytest.approx(se, rel=0.1)
    r, r_se = e.ratio_of_means(np.full(3, p), np.ones(3))
    assert math.isnan(r) and math.isnan(r_se)


def _synthetic_trials(rig, n, key=0):
    """Trials whose detections scatter about the true foot by the sigma rule's sigmas, without rendering."""
    import jax

    rng = np.random.default_rng(key)
    true_r, true_t = 120.0 + rng.uniform(-0.5, 0.5, n), 0.6 + rng.uniform(-0.01, 0.01, n)
    s_r, s_t = np.full(n, 2.0), np.full(n, 0.004)
    used_r, used_t = (np.asarray(v) for v in e.detection_sigmas(rig, s_r, s_t, 0.0, 0.0, true_r))
    r_f, th = true_r + used_r * rng.standard_normal(n), true_t + used_t * rng.standard_normal(n)
    x_true = np.asarray(rig.input_mean(true_r, true_t))
    z = np.zeros(n)
    det = e.Matched(found=np.ones(n, bool), r_f=r_f, r_in=r_f - 5, theta_f=th, sigma_r_f=s_r, sigma_theta_f=s_t,
                    bound_r_f=z, bound_theta_f=z, height_r_f=z, from_head=z > 0, contrast=z + 100)
    return e.Trials(det=det, x_true=x_true, r_inner=true_r - 5, head=np.zeros((n, 3)), R_h=z + 0.1,
                    true_rig=jax.tree.map(lambda a: np.broadcast_to(np.asarray(a), (n, *np.shape(a))), rig),
                    others=z.astype(int), lines_over=z.astype(int))


def test_table_row_keeps_the_report_keys(paper_rig):
    # the contract's keys (docs/design.md section 7) on detections that scatter by exactly the sigmas the
    # prediction uses (one fixed rig, person priors zero): the ratios and NEES near 1 (64 trials: loose bounds)
    import equinox as eqx

    rig = eqx.tree_at(lambda r: (r.sigmas.H_p, r.sigmas.R_h), paper_rig, (jnp.zeros(()), jnp.zeros(())))
    t = _synthetic_trials(rig, 64)
    row = e.table_row(rig, "P1", (1.0, 2.0), t, True, paper=_synthetic_trials(rig, 16, 1))
    assert set(row) >= {"position", "pred_var_tan_tilt", "emp_var_tan_tilt", "pred_var_sin_pan", "emp_var_sin_pan",
                        "trials", "ratio_tan_tilt", "ratio_tan_tilt_se", "ratio_sin_pan", "ratio_sin_pan_se",
                        "pointing", "paper_fixed_position", "diagnosis"}
    assert row["trials"] == 64 and set(row["pointing"]) >= {"nees_mean", "nees_over_5_99", "frames"}
    assert row["diagnosis"]["r_in_bias_px"] == pytest.approx(row["diagnosis"]["r_f_bias_px"])
    assert abs(row["diagnosis"]["foot_model_offset_bias_px"]) < 1e-9
    for q in ("tan_tilt", "sin_pan"):
        assert row[f"ratio_{q}"] == pytest.approx(row[f"pred_var_{q}"] / row[f"emp_var_{q}"])
        assert 0.5 < row[f"ratio_{q}"] < 2 and 0 < row[f"ratio_{q}_se"] < 0.5
        assert row["paper_fixed_position"][f"ratio_{q}"] > 0
    assert 0.5 < row["pointing"]["nees_mean"] < 2
