"""Layout optimiser: objectives and their gradients, the box map, the search against its grid,
the [layout] section, and `omnijax optimise`'s contract (docs/design.md section 7.3)."""

from __future__ import annotations

import copy
import json
import math
import tomllib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

from omnijax import ConfigError, parse_rig
from optimise import (
    SENSE,
    Box,
    configured_layout,
    floor_grid,
    floor_statistic,
    floor_values,
    search,
    search_box,
)
from runtime.cli import main
from runtime.files import load_rig
from tests.autodiff import assert_jacobians_close, cached_jit
from tests.paths import CONFIGS
from tests.tolerances import ROOT_FINITE_DIFF

PAPER = str(CONFIGS / "paper.toml")


def _rig(**layout):
    d = tomllib.loads((CONFIGS / "paper.toml").read_text())
    d["layout"].update(layout)
    return parse_rig(d, source="test.toml")


# ---------------------------------------------------------------------------------------------
# The floor region and the per-point values


def test_floor_grid_keeps_the_room_and_leaves_out_its_excluded_zones(paper_rig):
    fl = floor_grid(paper_rig.room, 0.25)
    X, Y = np.asarray(fl.X), np.asarray(fl.Y)
    assert fl.size == X.size == int(fl.inside.sum())
    assert X.min() > -4.5 and X.max() < 3.3 and Y.min() > -3 and Y.max() < 3
    assert not np.any((X < -3.0) & (Y > 2.2))  # the cupboard
    np.testing.assert_array_equal(fl.to_map(X)[fl.inside], X)
    Xp, Yp, live = fl.padded(128)
    assert Xp.shape[0] % 128 == 0 and int(live.sum()) == fl.size


@pytest.fixture(scope="module")
def paper_floor(paper_rig):
    """The paper rig's floor grid (0.25 m) and its per-point values at the configured layout."""
    fl = floor_grid(paper_rig.room, 0.25)
    values = jax.jit(lambda X, Y: floor_values(paper_rig, configured_layout(paper_rig), X, Y, fl.step))
    return fl, jax.tree.map(np.asarray, values(fl.X, fl.Y))


def test_near_zone_is_left_out_smoothly(paper_floor):
    fl, fv = paper_floor
    d, w = np.asarray(fv.distance), np.asarray(fv.weight)
    assert np.all(w[d <= 1.0] == 0) and np.all(w[d >= 1.25] == 1)
    assert np.all((w >= 0) & (w <= 1)) and np.any((w > 0) & (w < 1))
    assert np.all(np.isfinite(np.asarray(fv.face_px))) and np.all(np.isfinite(np.asarray(fv.var_pan)))


