"""The command line: `omnijax variance` and `omnijax validate` keep docs/design.md section 7.3's contracts."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from runtime.cli import build_parser, main
from tests.paths import CONFIGS, ROOT

PAPER = str(CONFIGS / "paper.toml")
INPUTS = ("r_f", "theta_f", "H_o", "H_f", "D_c", "theta_c", "r_m", "H_p", "R_h")


def _variance(capsys, *args):
    code = main(["variance", "--config", PAPER, "--json", *args])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


@pytest.mark.parametrize("method", ["autodiff", "analytic", pytest.param("second_order", marks=pytest.mark.slow),
                                    pytest.param("montecarlo", marks=pytest.mark.slow)])
def test_variance_contract(capsys, method):
    extra = ["--rel-tol", "0.05"] if method == "montecarlo" else []
    rep = _variance(capsys, "--foot", "100", "0.7", "--method", method, *extra)
    for key in ("pan", "tilt", "distance_m", "radius_m", "zoom", "camera_model", "valid", "inputs"):
        assert key in rep
    assert set(rep["var"]) >= {"sin_pan", "tan_tilt", "pan", "tilt", "cov_pan_tilt"}
    assert set(rep["fov"]) == {"h", "v"}
    assert rep["camera_model"] == "paraboloid" and rep["valid"] is True
    assert list(rep["inputs"]) == list(INPUTS)
    assert rep["inputs"]["r_f"] == {"mean": 100.0, "sigma": 1.0}
    assert rep["inputs"]["theta_f"]["sigma"] == pytest.approx(math.radians(1.0))
    assert rep["inputs"]["D_c"] == {"mean": 3.0, "sigma": 0.1}
    assert all(v > 0 for k, v in rep["var"].items() if k != "cov_pan_tilt")


def test_variance_sigma_overrides_are_echoed(capsys):
    rep = _variance(capsys, "--foot", "100", "0.7", "--sigma-rf", "2.5", "--sigma-theta-deg", "0.5")
    assert rep["inputs"]["r_f"]["sigma"] == 2.5 and rep["inputs"]["theta_f"]["sigma"] == math.radians(0.5)
    base = _variance(capsys, "--foot", "100", "0.7")
    assert rep["var"]["pan"] > base["var"]["pan"] * 0.3  # theta sigma 0.5 deg vs 1 deg: smaller, not zero


def test_variance_flags_degenerate_geometry(capsys):
    rep = _variance(capsys, "--foot", "219.5", "0.0")
    assert rep["valid"] is False
    assert all(math.isfinite(v) for v in rep["var"].values())


@pytest.mark.parametrize("args,expect", [
    (["--foot", "-3", "0"], "--foot"),
    (["--foot", "10", "0", "--sigma-rf", "-1"], "--sigma-rf"),
    (["--foot", "10", "nan"], "--foot"),
])
def test_variance_bad_arguments_exit_2(capsys, args, expect):
    code = main(["variance", "--config", PAPER, *args])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and expect in err and err.count("\n") == 1


def test_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("variance", "validate"):
        assert cmd in out


TABLE1_ROW = {"position", "pred_var_tan_tilt", "emp_var_tan_tilt", "pred_var_sin_pan", "emp_var_sin_pan", "trials",
              "ratio_tan_tilt", "ratio_tan_tilt_se", "ratio_sin_pan", "ratio_sin_pan_se"}


@pytest.mark.slow
def test_validate_quick_writes_report_and_maps(tmp_path):
    # as a user runs it: a separate process (the world's renderer is type-checked by its own tests)
    out = tmp_path / "val"
    run = subprocess.run([sys.executable, "-m", "runtime.cli", "validate", "--config", PAPER, "--out", str(out),
                          "--quick", "--grid-step-px", "24", "--trials", "8", "--paper-trials", "8",
                          "--fresh-trials", "8", "--empty-frames", "8"],
                         capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "containment:" in run.stdout
    rep = json.loads((out / "report.json").read_text())
    for name in ("table1", "table1_full_propagation"):
        assert len(rep[name]) == 8
        for row in rep[name]:
            assert set(row) >= TABLE1_ROW and row["trials"] + row["missed"] == 8
            assert row["pred_var_tan_tilt"] > 0 and row["emp_var_tan_tilt"] >= 0
    # one person standing in a plain room, background learnt empty: x_m = 0.01 promises about 0.6 misses in 64
    # trials (seed 0, so the count is fixed, not drawn anew); a person's own dip in the angular profile (two legs
    # near the axis) once split their run and left its centre off them: 2 of these 64 (11 of 40 at P3 and P4 in full)
    assert sum(row["missed"] for row in rep["table1"]) <= 1
    # the foot rho beyond the silhouette's inner end, not pi rho / 4: every position's feet fell 1-2 px short
    # (pooled over these 64 trials -1.4 px, its standard error about 0.25 px; docs/detection.md, "The foot is rho
    # beyond the inner end")
    n = sum(row["trials"] for row in rep["table1"])
    bias = sum(row["diagnosis"]["r_f_bias_px"] * row["trials"] for row in rep["table1"]) / n
    assert abs(bias) < 0.8, bias
    for row in rep["table1"]:  # the paper's own measure beside it, labelled
        assert row["paper_fixed_position"]["trials"] <= 8 and row["paper_fixed_position"]["emp_var_sin_pan"] >= 0
    assert set(rep["pointing"]) >= {"nees_mean", "nees_over_5_99", "frames"} and rep["pointing"]["frames"] > 0
    assert "+-" in run.stdout.split("table1 (")[1].splitlines()[1]  # each ratio printed with its standard error
    assert set(rep["rates"]) >= {"x_f", "false_alarm_rate", "x_m", "miss_rate"}
    assert 0 <= rep["rates"]["false_alarm_rate"] <= 1 and 0 <= rep["rates"]["miss_rate"] <= 1
    assert set(rep["containment"]) >= {"p_contain", "rule", "rate", "trials"}
    assert {(c["rule"], c["p_contain"]) for c in rep["containment"]["curve"]} >= {
        (r, p) for r in ("paper", "calibrated") for p in (0.9, 0.95, 0.99)}
    f = rep["framing"]  # over all 64 fresh-rig trials: a missed person is not framed
    assert f["trials"] == 64 and f["p_contain"] == rep["containment"]["p_contain"]
    assert 0 <= f["no_person_share"] + f["no_target_share"] <= 1 - f["detected"] / 64 + 1e-12
    main_rule = f["rules"][rep["containment"]["rule"]]
    assert main_rule["rate_all_trials"] * 64 == pytest.approx(rep["containment"]["rate"] * f["detected"])
    assert [c["position"] for c in f["face_coverage"]] == [f"P{k}" for k in range(1, 9)]
    for rule, r in f["rules"].items():
        assert r["face_px_median"] > 0
        assert sum(c["rules"][rule] * c["trials"] for c in f["face_coverage"]) == pytest.approx(
            r["rate_all_trials"] * 64)
    assert "framing at p_contain" in run.stdout
    md = (out / "report.md").read_text()
    for name in ("table1.png", "table1_positions.png", "containment.png", "chroma.png", "ptz_pan.png"):
        assert f"]({name})" in md
        assert (out / name).stat().st_size > 10_000
    assert set(rep["chroma"]) >= {"max_rel_diff"}
    assert set(rep["ptz"]) >= {"autodiff_vs_analytic_max_rel", "autodiff_vs_mc_max_rel", "analytic_vs_mc_max_rel"}
    assert rep["chroma"]["eq5_vs_jacobian_max_rel"] < 1e-12
    assert rep["chroma"]["max_rel_diff"] < 0.1
    assert rep["ptz"]["autodiff_vs_mc_max_rel"] < 0.2
    for name in ("chroma.png", "ptz_sin_pan.png", "ptz_tan_tilt.png", "ptz_pan.png", "ptz_tilt.png"):
        assert (out / name).stat().st_size > 10_000
    assert not list(tmp_path.glob(".*partial*"))


def test_validate_failure_leaves_nothing_behind(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text((CONFIGS / "paper.toml").read_text().replace("\n[room]\n", "\n[room]\nfloor = 1\n"))
    out = tmp_path / "val"
    assert main(["validate", "--config", str(bad), "--out", str(out), "--quick"]) == 2
    assert not out.exists() and not list(tmp_path.glob(".*partial*"))
    assert "room.floor: unknown key" in capsys.readouterr().err


def test_validate_failing_midway_ends_and_leaves_nothing_behind(tmp_path, monkeypatch):
    """A failure after the figures' thread started (here the PTZ check, once the chroma figure was
    handed to that thread) ends the run with the error, nothing written: the thread is not left
    waiting for the trials that will never start (it used to wait for them, and the run with it)."""
    import threading

    import runtime.validation.theory as theory

    def broken(*args, **kwargs):
        raise RuntimeError("ptz check broke")

    monkeypatch.setattr(theory, "ptz_check", broken)
    out = tmp_path / "val"
    raised = []

    def run():
        try:
            main(["validate", "--config", PAPER, "--out", str(out), "--quick", "--no-cache"])
        except RuntimeError as exc:
            raised.append(str(exc))

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(300)
    assert not worker.is_alive(), "validate hung after a failure"
    assert raised == ["ptz check broke"]
    assert not out.exists() and not list(tmp_path.glob(".*partial*"))
