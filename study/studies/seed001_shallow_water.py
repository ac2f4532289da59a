"""Seed 001 (Xu & Guedes Soares): Nomoto models in shallow water identified by the truncated LS-SVM against least
squares, LS-SVM and nu-SVR.

``build`` writes the study's figures and tables into ``paper_figs/seed001_shallow_water/`` and appends its claim (if any) to
``claims``; ``python -m study.figures`` finds this module by the study's name (``conf/experiment/seed001_shallow_water.yaml``)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..figures.plots import (
    ESTIMATOR_ORDER, NOISE_ORDER, _plt, _order, Builder, _hT, _first, fit_time_figure, lcurve_figure, _pct,
    _verdict,
)

NAME = "seed001_shallow_water"
SEED = "001"  # the seed paper whose claim it tests: a "not run" row in CLAIMS.md until it has run


def build(b: Builder, runs, params, claims):
    s = "seed001_shallow_water"
    r, p = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    plt = _plt()
    p = p.copy()
    p["hT"] = p["cfg_depth.h_T"].map(_hT)
    L = p["cfg_vessel.particulars.Lpp"].astype(float)
    U = p["cfg_vessel.operation.U0"].astype(float)
    nd = {"K": L / U, "T": U / L, "T1": U / L, "T2": U / L, "T3": U / L, "alpha": (U / L) ** 2}
    p["estimate_nd"] = np.nan
    p["truth_nd"] = np.nan
    for k, f in nd.items():
        m = p["name"] == k
        p.loc[m, "estimate_nd"] = p.loc[m, "estimate"] * f[m]
        p.loc[m, "truth_nd"] = p.loc[m, "truth"] * f[m]
    order = ["1.32", "1.46", "2.9", "5.6", "deep"]
    rows = []
    for model, names in (("nomoto1_nl", ["K", "T"]), ("nomoto2_nl", ["K", "T1", "T3"])):
        q = p[(p["cfg_model.name"] == model) & (p["cfg_vessel.name"] == "kcs")]
        if not len(q):
            continue
        speeds = sorted(q["cfg_vessel.operation.U0"].dropna().unique())
        noises = _order(q["cfg_noise.name"], NOISE_ORDER)
        fig, axes = plt.subplots(len(names), len(noises), figsize=(3.2 * len(noises), 2.5 * len(names)),
                                 squeeze=False, constrained_layout=True)
        for j, nz in enumerate(noises):
            for i, n in enumerate(names):
                ax = axes[i, j]
                for sp, ls_ in zip(speeds, ("-", "--")):
                    d = q[(q["name"] == n) & (q["cfg_noise.name"] == nz) & (q["cfg_vessel.operation.U0"] == sp)]
                    tru = d.groupby("hT")["truth_nd"].first().reindex(order)
                    ax.plot(range(len(order)), tru.to_numpy(float), "k" + ls_, lw=2, label=f"truth, U0 {sp:g}")
                    for e in _order(d["cfg_estimator.name"], ESTIMATOR_ORDER):
                        de = d[d["cfg_estimator.name"] == e].groupby("hT")["estimate_nd"].median().reindex(order)
                        ax.plot(range(len(order)), de.to_numpy(float), ls_, marker="o", ms=3, lw=0.8,
                                label=f"{e}, U0 {sp:g}")
                        for h in order:
                            rows.append({"model": model, "noise": nz, "U0": sp, "h/T": h, "parameter": n + "'",
                                         "estimator": e, "estimate": de.get(h), "truth": tru.get(h)})
                ax.set_xticks(range(len(order)), order)
                ax.set_title(f"{n}' ({model}), noise {nz}")
                if n == "K":
                    ax.set_yscale("symlog", linthresh=1.0)
                if j == 0:
                    ax.set_ylabel(f"{n}'")
                if i == len(names) - 1:
                    ax.set_xlabel("h/T")
        axes[0, -1].legend(fontsize=5, ncol=1, loc="best")
        b.figure(fig, s, f"KT_vs_hT_{model}", f"non-dimensional Nomoto parameters against h/T per estimator and "
                 f"speed ({model}; black: derived truth)")
    if rows:
        b.table(pd.DataFrame(rows), s, "KT_vs_hT", "median non-dimensional Nomoto parameters per h/T, estimator, "
                "speed and noise, with the derived truth")
    # drift against the noise level per estimator
    q = p[p["truth_kind"] == "derived"]
    if len(q):
        fig, axes = plt.subplots(1, 2, figsize=(8, 3))
        tab = []
        for ax, model in zip(axes, ("nomoto1_nl", "nomoto2_nl")):
            d = q[q["cfg_model.name"] == model]
            noises = _order(d["cfg_noise.name"], NOISE_ORDER)
            for e in _order(d["cfg_estimator.name"], ESTIMATOR_ORDER):
                med = d[d["cfg_estimator.name"] == e].groupby("cfg_noise.name")["abs_rel_error"].median().reindex(
                    noises)
                ax.plot(noises, med.to_numpy(float), marker="o", label=e)
                tab += [{"model": model, "estimator": e, "noise": nz, "median_abs_rel_error": med[nz]}
                        for nz in noises]
            ax.set_yscale("log")
            ax.set_title(f"{model}: median |relative error| of the Nomoto parameters")
            ax.set_xlabel("noise")
        axes[0].legend()
        b.figure(fig, s, "drift_vs_noise", "median drift of the Nomoto parameters against the noise level")
        b.table(pd.DataFrame(tab), s, "drift_vs_noise", "median drift of the Nomoto parameters against noise")
    # the L-curve of the truncated LS-SVM
    ent = []
    for nz in ("none", "medium"):
        run = _first(r, **{"cfg_estimator.name": "tlssvm", "cfg_model.name": "nomoto2_nl", "cfg_noise.name": nz,
                           "cfg_vessel.name": "kcs"})
        if run is not None:
            ent.append((f"KCS, nomoto2_nl, h/T {_hT(run['cfg_depth.h_T'])}, noise {nz}", run))
    lcurve_figure(b, s, ent)
    fit_time_figure(b, r, s)
    claims.append(claim(r, p))


def claim(r, p) -> dict:
    """Verdict on the exact KT truth (the Mariner as a Nomoto model): does truncation beat the others under noise,
    on each structure? The KCS (derived truth) numbers are given beside it: there the Nomoto model's own error
    dominates."""
    parts, wins, n = [], 0, 0
    for kind, label in (("exact", "exact KT Mariner"), ("derived", "KCS (derived truth)")):
        q = p[p["truth_kind"] == kind]
        med = q.groupby(["cfg_structure.name", "cfg_noise.name", "cfg_estimator.name"])["abs_rel_error"].median()
        for (st, nz), row in med.groupby(level=[0, 1]):
            row = row.droplevel([0, 1])
            others = row.drop("tlssvm", errors="ignore")
            if "tlssvm" not in row or not len(others):
                continue
            if kind == "exact" and nz != "none":
                n += 1
                wins += row["tlssvm"] < others.min()
            parts.append(f"{label}, {st}, noise {nz}: tlssvm {_pct(row['tlssvm'])}, " +
                         ", ".join(f"{e} {_pct(v)}" for e, v in others.items()))
    shallow = ""
    k = p[(p["name"] == "K") & (p["cfg_model.name"] == "nomoto1_nl") & (p["cfg_vessel.name"] == "kcs")]
    if "truth_nd" in k and len(k):
        kt = k.groupby(k["cfg_depth.h_T"].map(_hT))["truth_nd"].first()
        if "deep" in kt and "1.32" in kt:
            shallow = (f" Shallow water (KCS, derived truth): K' falls from {kt['deep']:.3g} in deep water to "
                       f"{kt['1.32']:.3g} at h/T 1.32.")
    return {"seed": "001 (Xu & Guedes Soares)", "claim": "the truncated LS-SVM improves the estimates under noise "
            "against least squares, LS-SVM and nu-SVR; shallow water changes K and T strongly",
            "study": "seed001_shallow_water", "verdict": _verdict(wins / n) if n else "not run",
            "numbers": "median |relative error| of the Nomoto parameters: " + "; ".join(parts) + "." + shallow}
