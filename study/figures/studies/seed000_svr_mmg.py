"""Song et al. (2025): SVR identification of a simplified MMG model; differenced and centred samples against
forward differences, and Lasso's term selection.

``build`` writes the study's figures and tables into ``paper_figs/seed000_svr_mmg/`` and appends its claim (if any) to
``claims``; ``python -m study.figures`` finds this module by the study's name (``conf/experiment/seed000_svr_mmg.yaml``)."""
from __future__ import annotations

import pandas as pd
from scipy import stats

from ..plots import (
    EQ_ORDER, STRUCTURE_ORDER, NOISE_ORDER, _order, Builder, _first, drift_heatmaps, fit_time_figure,
    collinearity_tables, vif_table, correlation_figure, validation_figure, rmse_cc_table, finest, sampling_label,
    structure_style,
)
from ..verdicts import compare, explain, sensitivity, settle, summary

NAME = "seed000_svr_mmg"
SEED = "000"  # the seed paper whose claim it tests: a "not run" row in CLAIMS.md until it has run


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


def _alternatives(q: pd.DataFrame) -> list:
    """(label, rows, metric, unit) of the claim's sensitivity table; the first is the primary choice (the seed's
    own metric, each coefficient's relative error, at the seed's own sampling interval)."""
    own, other_dts = finest(q)
    out = [("relative error, per coefficient (the seed's Table 2)", own, "abs_rel_error", "coefficient"),
           ("relative error, median per equation", own, "abs_rel_error", "equation"),
           ("scaled error, median per equation", own, "scaled_error", "equation")]
    for nz in _order(own["cfg_noise.name"], NOISE_ORDER):
        out.append((f"noise {nz} only", own[own["cfg_noise.name"] == nz], "abs_rel_error", "coefficient"))
    for dt in other_dts:
        sec = q.loc[q["m_sample_dt_LU"] == dt, "m_sample_dt"].iloc[0]
        out.append((f"sampled at {dt:.3g} L/U0 ({sec:g} s)", q[q["m_sample_dt_LU"] == dt], "abs_rel_error",
                    "coefficient"))
    return out


def claim(b: Builder, r, p) -> list:
    """Song et al.'s (2025) compound claim split in three, each decided by paired comparisons (study/figures/verdicts.py):
    SVR on differenced and centred rows against forward differences, on the seed's simplified model; the same for
    every other estimator, one verdict each; Lasso dropping N'vrr and N'vvr."""
    keys = ["cfg_model.name", "cfg_estimator.name", "cfg_noise.name", "cfg_seed", "m_sample_dt_LU"]
    q = p[p["truth_kind"].isin(["exact", "approximate"]) & (p["truth"] != 0)
          & p["cfg_structure.name"].isin(["euler", "diff_center"])]
    svr = q[(q["cfg_model.name"] == "mmg_simplified") & (q["cfg_estimator.name"] == "svr_eps")]
    tab = sensitivity(svr, "cfg_structure.name", "diff_center", "euler", keys, _alternatives(svr))
    full = finest(q[(q["cfg_model.name"] == "usv_full") & (q["cfg_estimator.name"] == "svr_eps")])[0]
    if len(full):
        tab = pd.concat([tab, sensitivity(full, "cfg_structure.name", "diff_center", "euler", keys, [
            ("the full model (usv_full) instead", full, "abs_rel_error", "coefficient")]).assign(
            choice="the full model (usv_full) instead")], ignore_index=True)
    out = []
    if len(tab):
        b.table(tab.drop(columns=["choice"]).rename(columns={"what": "choice"}), NAME, "claim_sensitivity",
                "Song et al. 2025: SVR on diff_center against euler rows, paired per coefficient, under each choice (sign "
                "test; wins are pairs where diff_center's error is lower by more than 5 %)", floatfmt=".3g")
        out.append({"seed": "000 (Song et al. 2025)", "study": NAME,
                    "claim": "differencing and centring the samples (diff_center) reduces the parameter drift of "
                             "epsilon-SVR identification against forward differences (euler), simplified MMG model",
                    "verdict": settle(tab), "numbers": "relative error per coefficient at the seed's 0.1 s, paired "
                    "over noise levels: " + explain(tab) + "."})
    per_est = {}
    for e in _order(q["cfg_estimator.name"], []):
        d = finest(q[(q["cfg_model.name"] == "mmg_simplified") & (q["cfg_estimator.name"] == e)])[0]
        per_est[e] = compare(d, "cfg_structure.name", "diff_center", "euler", keys, "abs_rel_error")["verdict"]
    if per_est:
        out.append({"seed": "000 (Song et al. 2025)", "study": NAME,
                    "claim": "the same for every estimator (each decided on its own pairs, at the seed's 0.1 s)",
                    "verdict": summary(per_est, "estimators"),
                    "numbers": "paired per coefficient over noise levels; " + ", ".join(
                        f"{e}: {v}" for e, v in per_est.items()) + "."})
    las = p[(p["cfg_model.name"] == "usv_full") & (p["cfg_estimator.name"] == "lasso") & p["name"].isin(["Nvrr", "Nvvr"])]
    if len(las) and las["selected"].notna().any():
        dropped = int((las["selected"] == 0).sum())
        n = int(las["selected"].notna().sum())
        pv = stats.binomtest(dropped, n, 0.5, alternative="greater").pvalue
        pr = stats.binomtest(n - dropped, n, 0.5, alternative="greater").pvalue
        v = "holds" if pv < 0.05 else ("does not hold" if pr < 0.05 else "cannot tell")
        out.append({"seed": "000 (Song et al. 2025)", "study": NAME,
                    "claim": "Lasso (10-fold CV) drops N'vrr and N'vvr from the full model",
                    "verdict": v, "numbers": f"dropped in {dropped} of {n} fits (each term of each Lasso run; sign "
                    f"test p = {pv:.2g})."})
    return out
