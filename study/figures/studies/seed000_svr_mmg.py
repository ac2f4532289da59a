"""Song et al. (2025): SVR identification of a simplified MMG model; differenced and centred samples
against forward differences, and Lasso's term selection.

``build`` writes the study's figures and tables into ``paper_figs/seed000_svr_mmg/`` and appends
its claim (if any) to ``claims``; ``python -m study figures`` finds this module by the study's
name (``conf/experiment/seed000_svr_mmg.yaml``)."""
from __future__ import annotations

import pandas as pd
from scipy import stats

from ..plots import (
    EQ_ORDER, STRUCTURE_ORDER, NOISE_ORDER, _order, Builder, _first, drift_heatmaps, fit_time_figure,
    collinearity_tables, vif_table, correlation_figure, validation_figure, rmse_cc_table, finest, sampling_label,
    structure_style,
)
from ..verdicts import dataset_sensitivity, dataset_verdict, summary, tidy_sensitivity

NAME = "seed000_svr_mmg"
SEED = "000"  # the seed paper whose claim it tests: a "not run" row in CLAIMS.md until it has run
#: where the study's set-up departs from the paper's, and why
DEPARTURES = ("Song et al. identify from one simulated 2100 s zigzag sequence sampled at 0.1 s, with noise they do not "
              "state; here the same sequence, noise-free (one dataset) and with 1 % of each channel's RMS (20 datasets), "
              "also sampled five times coarser (0.5 s) to separate the sampling from the method; the USV's published "
              "coefficients stand in for the paper's vessel.")


def build(b: Builder, runs, params, claims):
    s = "seed000_svr_mmg"
    r_all, p_all = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    # the figures and tables at the seed's own sampling interval (the finest swept); the claim weighs the others
    r, p = finest(r_all)[0], finest(p_all)[0]
    for noise in _order(r["cfg_noise.name"], NOISE_ORDER):
        drift_heatmaps(b, r, p, s, "mmg_simplified", noise, f"drift_heatmap_{noise}")
    # Table 2: truth, 'original' (SVR, euler) and 'improved' (SVR, diff_center)
    t2 = []
    for noise in _order(r["cfg_noise.name"], NOISE_ORDER):
        q = p[(p["cfg_model.name"] == "mmg_simplified") & (p["cfg_estimator.name"] == "svr_eps")
              & (p["cfg_noise.name"] == noise)]
        if not len(q):
            continue
        piv = q.pivot_table(index=["equation", "name"], columns="cfg_structure.name", values="estimate",
                            aggfunc="median")
        tru = q.groupby(["equation", "name"])["truth"].first()
        for (eq, n) in sorted(piv.index, key=lambda k: (EQ_ORDER.get(k[0], 3), k[1])):
            t2.append({"noise": noise, "equation": eq, "coefficient": n, "truth (CFD)": tru[(eq, n)],
                       **{f"{st}": piv.loc[(eq, n), st] for st in _order(piv.columns, STRUCTURE_ORDER)}})
    if t2:
        b.table(pd.DataFrame(t2), s, "table2_svr_original_vs_improved", "Song et al. 2025 Table 2: the truth against "
                "epsilon-SVR on forward differences ('original', euler), differenced and centred ('improved', "
                "diff_center) and the other structures")
    collinearity_tables(b, r, s)
    vif_table(b, p, s)
    run = _first(r, **{"cfg_model.name": "mmg_simplified", "cfg_estimator.name": "svr_eps",
                       "cfg_structure.name": "euler", "cfg_noise.name": "none"})
    if run is not None:
        correlation_figure(b, r, s, run, f"mmg_simplified, euler rows, noise-free, {sampling_label(r)}")
    rmse_cc_table(b, r[r["cfg_model.name"] == "mmg_simplified"], s,
                  ("cfg_estimator.name", "cfg_structure.name", "cfg_noise.name"),
                  ("zigzag_20_20", "zigzag_35_35", "turning_35"))
    fit_time_figure(b, r, s)
    # Figures 4, 7, 9: predictions by the SVR models against the truth
    for nz in _order(r["cfg_noise.name"], NOISE_ORDER):
        ent = []
        for st, lab in (("euler", "SVR, original (euler)"), ("diff_center", "SVR, improved (diff_center)"),
                        ("central", "SVR, central")):
            run = _first(r, **{"cfg_model.name": "mmg_simplified", "cfg_estimator.name": "svr_eps",
                               "cfg_structure.name": st, "cfg_noise.name": nz})
            if run is not None:
                ent.append((lab, run["run_id"], structure_style(st)))
        for m, fig_no in (("zigzag_20_20", 4), ("zigzag_35_35", 7), ("turning_35", 9)):
            validation_figure(b, s, ent, m, f"validation_{m}_{nz}", f"Song et al. 2025 Fig. {fig_no}: {m} predicted by the "
                              f"SVR models identified at noise {nz} against the truth",
                              setup=f"mmg_simplified by epsilon-SVR, noise {nz}, {sampling_label(r)}")
    # Lasso term selection on the full model (Song et al. 2025 Sec. 2.3)
    las = p[(p["cfg_model.name"] == "usv_full") & (p["cfg_estimator.name"] == "lasso")]
    if len(las):
        sel = las.pivot_table(index=["equation", "name"], columns=["cfg_structure.name", "cfg_noise.name"],
                              values="selected", aggfunc="mean")
        sel.columns = [f"{a} / {bb}" for a, bb in sel.columns]
        sel = sel.reset_index()
        sel["o"] = sel["equation"].map(EQ_ORDER)
        sel = sel.sort_values(["o", "name"]).drop(columns="o")
        b.table(sel, s, "lasso_selection", "Lasso (10-fold CV) on the full model: 1 = term kept, 0 = dropped (Song et al. 2025 "
                "drops N'vrr, N'vvr)")
    claims.extend(claim(b, r_all, p_all))


