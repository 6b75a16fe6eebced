"""Pointing uncertainty: autodiff against a hand-derived closed form, finite differences,
jacrev and Monte Carlo; eq 13/14 against an independent transcription; GUM second order
against exact moments."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from jax.test_util import check_grads

from omnijax import (
    Paraboloid,
    gum_second_order,
    pointing,
    pointing_covariance,
    pointing_covariance_mc,
    pointing_outputs,
)
from tests.autodiff import assert_jacobians_close
from tests.tolerances import CLOSED_FORM, FINITE_DIFF

PROFILE = Paraboloid()
_outputs_of = lambda x: pointing_outputs(x, PROFILE)
_outputs_jit = jax.jit(_outputs_of)
_jacfwd = jax.jit(jax.jacfwd(_outputs_of))
_valid = jax.jit(lambda x: (pointing(x, PROFILE).valid, pointing(x, PROFILE).distance, pointing(x, PROFILE).radius))


def hand_jacobian(x: np.ndarray) -> np.ndarray:
    """d(pan, tilt, sin pan, tan tilt) / d(r_f, theta_f, H_o, H_f, D_c, theta_c, r_m, H_p, R_h), by hand."""
    r_f, th_f, H_o, H_f, D_c, th_c, r_m, H_p, R_h = x
    q = r_m**2 - r_f**2
    R = 2 * H_o * r_m * r_f / q
    dR = np.zeros(9)
    dR[0] = 2 * H_o * r_m * (r_m**2 + r_f**2) / q**2
    dR[6] = -2 * H_o * r_f * (r_m**2 + r_f**2) / q**2
    dR[2] = R / H_o
    vt = th_f - th_c
    dvt = np.zeros(9)
    dvt[1], dvt[5] = 1.0, -1.0
    dDc = np.zeros(9)
    dDc[4] = 1.0
    N, M = R * np.sin(vt), D_c - R * np.cos(vt)
    D2 = N * N + M * M
    D = math.sqrt(D2)
    dpan = (D_c * np.sin(vt) * dR + R * (D_c * np.cos(vt) - R) * dvt - R * np.sin(vt) * dDc) / D2
    dD = ((R - D_c * np.cos(vt)) * dR + D_c * R * np.sin(vt) * dvt + (D_c - R * np.cos(vt)) * dDc) / D
    aim = H_p - R_h - H_f
    daim = np.zeros(9)
    daim[7], daim[8], daim[3] = 1.0, -1.0, -1.0
    dtilt = (D * daim - aim * dD) / (D2 + aim**2)
    pan = math.atan2(N, M)
    dsin = math.cos(pan) * dpan
    dtan = daim / D - aim * dD / D2
    return np.stack([dpan, dtilt, dsin, dtan])


def hand_eq13_eq14(x: np.ndarray, s: np.ndarray) -> tuple[float, float]:
    """Eq 13 and eq 14 with sigma_Rp^2, sigma_Dp^2 propagated through eq 1 and eq 3 by hand."""
    r_f, th_f, H_o, H_f, D_c, th_c, r_m, H_p, R_h = x
    v = s**2
    q = r_m**2 - r_f**2
    R = 2 * H_o * r_m * r_f / q
    var_R = ((2 * H_o * r_m * (r_m**2 + r_f**2) / q**2) ** 2 * v[0]
             + (R / H_o) ** 2 * v[2] + (2 * H_o * r_f * (r_m**2 + r_f**2) / q**2) ** 2 * v[6])
    vt = th_f - th_c
    var_vt = v[1] + v[5]
    D = math.sqrt(D_c**2 + R**2 - 2 * D_c * R * math.cos(vt))
    var_D = (((R - D_c * math.cos(vt)) / D) ** 2 * var_R + (D_c * R * math.sin(vt) / D) ** 2 * var_vt
             + ((D_c - R * math.cos(vt)) / D) ** 2 * v[4])
    aim, var_aim = H_p - R_h - H_f, v[7] + v[8] + v[3]
    eq13 = var_D / D**4 * (aim**2 + var_aim) + var_aim / D**2
    eq14 = (R**2 * var_vt * math.cos(vt) ** 2 / D**2
            + (math.sin(vt) ** 2 + var_vt * math.cos(vt) ** 2)
            * (R**2 * var_D / D**4 + var_R / D**2 + var_R * var_D / D**4))
    return eq13, eq14


def random_inputs(rng: np.random.Generator, n: int) -> np.ndarray:
    """Valid input vectors over a wide range of rigs, away from the PTZ's foot (D_p > 0.3 m)."""
    out = []
    while len(out) < n:
        r_m = rng.uniform(150, 400)
        x = np.array([rng.uniform(0, 0.9) * r_m, rng.uniform(-np.pi, np.pi), rng.uniform(2.2, 4.0),
                      rng.uniform(0.5, 2.5), rng.uniform(0.5, 6.0), rng.uniform(-np.pi, np.pi), r_m,
                      rng.uniform(1.4, 2.0), rng.uniform(0.07, 0.13)])
        valid, distance, radius = _valid(jnp.asarray(x))
        if bool(valid) and float(distance) > 0.3 and float(radius) < 30:
            out.append(x)
    return np.array(out)


