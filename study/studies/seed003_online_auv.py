"""Seed 003 (Du et al. 2016): the incremental LS-SVM on an AUV's integral samples, and how fast its derivatives
settle.

``build`` writes the study's figures and tables into ``paper_figs/seed003_online_auv/`` and appends its claim (if any) to
``claims``; ``python -m study.figures`` finds this module by the study's name (``conf/experiment/seed003_online_auv.yaml``)."""
from __future__ import annotations

import numpy as np

from ..figures.plots import (
    STRUCTURE_ORDER, NOISE_ORDER, _order, Builder, _first, drift_heatmaps, fit_time_figure,
    collinearity_tables, convergence_figure, _pct, _verdict,
)

NAME = "seed003_online_auv"
SEED = "003"  # the seed paper whose claim it tests: a "not run" row in CLAIMS.md until it has run


def build(b: Builder, runs, params, claims):
    s = "seed003_online_auv"
    r, p = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    for noise in _order(r["cfg_noise.name"], NOISE_ORDER):
        drift_heatmaps(b, r, p, s, "auv", noise, f"drift_heatmap_{noise}")
    # online convergence against the number of samples (Figures 3-8)
    for st in _order(r["cfg_structure.name"], STRUCTURE_ORDER):
        for nz in _order(r["cfg_noise.name"], NOISE_ORDER):
            run = _first(r, **{"cfg_estimator.name": "lssvm_online", "cfg_structure.name": st, "cfg_noise.name": nz})
            if run is not None:
                convergence_figure(b, s, run, p, f"online_convergence_{st}_{nz}", f"{st} samples, noise {nz}; "
                                   "seed 003 Figs. 3-8")
    # difference (central) against integral
    d = p[p["truth_kind"] == "exact"]
    tab = d.pivot_table(index=["cfg_estimator.name", "cfg_noise.name"], columns="cfg_structure.name",
                        values="abs_rel_error", aggfunc="median").reset_index()
    if len(tab):
        tab.columns.name = None
        b.table(tab.rename(columns={"cfg_estimator.name": "estimator", "cfg_noise.name": "noise"}), s,
                "difference_vs_integral", "median |relative error| of the 17 derivatives: central differences against "
                "integral samples, per estimator and noise")
    collinearity_tables(b, r, s)
    fit_time_figure(b, r, s)
    claims.append(claim(r, p))


def claim(r, p) -> dict:
    on = r[r["cfg_estimator.name"] == "lssvm_online"]
    parts, ok, n = [], 0, 0
    for _, row in on.sort_values(["cfg_structure.name", "cfg_noise.sample_dt", "cfg_noise.name"]).iterrows():
        nc = [row.get(f"m_est_{e}_n_converged") for e in ("X", "Y", "N")]
        nc = [x for x in nc if x is not None and np.isfinite(x)]
        if not nc:
            continue
        d = p[(p["run_id"] == row["run_id"]) & (p["truth_kind"] == "exact")]["abs_rel_error"].median()
        n += 1
        ok += max(nc) <= 30 and d < 0.1
        parts.append(f"{row['cfg_structure.name']}, sampled at {row['cfg_noise.sample_dt']:g} s, noise "
                     f"{row['cfg_noise.name']}: every coefficient within 5 % of its final value after {int(max(nc))} "
                     f"samples, median drift of the final values {_pct(d)}")
    return {"seed": "003 (Du et al. 2016)", "claim": "with integral samples the incremental LS-SVM's derivatives all "
            "converge to the captive-test values after about 20 samples", "study": "seed003_online_auv",
            "verdict": _verdict(ok / n) if n else "not run", "numbers": "; ".join(parts) + "."}