#: what names a dataset (with the replicate): the same records, built into rows both ways
KEYS = ["cfg_model.name", "cfg_estimator.name", "cfg_noise.name", "cfg_seed", "m_sample_dt_LU"]
CLAIM = ("differencing and centring the samples (diff_center) reduces the parameter drift of epsilon-SVR "
         "identification against forward differences (euler), simplified MMG model")


def _subsets(q: pd.DataFrame, runs: pd.DataFrame) -> list:
    """The claim's other choices: each noise level (noise-free: one dataset), the coarser
    sampling interval."""
    own, other_dts = finest(q)
    ro = finest(runs)[0]
    out = [(f"noise {nz} only" + (" (one dataset: nothing drawn at random)" if nz == "none" else ""),
            own[own["cfg_noise.name"] == nz], ro[ro["cfg_noise.name"] == nz])
           for nz in _order(own["cfg_noise.name"], NOISE_ORDER)]
    for dt in other_dts:
        sec = q.loc[q["m_sample_dt_LU"] == dt, "m_sample_dt"].iloc[0]
        out.append((f"sampled at {dt:.3g} L/U0 ({sec:g} s), noisy datasets",
                    q[(q["m_sample_dt_LU"] == dt) & (q["cfg_noise.name"] != "none")],
                    runs[(runs["m_sample_dt_LU"] == dt) & (runs["cfg_noise.name"] != "none")]))
    return out


def claim(b: Builder, r, p) -> list:
    """Song et al.'s (2025) compound claim split in three, each decided over datasets
    (study/figures/verdicts.py): SVR on differenced and centred rows against forward differences,
    on the seed's simplified model, noisy datasets at the seed's 0.1 s (the full model, the
    noise-free dataset, the coarser interval and the scoring choices are the sensitivity table);
    the same for every other estimator, one verdict each; Lasso dropping N'vrr and N'vvr, per
    dataset of a set-up."""
    runs_all = b.all_runs if b.all_runs is not None else r
    runs_all = runs_all[runs_all["cfg_structure.name"].isin(["euler", "diff_center"])]
    q = p[p["truth_kind"].isin(["exact", "approximate"]) & (p["truth"] != 0)
          & p["cfg_structure.name"].isin(["euler", "diff_center"])]

    def sel(df, model, est):
        return df[(df["cfg_model.name"] == model) & (df["cfg_estimator.name"] == est)]

    def noisy(df):
        return finest(df)[0].pipe(lambda x: x[x["cfg_noise.name"] != "none"])

    out, tabs = [], []
    svr, rsvr = sel(q, "mmg_simplified", "svr_eps"), sel(runs_all, "mmg_simplified", "svr_eps")
    if len(svr):
        subsets = _subsets(svr, rsvr)
        full, rfull = sel(q, "usv_full", "svr_eps"), sel(runs_all, "usv_full", "svr_eps")
        if len(full):
            subsets.append(("the full model (usv_full) instead, noisy datasets", noisy(full), noisy(rfull)))
        t = dataset_sensitivity(CLAIM, "svr_eps, mmg_simplified", noisy(svr), noisy(rsvr), "cfg_structure.name",
                                "diff_center", "euler", KEYS, subsets)
        tabs.append(t)
        v, line = dataset_verdict(t)
        out.append({"seed": "000 (Song et al. 2025)", "study": NAME, "claim": CLAIM, "verdict": v,
                    "numbers": f"noisy datasets at the seed's 0.1 s: {line}."})
    per_est = {}
    for e in _order(q["cfg_estimator.name"], []):
        d, rd = sel(q, "mmg_simplified", e), sel(runs_all, "mmg_simplified", e)
        t = dataset_sensitivity("the same for every estimator", f"{e}, mmg_simplified", noisy(d), noisy(rd),
                                "cfg_structure.name", "diff_center", "euler", KEYS, _subsets(d, rd))
        tabs.append(t)
        per_est[e] = dataset_verdict(t)
    if tabs:
        b.table(tidy_sensitivity(pd.concat(tabs, ignore_index=True)), NAME, "claim_sensitivity",
                "Song et al. 2025: diff_center against euler rows, per estimator, the dataset as the unit (sign test; "
                "wins are datasets where diff_center's median error is lower by more than 5 %), under each choice",
                floatfmt=".3g")
    if per_est:
        out.append({"seed": "000 (Song et al. 2025)", "study": NAME,
                    "claim": "the same for every estimator (each decided on its own datasets, at the seed's 0.1 s)",
                    "verdict": summary({e: v for e, (v, _) in per_est.items()}, "estimators"),
                    "numbers": "; ".join(f"{e}: {line}" for e, (_, line) in per_est.items()) + "."})
    out.extend(_lasso_claim(b, p))
    return out