inputs = st.integers(0, 2**31 - 1).map(lambda seed: random_inputs(np.random.default_rng(seed), 1)[0])


def _max_rel(a, b, floor):
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), floor)))


@settings(max_examples=1000)
@given(x=inputs)
def test_autodiff_jacobian_is_the_hand_derived_one(x):
    J = np.asarray(_jacfwd(jnp.asarray(x)))
    ref = hand_jacobian(x)
    assert _max_rel(J, ref, 1e-6 * np.abs(ref).max()) < CLOSED_FORM


@settings(max_examples=1000)
@given(x=inputs)
def test_jacfwd_jacrev_and_central_differences_agree(x):
    """jacfwd equals jacrev to rounding; both match central differences (step 1e-6 relative, entries
    below 1e-4 of the largest compared on its scale)."""
    assert_jacobians_close(_outputs_of, x, step=1e-6 * np.maximum(np.abs(x), 1.0), rtol=FINITE_DIFF, floor=1e-4)


@pytest.mark.slow
@settings(max_examples=10)
@given(x=inputs)
def test_second_derivatives_against_finite_differences(x):
    """The GUM second order differentiates the pointing twice (its Hessian, and that Hessian's
    jacfwd): jax.test_util.check_grads to order 2, forward and reverse mode, against central
    differences along a random direction (step 1e-4 in every input). Ten rigs: each example
    compiles its nested derivatives anew (0.3 s), and the program differentiated is the same."""
    check_grads(_outputs_jit, (jnp.asarray(x),), order=2, modes=("fwd", "rev"), eps=1e-4, rtol=FINITE_DIFF)


def test_autodiff_covariance_over_many_points_is_J_sigma_JT():
    """Vectorised over 2000 random points: the jitted batch equals the hand closed form."""
    rng = np.random.default_rng(7)
    x = random_inputs(rng, 2000)
    s = np.abs(x) * rng.uniform(1e-3, 2e-2, x.shape) + 1e-3
    cov = np.asarray(pointing_covariance(jnp.asarray(x), jnp.asarray(s), PROFILE, "autodiff").cov)
    J = np.stack([hand_jacobian(xi) for xi in x])
    ref = np.einsum("pai,pi,pbi->pab", J, s**2, J)
    scale = np.sqrt(np.einsum("paa->pa", ref))
    err = np.abs(cov - ref) / (scale[:, :, None] * scale[:, None, :])
    assert err.max() < CLOSED_FORM


def test_autodiff_by_halves_is_jacfwd_of_the_whole_pointing():
    """The autodiff method differentiates pointing's two halves (eq 1, then eqs 3-4); over 500 random
    points it equals J Sigma J^T with J = jacfwd of the whole nine-input function."""
    rng = np.random.default_rng(8)
    x = random_inputs(rng, 500)
    s = np.abs(x) * rng.uniform(1e-3, 2e-2, x.shape) + 1e-3
    cov = np.asarray(pointing_covariance(jnp.asarray(x), jnp.asarray(s), PROFILE, "autodiff").cov)
    J = np.asarray(jax.vmap(jax.jacfwd(pointing_outputs), in_axes=(0, None))(jnp.asarray(x), PROFILE))
    ref = np.einsum("pai,pi,pbi->pab", J, s**2, J)
    scale = np.sqrt(np.einsum("paa->pa", ref))
    assert (np.abs(cov - ref) / (scale[:, :, None] * scale[:, None, :])).max() < 1e-9


