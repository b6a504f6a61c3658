"""The Monte Carlo study's terminal report (``studies.montecarlo``)."""
from __future__ import annotations

from planecal.model.layout import display_of as display
from planecal.present.tables import table
from planecal.twin.world import SOURCES


def format_montecarlo(res: dict) -> str:
    st = res["settings"]
    w = res["world"]
    cal = st.get("calibration") or {}
    out = [f"Monte Carlo: scene {st['scene']}, mode {st['mode']}, level "
           f"{cal.get('level', 'offsets')}{' + compliance' if cal.get('compliance') else ''}, "
           f"{res['runs']} runs of "
           f"{res['samples_per_run']:.0f} samples; {w['errors']} world, truth "
           + ("drawn per run" if st["vary_truth"] else f"fixed (seed {st['truth_seed']})")
           + f"; noise: laser {w['laser_noise_mm']:g} mm per reading, repeatability "
           + f"{w['repeatability_mm']:g} mm"
           + (", encoder quantisation" if w["quantization"] else "")
           + ("; fit weighted by the noise model" if st.get("weighted") else
              "; fit unweighted"),
           f"noise model rms per sample {res['sigma_model_mm'] * 1e3:.2f} um, fit sigma "
           f"{res['sigma_fit_mm'] * 1e3:.2f} um; a std from {res['runs']} runs is known to "
           f"+-{res['relative_standard_error_of_std']:.0%} (1 s.e.)", ""]
    rows = []
    for n, p in res["params"].items():
        k, unit = display(n)
        rows.append([n, unit, f"{p['bias'] * k:+.3g}", f"{p['empirical_std'] * k:.4g}",
                     f"{p['crb_std'] * k:.4g}", f"{p['crb_white_std'] * k:.4g}",
                     f"{p['sandwich_std'] * k:.4g}", f"{p['reported_std'] * k:.4g}",
                     f"{p['ratio_emp_to_crb']:.3f}", f"{p['ratio_emp_to_crb_white']:.3f}",
                     f"{p['ratio_emp_to_sandwich']:.3f}", f"{p['ratio_emp_to_reported']:.3f}",
                     f"{p['normalized_std']:.3f}", f"{p['bias_over_crb']:.3f}"])
    out.append(table(["param", "unit", "bias", "emp_std", "CRB", "CRB_white", "sandwich",
                      "reported", "emp/CRB", "emp/white", "emp/sandw", "emp/rep", "std(e/CRB)",
                      "|bias|/CRB"], rows))
    out.append("emp/X: empirical std over the RMS of the runs' X; std(e/CRB): std of the errors "
               "each divided by its own run's bound (robust to designs of unequal strength)")
    if st.get("weighted"):
        out.append("sandwich: the unweighted fit's covariance, for comparison (the errors "
                   "and 'reported' are the weighted fit's)")
    out.append("")
    for key, what in (("chi2_offsets_reported", "offsets, fit's reported covariance"),
                      ("chi2_offsets_sandwich", "offsets, sandwich covariance"),
                      ("chi2_all_reported", "all free parameters, reported covariance")):
        c = res[key]
        if c:
            out.append(f"chi-square ({what}): mean {c['mean']:.2f} for {c['dof']} dof "
                       f"(+-{c['standard_error']:.2f}), KS p {c['ks_pvalue']:.3f}, "
                       f"{c['share_below_chi2_95']:.0%} below the 95 % quantile -> "
                       + ("PASS" if c["passes"] else "FAIL"))
    v = res["verdict"]
    out.append("")
    out.append("offsets within 15 % of the Cramer-Rao bound: "
               + ", ".join(f"{n} {'yes' if ok else 'NO'}" for n, ok in v["efficient_within_15pct_of_crb"].items()))
    out.append("offsets within 15 % of the white-noise bound: "
               + ", ".join(f"{n} {'yes' if ok else 'NO'}" for n, ok in v["within_15pct_of_white_crb"].items()))
    out.append("reported std within 15 % of the spread: "
               + ", ".join(f"{n} {'yes' if ok else 'NO'}" for n, ok in v["reported_std_within_15pct"].items()))
    out.append("bias under a fifth of the bound: "
               + ", ".join(f"{n} {'yes' if ok else 'NO'}" for n, ok in v["bias_under_fifth_of_crb"].items()))
    unreported = [n for n, p in res["params"].items() if p.get("reported_in_runs", 1) == 0]
    if unreported:
        out.append("no std reported in any run (the fit found it not identifiable at its "
                   "residual level): " + ", ".join(unreported))
    if res["not_identifiable_all_free"]:
        out.append("with every parameter free, not identifiable: "
                   + ", ".join(res["not_identifiable_all_free"]))
    out += _format_mismatch(res)
    r = res["rejected_total"]
    out.append(f"rejected poses over all runs: collision {r['collision']}, laser {r['laser']}, "
               f"unreachable {r['unreachable']}; fits not converged: {res['not_converged']}")
    for f in res.get("failed_runs", []):
        out.append(f"run with seed {f['seed']} left out: {f['reason']}")
    return "\n".join(out)


def _format_mismatch(res: dict) -> list[str]:
    """What the world's errors beyond the noise do to the comparison with the bound."""
    w = res["world"]
    mx = w["max_residual_mm"]
    out = ["", f"max model error after calibration (largest |residual| of a run): median "
               f"{mx['median']:.3f} mm ({mx['min']:.3f}-{mx['max']:.3f}); the real MC70 "
               f"(seed Table 9): 0.102-0.188 mm on sets of 30-257 samples"]
    if not w["model_mismatch"]:
        out.append("the world's only errors are the noise the bound describes: the spread "
                   "should meet the bound and the chi-square pass")
        return out
    offs = res["offsets"]
    emp = [res["params"][n]["ratio_emp_to_crb"] for n in offs]
    bias = [res["params"][n]["bias_over_crb"] for n in offs]
    c = res["chi2_offsets_reported"]
    out.append(
        "model mismatch: this world has errors the fit's model does not ("
        + ", ".join(SOURCES[f] for f in w["model_mismatch"]) + "). The fit's residual sigma "
        f"is {w['sigma_fit_over_model']:.1f}x the noise model's; the offsets absorb the rest. "
        f"Their spread over runs is {min(emp):.1f}-{max(emp):.1f}x the Cramer-Rao bound and "
        f"their bias {min(bias):.1f}-{max(bias):.1f}x it"
        + (f"; chi-square mean {c['mean']:.0f} for {c['dof']} dof" if c else "")
        + ". The bound and the reported std describe the noise only, not the mismatch: "
        "against the truth they are too small, as they are on a real robot.")
    return out


def format_slope(sl: dict) -> str:
    offs = list(sl["slopes"])
    unit = display(offs[0])[1] if offs else "urad"
    rows = []
    for r in sl["rows"]:
        row = [str(r["samples"])]
        for p in offs:
            k, _ = display(p)
            row.append(f"{r[p]['empirical_std'] * k:.3g} / {r[p]['crb_std'] * k:.3g}")
        rows.append(row)
    rows.append(["slope"] + [f"{sl['slopes'][p]['empirical']:+.3f} / {sl['slopes'][p]['crb']:+.3f}"
                             for p in offs])
    return (f"spread vs samples ({sl['runs_per_point']} runs per point), empirical / CRB [{unit}]; "
            f"expected slope -0.5\n" + table(["samples"] + offs, rows))