def _lasso_claim(b: Builder, p) -> list:
    """Lasso drops N'vrr and N'vvr: a property of each dataset (both dropped or not), decided
    over the datasets of a set-up (the structures of one dataset are the same records, not more
    evidence); primary: diff_center rows (the seed's improved samples), noisy, the seed's 0.1 s."""
    las = p[(p["cfg_model.name"] == "usv_full") & (p["cfg_estimator.name"] == "lasso") & p["name"].isin(["Nvrr", "Nvvr"])]
    if not len(las) or not las["selected"].notna().any():
        return []
    per_run = (las.groupby(["cfg_structure.name", "cfg_noise.name", "m_sample_dt_LU", "run_id"])["selected"]
               .apply(lambda s: bool((s == 0).all())).reset_index(name="both_dropped"))
    rows = []
    for (st, nz, dt), g in per_run.groupby(["cfg_structure.name", "cfg_noise.name", "m_sample_dt_LU"]):
        k, n = int(g["both_dropped"].sum()), len(g)
        lo, hi = stats.binomtest(k, n).proportion_ci(0.95, method="wilson")
        pv = stats.binomtest(k, n, 0.5, alternative="greater").pvalue
        pr = stats.binomtest(n - k, n, 0.5, alternative="greater").pvalue
        v = ("holds" if k else "does not hold") if n == 1 else (
            "holds" if pv < 0.05 else ("does not hold" if pr < 0.05 else "cannot tell"))
        rows.append({"structure": st, "noise": nz, "sample_dt_LU": dt, "datasets": n, "both_dropped": k,
                     "share": k / n, "share_low": lo, "share_high": hi, "verdict": v})
    lt = pd.DataFrame(rows)
    b.table(lt, NAME, "lasso_dropped", "Song et al. 2025: datasets in which Lasso (10-fold CV) drops both N'vrr and "
            "N'vvr from the full model, per set-up, with the Wilson 95 % interval and the verdict (binomial test "
            "against one half; one dataset where nothing is drawn at random)", floatfmt=".3g")
    fine = lt["sample_dt_LU"].min()
    prim = lt[(lt["structure"] == "diff_center") & (lt["noise"] != "none") & (lt["sample_dt_LU"] == fine)]
    prim = prim.iloc[0] if len(prim) else lt.iloc[0]
    off = lt[lt["verdict"] != prim["verdict"]]
    verdict = prim["verdict"] + ("; depends on the choice: " + ", ".join(
        f"{x.verdict} with {x.structure}, noise {x.noise}, {x.sample_dt_LU:.3g} L/U0" for x in off.itertuples())
        if len(off) else "")
    return [{"seed": "000 (Song et al. 2025)", "study": NAME,
             "claim": "Lasso (10-fold CV) drops N'vrr and N'vvr from the full model", "verdict": verdict,
             "numbers": f"{prim['structure']} rows, noise {prim['noise']}, the seed's 0.1 s: both dropped in "
                        f"{int(prim['both_dropped'])} of {int(prim['datasets'])} datasets ({100 * prim['share']:.0f} %, "
                        f"Wilson 95 % {100 * prim['share_low']:.0f}-{100 * prim['share_high']:.0f} %); every set-up in "
                        f"table lasso_dropped."}]