def test_the_grid_covariance_computes_sin_and_cos_once():
    """XLA's CPU fusion counts sin and cos as cheap and copied each into every fused loop that read
    it (sixteen of each over a grid: two thirds of the autodiff covariance's time); geometry.sincos
    keeps them in buffers of their own. The compiled covariance of a 20 x 20 grid, its validity
    included, holds one sine and one cosine."""
    x = jnp.asarray(random_inputs(np.random.default_rng(9), 400).reshape(20, 20, 9))
    s = jnp.asarray([1.0, 0.017, 0.01, 0.01, 0.1, 0.0, 0.5, 0.05, 0.01])
    hlo = jax.jit(lambda x, s: pointing_covariance(x, s, PROFILE, "autodiff")).lower(x, s).compile().as_text()
    assert (hlo.count(" sine("), hlo.count(" cosine(")) == (1, 1)


@settings(max_examples=300)
@given(x=inputs)
def test_covariances_are_symmetric_positive_semidefinite(x):
    s = 0.01 * np.abs(x) + 1e-3
    for method in ("autodiff", "analytic"):
        c = np.asarray(pointing_covariance(jnp.asarray(x), jnp.asarray(s), PROFILE, method).cov)
        np.testing.assert_allclose(c, c.T, rtol=0, atol=1e-15 * np.abs(c).max())
        assert np.linalg.eigvalsh(c).min() >= -1e-12 * np.abs(c).max()


@settings(max_examples=300)
@given(x=inputs)
def test_analytic_is_eq_13_and_eq_14_literally(x):
    s = 0.01 * np.abs(x) + np.array([1.0, 0.017, 0.01, 0.01, 0.1, 0.0, 0.5, 0.05, 0.01])
    c = pointing_covariance(jnp.asarray(x), jnp.asarray(s), PROFILE, "analytic")
    eq13, eq14 = hand_eq13_eq14(x, s)
    assert float(c.var_tan_tilt) == pytest.approx(eq13, rel=1e-10)
    assert float(c.var_sin_pan) == pytest.approx(eq14, rel=1e-10)


def test_eq_13_is_first_order_plus_its_product_term(paper_rig):
    """var(aim / D_p): eq 13 adds sigma_Dp^2 sigma_aim^2 / D_p^4 to the exact first order."""
    x = paper_rig.input_mean(120.0, 1.1)
    s = paper_rig.input_sigma()
    a = pointing_covariance(x, s, PROFILE, "analytic")
    ad = pointing_covariance(x, s, PROFILE, "autodiff")
    eq13, _ = hand_eq13_eq14(np.asarray(x), np.asarray(s))
    D = float(pointing(x, PROFILE).distance)
    v = np.asarray(s) ** 2
    var_aim = v[7] + v[8] + v[3]
    var_D = (eq13 - var_aim / D**2) / ((float(x[7] - x[8] - x[3])) ** 2 + var_aim) * D**4
    assert float(a.var_tan_tilt) == pytest.approx(float(ad.var_tan_tilt) + var_D * var_aim / D**4, rel=1e-10)


def test_eq_14_overstates_sin_pan_where_R_p_and_D_p_correlate(paper_rig):
    """docs/design.md section 4.10: at R_p = 4 m, vartheta = 45 deg eq 14 is several times Monte Carlo's variance."""
    from omnijax import world_to_image

    rig = paper_rig
    px, py = world_to_image(rig.omni, 4 * math.cos(math.pi / 4), 4 * math.sin(math.pi / 4), 0.0)
    r, th = rig.omni.to_polar(px, py)
    x, s = rig.input_mean(r, th), rig.input_sigma()
    mc = pointing_covariance_mc(x, s, PROFILE, jax.random.key(3), rel_tol=0.01)
    a = pointing_covariance(x, s, PROFILE, "analytic")
    assert float(a.var_sin_pan) / float(mc.covariance.var_sin_pan) > 3.0


def test_gum_second_order_is_exact_for_quadratics():
    mu, sd = jnp.array([1.3, -0.7]), jnp.array([0.4, 0.9])
    f = lambda x: jnp.stack([x[0] * x[1], x[0] ** 2])
    c = np.asarray(gum_second_order(f, mu, sd))
    m1, m2 = 1.3, -0.7
    v1, v2 = 0.16, 0.81
    exact = np.array([[m1**2 * v2 + m2**2 * v1 + v1 * v2, 2 * m1 * m2 * v1],
                      [2 * m1 * m2 * v1, 4 * m1**2 * v1 + 2 * v1**2]])
    np.testing.assert_allclose(c, exact, rtol=1e-13)


