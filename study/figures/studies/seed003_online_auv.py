"""Du et al. (2016): the incremental LS-SVM on an AUV's integral samples, and how fast its derivatives
settle.

``build`` writes the study's figures and tables into ``paper_figs/seed003_online_auv/`` and appends its claim (if any) to
``claims``; ``python -m study.figures`` finds this module by the study's name (``conf/experiment/seed003_online_auv.yaml``)."""
from __future__ import annotations

import numpy as np

import pandas as pd

from ..plots import (
    STRUCTURE_ORDER, NOISE_ORDER, _order, Builder, _first, at_sampling, drift_heatmaps, fit_time_figure,
    collinearity_tables, convergence_figure, sampling_label,
)

NAME = "seed003_online_auv"
SEED = "003"  # the seed paper whose claim it tests: a "not run" row in CLAIMS.md until it has run


def build(b: Builder, runs, params, claims):
    s = "seed003_online_auv"
    r_all, p_all = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    # the figures at the seed's sampling interval scaled to this AUV (the coarser of the two swept); the claim
    # and its table weigh the other
    r, p = at_sampling(r_all, "coarsest"), at_sampling(p_all, "coarsest")
    dt = r["m_sample_dt"].dropna().iloc[0] if "m_sample_dt" in r and r["m_sample_dt"].notna().any() else None
    at = f", sampled at {dt:g} s" if dt else ""  # the tables' captions, as before
    sub = sampling_label(r)
    for noise in _order(r["cfg_noise.name"], NOISE_ORDER):
        drift_heatmaps(b, r, p, s, "auv", noise, f"drift_heatmap_{noise}")
    # online convergence against the number of samples (Figures 3-8)
    for st in _order(r["cfg_structure.name"], STRUCTURE_ORDER):
        for nz in _order(r["cfg_noise.name"], NOISE_ORDER):
            run = _first(r, **{"cfg_estimator.name": "lssvm_online", "cfg_structure.name": st, "cfg_noise.name": nz})
            if run is not None:
                convergence_figure(b, s, run, p, f"online_convergence_{st}_{nz}", f"{st} samples, noise {nz}{at}; "
                                   "Du et al. 2016 Figs. 3-8", title=f"auv, {st} samples, noise {nz}, {sub}, the seed's "
                                   "interval scaled to this AUV; Du et al. 2016 Figs. 3-8")
    # difference (central) against integral
    d = p[p["truth_kind"] == "exact"]
    tab = d.pivot_table(index=["cfg_estimator.name", "cfg_noise.name"], columns="cfg_structure.name",
                        values="abs_rel_error", aggfunc="median").reset_index()
    if len(tab):
        tab.columns.name = None
        b.table(tab.rename(columns={"cfg_estimator.name": "estimator", "cfg_noise.name": "noise"}), s,
                "difference_vs_integral", "median |relative error| of the 17 derivatives: central differences against "
                f"integral samples, per estimator and noise{at}")
    collinearity_tables(b, r, s)
    fit_time_figure(b, r, s)
    claims.extend(claim(b, r_all, p_all))


#: the truth-based band: within 10 % of the truth, or (whichever is wider) an error that moves its equation by
#: less than 2 % of the equation's own size (term_scale; the only band a zero truth can have)
REL_BAND, SCALED_BAND = 0.10, 0.02
#: the seed's "about 20 samples", with half again as margin
SEED_SAMPLES = 30


def settling(b: Builder, run, params) -> pd.DataFrame | None:
    """Per coefficient of an incremental LS-SVM run: the number of samples after which it stays inside its
    truth-based band (NaN: never), from the run's convergence history; and after which it stays within 5 % of its
    own final value (the criterion the estimator reports)."""
    pr = params[params["run_id"] == run["run_id"]].set_index("name")
    rows = []
    for eq in ("X", "Y", "N"):
        cv = b.artefact_csv(run["run_id"], f"{eq}/convergence.csv")
        if cv is None:
            continue
        n = cv.iloc[:, 0].to_numpy(float)
        for c in cv.columns[1:]:
            if c not in pr.index or c == "intercept":
                continue
            x = cv[c].to_numpy(float)
            t, ts = float(pr.at[c, "truth"]), float(pr.at[c, "term_scale"]) if "term_scale" in pr else np.nan
            band = max(REL_BAND * abs(t), SCALED_BAND / ts if np.isfinite(ts) and ts > 0 else 0.0)
            out_t = np.abs(x - t) > band
            out_f = np.abs(x - x[-1]) > 0.05 * abs(x[-1])
            last_t = np.flatnonzero(out_t)
            last_f = np.flatnonzero(out_f)
            rows.append({"equation": eq, "name": c, "truth": t,
                         "settled_truth_band": np.nan if band == 0 or (len(last_t) and last_t[-1] == len(n) - 1)
                         else float(n[last_t[-1] + 1] if len(last_t) else n[0]),
                         "settled_own_final_5pct": float(n[last_f[-1] + 1] if len(last_f) else n[0])})
    return pd.DataFrame(rows) if rows else None


