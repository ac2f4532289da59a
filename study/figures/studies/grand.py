"""The grand cross: every estimator and structure over vessels, noise levels and depths; does drift grow with noise?

``build`` writes the study's figures and tables into ``paper_figs/grand/`` and appends its claim (if any) to
``claims``; ``python -m study.figures`` finds this module by the study's name (``conf/experiment/grand.yaml``)."""
from __future__ import annotations

import pandas as pd

from ..plots import (
    ESTIMATOR_ORDER, STRUCTURE_ORDER, NOISE_ORDER, PRINT_WIDTH_IN, _plt, _order, _wrap, Builder, _hT,
    estimator_style, fit_time_figure, collinearity_tables, log_ticks, sampling_label, _pct, _verdict,
)

NAME = "grand"
SEED = None  # no seed paper's claim


def build(b: Builder, runs, params, claims, s="grand"):
    r, p = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    plt = _plt()
    p = p[p["truth_kind"] == "exact"].copy()
    p["hT"] = p["cfg_depth.h_T"].map(_hT)
    tabs = {}
    sub = sampling_label(p)
    for axis, col, order in (("noise", "cfg_noise.name", NOISE_ORDER), ("hT", "hT", ["deep", "5.6", "2.9", "1.46",
                                                                                     "1.32"])):
        vals = _order(p[col], order)
        if len(vals) < 2:
            continue
        structs = _order(p["cfg_structure.name"], STRUCTURE_ORDER)
        fig, axes = plt.subplots(1, len(structs), figsize=(PRINT_WIDTH_IN, 3.6), sharey=True, squeeze=False,
                                 layout="constrained")
        rows = []
        for ax, st in zip(axes[0], structs):
            d = p[p["cfg_structure.name"] == st]
            for e in _order(d["cfg_estimator.name"], ESTIMATOR_ORDER):
                med = d[d["cfg_estimator.name"] == e].groupby(col)["abs_rel_error"].median().reindex(vals)
                ax.plot(vals, med.to_numpy(float), lw=1.0, ms=5, label=e, **estimator_style(e))
                rows += [{"structure": st, "estimator": e, axis: v, "median_abs_rel_error": med[v]} for v in vals]
            ax.set_yscale("log")
            ax.set_title(f"{st} samples")
            ax.set_xlabel("noise level" if axis == "noise" else "h/T [-]")
        log_ticks(axes[0, 0])
        axes[0, 0].set_ylabel("median |relative error| [-]")
        handles = {}
        for ax in axes[0]:
            for h, lab in zip(*ax.get_legend_handles_labels()):
                handles.setdefault(lab, h)
        ests = _order(list(handles), ESTIMATOR_ORDER)
        fig.legend([handles[e] for e in ests], ests, loc="outside lower center", ncol=min(len(ests), 6),
                   title="estimator")
        pooled = "vessels and depths" if axis == "noise" else "vessels and noise levels"
        fig.suptitle(_wrap(f"Median |relative error| of the exact coefficients against the "
                           f"{'noise level' if axis == 'noise' else 'water depth h/T'} (pooled over {pooled}; "
                           f"{sub or 'each vessel at its default sampling interval'})"))
        b.figure(fig, s, f"drift_vs_{axis}", f"median parameter drift against the {axis} per estimator and structure "
                 "(all vessels)")
        tabs[axis] = pd.DataFrame(rows)
        b.table(tabs[axis], s, f"drift_vs_{axis}", f"median parameter drift against the {axis}")
    piv = p.pivot_table(index=["cfg_structure.name", "cfg_estimator.name"], columns="cfg_vessel.name",
                        values="abs_rel_error", aggfunc="median").reset_index()
    if len(piv):
        piv.columns.name = None
        b.table(piv, s, "drift_by_vessel", "median |relative error| per structure, estimator and vessel")
    collinearity_tables(b, r, s, group=("cfg_vessel.name", "cfg_structure.name", "cfg_noise.name"))
    fit_time_figure(b, r, s)
    claims.append(claim(tabs))


def claim(tabs: dict) -> dict:
    t = tabs.get("noise")
    if t is None or not len(t):
        return {"seed": "(all)", "claim": "drift grows with noise for every estimator", "study": "grand",
                "rule": "share", "verdict": "not run", "numbers": ""}
    g = t.pivot_table(index=["structure", "estimator"], columns="noise", values="median_abs_rel_error")
    cols = [c for c in NOISE_ORDER if c in g.columns]
    grows = int((g[cols[-1]] > g[cols[0]]).sum()) if len(cols) >= 2 else 0
    best = t[t["noise"] == cols[-1]].sort_values("median_abs_rel_error").iloc[0]
    return {"seed": "(all)", "claim": "parameter drift grows with the noise level for every estimator and structure",
            "study": "grand", "rule": "share", "verdict": _verdict(grows / len(g)) if len(g) else "not run",
            "numbers": f"drift larger at noise {cols[-1]} than at {cols[0]} in {grows} of {len(g)} estimator x "
                       f"structure pairs; lowest median drift at noise {cols[-1]}: {best['estimator']} on "
                       f"{best['structure']} ({_pct(best['median_abs_rel_error'])})."}