def test_face_px_is_the_zoom_rules_face_where_p_contain_is_met(paper_rig, paper_floor):
    from omnijax import aim, face_pixels, point_image_radius

    fl, fv = paper_floor
    idx = np.array([0, fl.size // 3, fl.size - 1])
    X, Y = np.asarray(fl.X)[idx], np.asarray(fl.Y)[idx]
    omni = paper_rig.omni
    r_f = point_image_radius(jnp.hypot(X, Y), 0.0, omni.r_m, omni.H_o, omni.profile)
    a = jax.vmap(lambda r, t: aim(paper_rig, r, t))(r_f, jnp.arctan2(Y, X))
    expect = face_pixels(paper_rig.foveal.lens, a.zoom.zoom, a.pointing.slant, paper_rig.person.R_h)
    assert np.all(np.asarray(a.zoom.feasible)) and np.all(fv.feasible[idx] == 1.0)
    np.testing.assert_allclose(fv.face_px[idx], np.asarray(expect), rtol=1e-9)


def test_worst_case_stand_in_approaches_the_worst_from_the_better_side():
    v = jnp.array([1.0, 2.0, 5.0, 4.0])
    w = jnp.array([1.0, 1.0, 1.0, 0.0])
    assert float(floor_statistic(v, w, "worst", 1.0)) == 5.0
    assert float(floor_statistic(v, w, "worst", -1.0)) == 1.0
    soft = [float(floor_statistic(v, w, "worst", 1.0, q)) for q in (4.0, 32.0, 256.0)]
    assert soft[0] < soft[1] < soft[2] < 5.0 and soft[2] == pytest.approx(5.0, rel=0.01)
    assert float(floor_statistic(v, w, "mean", 1.0)) == pytest.approx(8.0 / 3.0)


@pytest.mark.slow
def test_objective_gradients_match_finite_differences(paper_rig):
    """Every objective (face_px, variance; mean and the smooth worst case) w.r.t. D_c, H_f, theta_c and
    H_o: forward-mode autodiff (the optimiser's mode, through the zoom's implicit function) against
    central differences (step 1e-5 m or rad) on a 0.6 m floor grid. The face's zoom is a root found
    to 1e-12 in its normal score, so its differences carry ~1e-7 relative noise: the bound is 1e-4
    relative, plus 1e-9 of each objective's value for the tiny slopes."""
    from optimise import Layout

    fl = floor_grid(paper_rig.room, 0.6)
    X, Y = fl.X, fl.Y

    def objectives(v):
        layout = Layout(D_c=v[0], H_f=v[1], theta_c=v[2], H_o=v[3])
        fv = floor_values(paper_rig, layout, X, Y, fl.step)
        out = []
        for objective, sense in SENSE.items():
            for statistic, q in (("mean", None), ("worst", 32.0)):
                out.append(floor_statistic(fv.per_point(objective), fv.weight, statistic, sense, q))
        return jnp.stack(out)

    v0 = np.array([2.7, 1.9, 0.4, 2.75])
    value = np.asarray(cached_jit(objectives)(v0))
    assert_jacobians_close(objectives, v0, step=1e-5, rtol=ROOT_FINITE_DIFF, atol=1e-9 * np.abs(value)[:, None],
                           modes=("fwd",))


# ---------------------------------------------------------------------------------------------
# The box and its map to an unconstrained space


@given(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(-3.0, 3.0))
def test_box_map_round_trip(f1, f2, theta):
    box = Box(names=("D_c", "H_f", "theta_c"), lower=jnp.array([0.5, 1.2, -math.pi]),
              upper=jnp.array([3.0, 2.6, math.pi]), periodic=(False, False, True))
    x = np.array([0.5 + 2.5 * f1, 1.2 + 1.4 * f2, theta])
    u = box.to_unconstrained(jnp.asarray(x))
    assert np.all(np.abs(np.asarray(u[:2])) <= math.pi / 2 + 1e-12)
    np.testing.assert_allclose(np.asarray(box.from_unconstrained(u)), x, atol=1e-9)
    far = np.asarray(box.from_unconstrained(jnp.array([40.0, -40.0, 40.0])))  # any u lands inside the box
    assert 0.5 <= far[0] <= 3.0 and 1.2 <= far[1] <= 2.6
    assert -math.pi <= box.wrap(far)[2] < math.pi


def test_bound_side_and_inset():
    box = Box(names=("D_c", "H_f"), lower=jnp.array([0.5, 1.2]), upper=jnp.array([3.0, 2.6]),
              periodic=(False, False))
    assert box.bound_side([3.0, 1.9]) == {"D_c": "upper"}
    assert box.bound_side([0.5001, 1.2]) == {"D_c": "lower", "H_f": "lower"}
    assert box.bound_side([1.0, 2.0]) == {}
    np.testing.assert_allclose(box.inset([9.0, 0.0]), [3.0 - 0.05, 1.2 + 0.028])


def test_default_bounds_come_from_the_room_and_the_heights(paper_rig, fisheye_rig):
    lo, hi = np.asarray(paper_rig.layout.lower), np.asarray(paper_rig.layout.upper)
    assert paper_rig.layout.vary == ("D_c", "H_f") and paper_rig.layout.objective == "face_px"
    np.testing.assert_allclose([lo[0], hi[0], lo[1], hi[1]], [0.25, 3.3, 1.15, 2.7])
    lo, hi = np.asarray(fisheye_rig.layout.lower), np.asarray(fisheye_rig.layout.upper)  # no [layout] section
    assert hi[0] == pytest.approx(5.0 / math.cos(math.radians(30)))  # the wall at x = 5 along theta_c = 30 deg
    assert (lo[1], hi[1]) == pytest.approx((1.72 - 0.10 - 0.5, 2.9))
    assert hi[2] - lo[2] == pytest.approx(2 * math.pi)
    assert search_box(_rig(vary=["D_c", "theta_c"])).periodic == (False, True)


# ---------------------------------------------------------------------------------------------
# The search against its grid


@pytest.mark.slow
def test_search_matches_its_grid_and_reports_the_bound():
    """Mean variance in the paper's room: the optimum sits on D_c's upper bound (the wall), as the
    paper's section 6 and docs/design.md section 4.14 expect; the optimiser is within 0.5 % of the grid's best."""
    rig = _rig(objective="variance", grid_step=0.5, landscape=7, starts=2)
    result = search(rig, floor_grid(rig.room, 0.5))
    assert result.on_bound.get("D_c") == "upper"
    assert result.objective <= result.grid_objective * 1.005
    assert result.objective < result.objective_start
    assert all(s.converged for s in result.starts)
    assert result.landscape.summaries["variance_mean"].shape == (7, 7)
    best = float(np.min(result.landscape.summaries["variance_mean"]))
    assert result.grid_objective == pytest.approx(best)


# ---------------------------------------------------------------------------------------------
# The [layout] section


BAD_LAYOUT = [
    ({"vary": ["D_c", "height"]}, "layout.vary"),
    ({"vary": ["D_c", "D_c"]}, "vary must not repeat"),
    ({"vary": []}, "layout.vary"),
    ({"D_c": [3.0, 1.0]}, "D_c must be [low, high]"),
    ({"D_c": [-1.0, 1.0]}, "layout.D_c.0: expected metres in [0, "),
    ({"H_f": [0.0, 2.0]}, "H_f bounds must be > 0"),
    ({"theta_c_deg": [-200.0, 200.0]}, "at most 360 deg"),
    ({"vary": ["D_c", "H_o"]}, "H_o bounds [low, high] are required"),
    ({"vary": ["H_o"], "H_o": [1.5, 3.0]}, "must lie above person.H_p"),
    ({"grid_step": 0.0}, "layout.grid_step"),
    ({"grid_step": 0.03}, "floor points"),
    ({"objective": "faces"}, "layout.objective"),
    ({"statistic": "median"}, "layout.statistic"),
    ({"starts": 0}, "layout.starts"),
    ({"landscape": 2}, "layout.landscape"),
    ({"vary": ["D_c", "H_f", "theta_c"], "landscape": 40}, "lower landscape"),
    ({"near_radius": 0.01}, "layout.near_radius"),
    ({"zoom": 2.0}, "layout.zoom: unknown key"),
]


@pytest.mark.parametrize("layout,expect", BAD_LAYOUT, ids=[str(b[0]) for b in BAD_LAYOUT])
def test_bad_layout_section_is_one_line(layout, expect):
    d = tomllib.loads((CONFIGS / "paper.toml").read_text())
    d["layout"] = {**d["layout"], **copy.deepcopy(layout)}
    with pytest.raises(ConfigError) as err:
        parse_rig(d, source="bad.toml")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("bad.toml: ") and expect in msg


@pytest.mark.parametrize("name", ["paper.toml", "office_fisheye.toml", "l_room.toml", "corridor.toml"])
def test_shipped_rigs_load(name):
    rig = load_rig(CONFIGS / name)
    assert set(rig.layout.vary) <= {"D_c", "H_f", "theta_c", "H_o"}
    assert np.all(np.asarray(rig.layout.lower) <= np.asarray(rig.layout.upper))


# ---------------------------------------------------------------------------------------------
# The command


@pytest.mark.slow
def test_optimise_writes_the_contract_and_maps(tmp_path, capsys):
    out = tmp_path / "opt"
    code = main(["optimise", "--config", PAPER, "--out", str(out), "--grid-step-m", "0.6", "--landscape", "5",
                 "--starts", "2", "--no-cache"])
    assert code == 0, capsys.readouterr().err
    rep = json.loads((out / "layout.json").read_text())
    for key in ("D_c_m", "H_f_m", "objective", "objective_start", "grid_best", "seconds"):
        assert key in rep
    assert set(rep["grid_best"]) >= {"D_c_m", "H_f_m", "objective"}
    assert rep["objective_name"] == "face_px" and rep["sense"] == "max"
    assert rep["objective"] >= rep["objective_start"]
    assert rep["objective"] >= rep["grid_best"]["objective"] * (1 - 0.005)
    assert 0.25 <= rep["D_c_m"] <= 3.3 and 1.15 <= rep["H_f_m"] <= 2.7
    assert rep["findings"]["tilt_variance_best_H_f"]["H_p_minus_R_h_m"] == pytest.approx(1.65)
    for name in rep["maps"]:
        assert (out / name).stat().st_size > 10_000
    assert set(rep["maps"]) == {"face_px_map.png", "variance_map.png", "pan_tilt_map.png", "landscape.png"}
    assert not list(tmp_path.glob(".*partial*"))


@pytest.mark.parametrize("args,expect", [
    (["--grid-step-m", "-1"], "layout.grid_step"),
    (["--vary", "H_o"], "H_o bounds"),
    (["--starts", "0"], "layout.starts"),
])
def test_optimise_bad_flags_exit_2_and_write_nothing(tmp_path, capsys, args, expect):
    out = tmp_path / "opt"
    code = main(["optimise", "--config", PAPER, "--out", str(out), "--no-cache", *args])
    _, err = capsys.readouterr()
    assert code == 2 and expect in err and err.count("\n") == 1 and "command-line overrides" in err
    assert not out.exists()


def test_the_objective_with_its_gradient_has_the_plain_objectives_value_gradient_and_hessian():
    """``_with_gradient`` (BFGS's objective, its derivative computed with its value in forward mode) gives
    the same value, gradient and second derivative (reverse over its forward rule) as the function it
    wraps, at a fixed point of a non-quadratic function of three variables with a pytree of arguments;
    a derivative in the arguments is refused."""
    from optimise._search import _with_gradient

    def f(u, args):
        a, (b,) = args
        return jnp.sum(a * jnp.sin(u) ** 2) + b * jnp.prod(jnp.cos(u)) + jnp.dot(u, u) ** 1.5

    g = _with_gradient(f)
    u = jnp.asarray([0.3, -1.1, 2.0])
    args = (jnp.asarray([1.0, 2.0, 0.5]), (jnp.asarray(0.7),))
    assert float(g(u, args)) == pytest.approx(float(f(u, args)), rel=1e-12)
    np.testing.assert_allclose(jax.grad(g)(u, args), jax.grad(f)(u, args), rtol=1e-10)
    np.testing.assert_allclose(jax.jit(jax.value_and_grad(g))(u, args)[1], jax.grad(f)(u, args), rtol=1e-10)
    np.testing.assert_allclose(jax.jacrev(jax.grad(g))(u, args), jax.hessian(f)(u, args), rtol=1e-8)
    with pytest.raises(ValueError, match="in u only"):
        jax.grad(lambda a: g(u, (a, args[1])))(args[0])