def claim(b: Builder, r, p) -> list:
    """Du et al. (2016): the incremental LS-SVM on integral samples, every derivative settled after about 20 samples.
    Decided per run, on a band around the truth (the seed compares with the captive-test values), at the seed's
    sampling interval scaled to this AUV's time scale; the estimator's own criterion (within 5 % of its own final
    value, which a zero truth meets only at the last sample) and the other intervals and structures are the
    sensitivity table."""
    on = r[r["cfg_estimator.name"] == "lssvm_online"]
    rows = []
    for _, run in on.iterrows():
        st = settling(b, run, p)
        if st is None or not len(st):
            continue
        for crit, col in (("truth band", "settled_truth_band"), ("own final value, 5 %", "settled_own_final_5pct")):
            v = st[col]
            rows.append({"structure": run["cfg_structure.name"], "noise": run["cfg_noise.name"],
                         "sample_dt_LU": run.get("m_sample_dt_LU", np.nan), "sample_dt": run.get("m_sample_dt", np.nan),
                         "criterion": crit, "coefficients": len(v), "median_samples": float(v.median()),
                         "largest_samples": float(v.max()), "never_settled": int(v.isna().sum()),
                         "never": ", ".join(st.loc[v.isna(), "name"]),
                         "all_within_seed": bool(v.notna().all() and v.max() <= SEED_SAMPLES)})
    if not rows:
        return []
    t = pd.DataFrame(rows).sort_values(["criterion", "structure", "sample_dt_LU", "noise"], ascending=[False, True,
                                                                                                  False, True])
    b.table(t, NAME, "claim_settling", f"Du et al. 2016: samples after which each coefficient stays settled (median, "
            f"largest, never) per run; truth band: within {REL_BAND:.0%} of the truth or an error below "
            f"{SCALED_BAND:.0%} of its equation; the seed: 'about 20' (counted as at most {SEED_SAMPLES})",
            floatfmt=".3g")
    dts = sorted(t["sample_dt_LU"].dropna().unique())
    seed_dt = max(dts) if dts else np.nan  # the seed's interval, scaled (the coarser of the two swept)
    # primary: the seed's set-up -- integral samples of a clean simulation at its interval (scaled), truth band
    is_prim = ((t["criterion"] == "truth band") & (t["structure"] == "integral") & (t["noise"] == "none")
               & ((t["sample_dt_LU"] == seed_dt) if dts else True))
    prim = t[is_prim]
    ok = bool(len(prim)) and bool(prim["all_within_seed"].all())
    verdict = "holds" if ok else "does not hold"
    dissent = [f"{x.criterion}, {x.structure}, {x.sample_dt_LU:.3g} L/U0, noise {x.noise}"
               for x in t[~is_prim].itertuples() if x.all_within_seed != ok]
    if dissent:
        verdict += f"; depends on the choice: {'does not hold' if ok else 'holds'} with " + "; ".join(dissent)
    nums = "; ".join(f"noise {x.noise}: median {x.median_samples:g} samples, largest {x.largest_samples:g}, "
                     f"{x.never_settled} of {x.coefficients} never settle" + (f" ({x.never})" if x.never else "")
                     for x in prim.itertuples())
    return [{"seed": "003 (Du et al. 2016)", "study": NAME,
             "claim": "with integral samples the incremental LS-SVM's derivatives all converge to the captive-test "
                      "values after about 20 samples",
             "verdict": verdict,
             "numbers": f"integral samples of a clean simulation at the seed's interval scaled to this AUV "
                        f"({seed_dt:.3g} L/U0), band around the truth: {nums}. Every run (both structures, both "
                        f"intervals, noise none and low, both criteria) is in table claim_settling."}]
