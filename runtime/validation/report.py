"""``report.md``: the validation report for a reader, written beside ``report.json``."""

from __future__ import annotations


def _g(v, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    return f"{v:.{digits}g}"


def _ratio(row: dict, q: str) -> str:
    r, se = row[f"ratio_{q}"], row[f"ratio_{q}_se"]
    return "n/a" if r is None else f"{r:.3g} +- {se:.2g}"


def _table1(rows: list[dict], full: bool) -> list[str]:
    head = ("| position | foot (m) | to PTZ (m) | trials | pred var tan tilt | MSE tan tilt | ratio | "
            "pred var sin pan | MSE sin pan | ratio | NEES / dof |")
    lines = [head, "|" + "---|" * 11]
    for r in rows:
        lines.append(
            f"| {r['position']} | ({r['foot_m'][0]:.2f}, {r['foot_m'][1]:.2f}) | {r['distance_to_ptz_m']:.2f} | "
            f"{r['trials']} | {_g(r['pred_var_tan_tilt'])} | {_g(r['emp_var_tan_tilt'])} +- "
            f"{_g(r['emp_var_tan_tilt_se'], 2)} | {_ratio(r, 'tan_tilt')} | {_g(r['pred_var_sin_pan'])} | "
            f"{_g(r['emp_var_sin_pan'])} +- {_g(r['emp_var_sin_pan_se'], 2)} | {_ratio(r, 'sin_pan')} | "
            f"{_g(r['pointing']['nees_mean'])} |")
    if not full:
        lines += ["", "The paper's Table 1 as it was measured (labelled `paper_fixed_position`): the person at the "
                  "exact position in every trial, the variance of the error about its own mean; at one exact "
                  "position the polar grid's quantisation is a constant offset, which this variance cannot see, so "
                  "it is for comparison with the paper only.", "",
                  "| position | trials | pred var tan tilt | var tan tilt | ratio | pred var sin pan | var sin pan | "
                  "ratio |", "|" + "---|" * 8]
        for r in rows:
            p = r["paper_fixed_position"]
            lines.append(f"| {r['position']} | {p['trials']} | {_g(p['pred_var_tan_tilt'])} | "
                         f"{_g(p['emp_var_tan_tilt'])} | {_ratio(p, 'tan_tilt')} | {_g(p['pred_var_sin_pan'])} | "
                         f"{_g(p['emp_var_sin_pan'])} | {_ratio(p, 'sin_pan')} |")
    lines += ["", "Diagnosis (the detector's sigmas against its errors about the truth; the r_f bias split into the "
              "inner end's and the person model's, see docs/validation.md):", "",
              "| position | sigma_r_f (px) | r_f bias (px) | r_f sd (px) | inner end bias (px) "
              "| model offset bias (px) | sigma_theta_f (rad) | theta_f bias (rad) | theta_f sd (rad) | contrast | "
              "pred/MSE tan tilt, measured errors | pred/MSE sin pan, measured errors |",
              "|" + "---|" * 12]
    for r in rows:
        d = r["diagnosis"]
        alt = [r[f"pred_var_{q}_measured_detection_sigma"] / r[f"emp_var_{q}"] if r[f"emp_var_{q}"] > 0 else None
               for q in ("tan_tilt", "sin_pan")]
        lines.append(f"| {r['position']} | {_g(d['sigma_r_f_px'])} | {d['r_f_bias_px']:+.2f} +- "
                     f"{d['r_f_bias_se_px']:.2f} | {_g(d['r_f_sd_px'])} | {d['r_in_bias_px']:+.2f} | "
                     f"{d['foot_model_offset_bias_px']:+.2f} | {_g(d['sigma_theta_f_rad'])} | "
                     f"{d['theta_f_bias_rad']:+.2g} | {_g(d['theta_f_sd_rad'])} "
                     f"| {_g(d['contrast_median'])} | {_g(alt[0])} | {_g(alt[1])} |")
    return lines


def report_markdown(report: dict) -> str:
    """The report as Markdown: every table and figure with one sentence of what it shows."""
    c, p = report["chroma"], report["ptz"]
    out = [f"# omnijax validate: {report['config']}", "",
           f"Camera model `{report['camera_model']}`, seed {report['seed']}, "
           f"{'quick run' if report['quick'] else 'full run'}, {report['seconds']:.0f} s.", "",
           "## Chromaticity covariance (eq 5, figure 9)", "",
           f"Eq 5 against Monte Carlo over R, G at B = {c['blue']:g}: largest relative difference "
           f"{c['max_rel_diff']:.4f} (sampling alone gives about {c['expected_sampling_rel']:.4f}); "
           f"against the Jacobian {c['eq5_vs_jacobian_max_rel']:.1e}.", "",
           "![chroma](chroma.png)", "",
           "`chroma.png` shows eq 5's variance over (R, G) and the Monte Carlo estimate's difference from it "
           "(the paper's figure 9).", "",
           "## Pointing variances over the floor (eq 13/14, figure 10)", "",
           f"Over {p['points_compared']} floor points at least {p['min_distance_m']} m from the PTZ: "
           f"autodiff vs Monte Carlo {p['autodiff_vs_mc_max_rel']:.4f}, analytic (eq 13/14) vs Monte Carlo "
           f"{p['analytic_vs_mc_max_rel']:.3g}, autodiff vs analytic {p['autodiff_vs_analytic_max_rel']:.3g} "
           "(largest relative differences).", ""]
    for q in ("sin_pan", "tan_tilt", "pan", "tilt"):
        out += [f"![{q}](ptz_{q}.png)", "",
                f"`ptz_{q}.png` shows var({q.replace('_', ' ')}) by the four methods over the floor and where "
                "each departs from Monte Carlo.", ""]
    t = report["table1_summary"]
    target = t["target_ratio_rel_se"]
    out += ["## Table 1: one fixed rig (the paper's experiment)", "",
            f"A person stands still at eight positions ({t['scenario']}); each trial is a rendered omni frame "
            "of a fresh person (height, head, clothing from the priors) with fresh sensor noise, moved by up to "
            "half a pixel of radius and half a radial line of azimuth around the position (so that the polar "
            "grid's quantisation is random across trials), run through the detector; the prediction is the mean "
            "over trials of the pointing covariance with the detector's sigma_r_f and sigma_theta_f under the "
            "sigma rule and the person priors, calibration sigmas zero. Measured is the mean squared error "
            "(MSE) of the pointing about the truth, bias included; ratios are predicted / measured +- one "
            "standard error. "
            + (f"Each position took as many trials as put both ratios' relative standard error at {target:g} "
               f"(at most {t['trials_fixed_rig_max']}): {t['seconds_fixed_rig']:.0f} s for the eight."
               if target else f"{t['trials_fixed_rig_max']} trials per position."), "",
            "![positions](table1_positions.png)", "",
            "`table1_positions.png` shows where the eight positions lie relative to the omni axis and the PTZ.", ""]
    out += _table1(report["table1"], full=False)
    out += ["", "## Table 1 with a fresh rig per trial, full propagation", "",
            "The same positions; each trial draws a new true rig (calibration sigmas) and a new person "
            "(height, head, clothing) and compares the pointing error with the full propagation.", ""]
    out += _table1(report["table1_full_propagation"], full=True)
    out += ["", "![table1](table1.png)", "",
            "`table1.png` shows predicted / empirical variance per position for both experiments (dots: with the "
            "detector's sigmas, +-2 sampling errors; crosses: with the measured detection spread instead), "
            "against the +-10 % band.", ""]
    s = t["fixed_rig"], t["fresh_rig"]
    out += [f"Within +-10 %: fixed rig {s[0]['rows_within_10pct_tan_tilt']}/8 (tan tilt), "
            f"{s[0]['rows_within_10pct_sin_pan']}/8 (sin pan); fresh rig {s[1]['rows_within_10pct_tan_tilt']}/8, "
            f"{s[1]['rows_within_10pct_sin_pan']}/8.", ""]
    pt = report["pointing"]
    out += ["## Pointing NEES", "",
            f"Over the {pt['frames']} fresh-rig trials (each one PTZ aimed and arrived at a detected person, "
            f"as the loop aims): the NEES of (pan, tilt) against the true head direction under the aim's "
            f"covariance is {pt['nees_mean']:.3f} per degree of freedom (+- {pt['nees_mean_se']:.3f}; 1 when the "
            f"covariance is right; pan {pt['pan_nees_mean']:.3f}, tilt {pt['tilt_nees_mean']:.3f}), and "
            f"exceeds chi-square(2)'s 95 % point 5.99 in {pt['nees_over_5_99']:.4f} of them (0.05 when "
            "right). Containment at p_contain 0.9, 0.95, 0.99 over the same trials is below.", ""]
    r = report["rates"]
    out += ["## Detection rates", "",
            "| rate | configured | measured | 95 % interval | trials |", "|---|---|---|---|---|",
            f"| false alarm per radial line (eq 10) | x_f = {r['x_f']:g} | {r['false_alarm_rate']:.4g} | "
            f"[{r['false_alarm_interval'][0]:.4g}, {r['false_alarm_interval'][1]:.4g}] | "
            f"{r['false_alarm_lines']['n']} lines |",
            f"| miss per person | x_m = {r['x_m']:g} | {r['miss_rate']:.4g} | "
            f"[{r['miss_interval'][0]:.4g}, {r['miss_interval'][1]:.4g}] | {r['misses']['n']} frames |",
            f"| empty frames with a detection | {r['predicted_frames_with_detection']:.3g} (thresholds) | "
            f"{r['empty_frames_with_detection']['rate']:.4g} | [{r['empty_frames_with_detection']['lower']:.3g}, "
            f"{r['empty_frames_with_detection']['upper']:.3g}] | {r['empty_frames_with_detection']['n']} frames |",
            "", "The table shows how often the detector fires on empty floor and misses a standing person, "
            "against the rates its thresholds were built for.", ""]
    out += ["## Containment", "",
            "| rule | p_contain | measured rate | 95 % interval | predicted (mean) | median zoom | "
            "median face (px) | trials |", "|---|---|---|---|---|---|---|---|"]
    for c in report["containment"]["curve"]:
        out.append(f"| {c['rule']} | {c['p_contain']:g} | {c['rate']:.4f} | [{c['lower']:.4f}, {c['upper']:.4f}] | "
                   f"{c['predicted_mean']:.4f} | {c['zoom_median']:.2f} | {c['face_px_median']:.0f} | {c['trials']} |")
    out += ["", "![containment](containment.png)", "",
            "`containment.png` shows how often the true head disc lay inside the foveal frame at each rule's zoom "
            "(fresh rig per trial) against the p_contain asked for, and the face pixels each rule buys.", ""]
    f = report.get("framing")
    if f is not None:
        out += ["## Framing: what the PTZ delivers", "",
                f"Over all {f['trials']} fresh-rig trials at p_contain = {f['p_contain']:g} (a trial whose person "
                f"was not detected counts as not framed; {f['detected']} were detected). The PTZ would have been "
                f"aimed at no person (the person missed, another detection present) in {f['no_person_share']:.4f} "
                f"of them and had no target in {f['no_target_share']:.4f}.", "",
                "| rule | framed, all trials | framed, detected trials | median face (px) |", "|---|---|---|---|"]
        for rule, r in f["rules"].items():
            det = "n/a" if r["rate_detected"] is None else f"{r['rate_detected']:.4f}"
            px = "n/a" if r["face_px_median"] is None else f"{r['face_px_median']:.0f}"
            out.append(f"| {rule} | {r['rate_all_trials']:.4f} | {det} | {px} |")
        rules = list(f["rules"])
        out += ["", "Face coverage: per position (one person standing there), the share of trials with the head "
                "framed.", "", "| position | trials | " + " | ".join(rules) + " |",
                "|---|---|" + "---|" * len(rules)]
        for c in f["face_coverage"]:
            out.append(f"| {c['position']} | {c['trials']} | " + " | ".join(f"{c['rules'][r]:.3f}" for r in rules)
                       + " |")
        out.append("")
    return "\n".join(out)