def test_gum_second_order_cubic_keeps_the_third_derivative_term():
    """y = x^3, x ~ N(m, v): var = 9 m^4 v + 36 m^2 v^2 + 15 v^3; GUM's terms give all but 15 v^3."""
    m, sd = 0.8, 0.3
    v = sd**2
    c = float(gum_second_order(lambda x: x**3, jnp.array([m]), jnp.array([sd]))[0, 0])
    assert c == pytest.approx(9 * m**4 * v + 36 * m**2 * v**2, rel=1e-13)


@pytest.mark.slow
def test_gum_second_order_matches_the_full_third_derivative_tensor(paper_rig):
    """The directional form of the third-derivative term against the literal one (jacfwd of the
    Hessian, all m n^3 entries), on the pointing at 5 floor points (fixed seed), near the PTZ too."""
    rng = np.random.default_rng(7)
    s = paper_rig.input_sigma()
    f = _outputs_of
    for r, th in zip(rng.uniform(20.0, 230.0, 5), rng.uniform(0.0, 2 * np.pi, 5)):
        x = paper_rig.input_mean(r, th)
        v = s**2
        J, H = jax.jacfwd(f)(x), jax.hessian(f)(x)
        T_ijj = jnp.einsum("aijj->aij", jax.jacfwd(jax.hessian(f))(x))
        third = jnp.einsum("ai,bij,i,j->ab", J, T_ijj, v, v)
        literal = ((J * s) @ (J * s).T + 0.5 * jnp.einsum("aij,bij,i,j->ab", H, H, v, v)
                   + 0.5 * (third + third.T))
        np.testing.assert_allclose(np.asarray(gum_second_order(f, x, s)), np.asarray(literal),
                                   rtol=1e-10, atol=1e-14 * float(jnp.abs(literal).max()))


def test_montecarlo_matches_autodiff_where_linear(paper_rig):
    """Tiny sigmas: the geometry is linear over them, so Monte Carlo must agree within its tolerance.

    One point, rel_tol 0.01 (95 %): >= 2e4 trials; false-failure probability < 1e-3 at 3x the tolerance.
    """
    x = paper_rig.input_mean(90.0, 2.0)
    s = paper_rig.input_sigma() * 0.05
    mc = pointing_covariance_mc(x, s, PROFILE, jax.random.key(11), rel_tol=0.01)
    ad = pointing_covariance(x, s, PROFILE, "autodiff")
    assert mc.trials >= 20_000 and mc.tolerance <= 0.01
    for name in ("var_pan", "var_tilt", "var_sin_pan", "var_tan_tilt"):
        assert float(getattr(mc.covariance, name)) == pytest.approx(float(getattr(ad, name)), rel=3 * mc.tolerance)


def test_second_order_tracks_montecarlo_near_the_ptz(paper_rig):
    """1.1 m from the PTZ's foot first order is off by a few %; GUM's second order closes most of it."""
    from omnijax import world_to_image

    rig = paper_rig
    px, py = world_to_image(rig.omni, float(rig.foveal.D_c) - 1.1, 0.05, 0.0)
    r, th = rig.omni.to_polar(px, py)
    x, s = rig.input_mean(r, th), rig.input_sigma()
    mc = pointing_covariance_mc(x, s, PROFILE, jax.random.key(5), rel_tol=0.005, max_trials=2_000_000)
    so = pointing_covariance(x, s, PROFILE, "second_order")
    ad = pointing_covariance(x, s, PROFILE, "autodiff")
    err_so = abs(float(so.var_pan) / float(mc.covariance.var_pan) - 1)
    err_ad = abs(float(ad.var_pan) / float(mc.covariance.var_pan) - 1)
    assert err_so < err_ad
    assert err_so < 0.01 + mc.tolerance


def test_montecarlo_reports_trials_and_tolerance(paper_rig):
    x = paper_rig.input_mean(np.array([50.0, 100.0]), np.array([0.5, 2.5]))
    seen = []
    mc = pointing_covariance_mc(x, paper_rig.input_sigma(), PROFILE, jax.random.key(0), rel_tol=0.05,
                                callback=lambda n, tol: seen.append((n, tol)))
    assert mc.covariance.cov.shape == (2, 4, 4)
    assert mc.trials == seen[-1][0] and mc.batches == len(seen) >= 2
    assert mc.tolerance <= 0.05
