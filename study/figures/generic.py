"""Figures for any sweep: what ``python -m study figures`` builds from runs that no named study
claims.

A sweep of one's own (``python -m study -m structure=euler,central estimator=ls,ridge ...``) gets a
comparison of whatever it varied: the coefficient error of every dataset by estimator and structure,
the held-out prediction error of each validation manoeuvre, the fit time, and the multicollinearity
of the regressors. Each point of the error figures is one run (one dataset); boxes show their
spread, so a sweep with ``replicates=N`` shows how much of a difference is the data's.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from .plots import ESTIMATOR_ORDER, STRUCTURE_ORDER, Builder, _order, _plt, _wrap, collinearity_tables, fit_time_figure
from .style import PRINT_WIDTH_IN, estimator_style, log_ticks, structure_style

#: configuration columns that name the data rather than the compared set-up
_DATA_COLUMNS = ("cfg_seed", "cfg_results_dir", "cfg_progress", "cfg_study")


def varied(runs: pd.DataFrame) -> list:
    """The configuration columns that take more than one value among ``runs`` (what the sweep
    compared)."""
    out = []
    for c in runs.columns:
        if c.startswith("cfg_") and c not in _DATA_COLUMNS and runs[c].astype(str).nunique() > 1:
            out.append(c)
    return out


def _by_estimator_and_structure(b: Builder, runs: pd.DataFrame, name: str, metric: str, label: str, out: str,
                                what: str) -> bool:
    if metric not in runs:
        return False
    r = runs[runs[metric].notna()]
    r = r[np.isfinite(r[metric].astype(float))]
    if not len(r):
        return False
    plt = _plt()
    ests = _order(r["cfg_estimator.name"], ESTIMATOR_ORDER)
    structs = _order(r["cfg_structure.name"], STRUCTURE_ORDER)
    fig, ax = plt.subplots(figsize=(min(PRINT_WIDTH_IN, 3.4 + 0.6 * len(ests) * max(1, len(structs)) ** 0.5), 3.4),
                           layout="constrained")
    w = 0.8 / len(structs)
    rows = []
    for k, s in enumerate(structs):
        st = structure_style(s)
        for i, e in enumerate(ests):
            v = r.loc[(r["cfg_structure.name"] == s) & (r["cfg_estimator.name"] == e), metric].astype(float)
            v = v[v > 0].to_numpy()
            if not len(v):
                continue
            x = i + k * w
            if len(v) > 1:
                ax.boxplot([v], positions=[x], widths=0.8 * w, showfliers=False, patch_artist=True,
                           boxprops={"facecolor": st["color"], "alpha": 0.35, "linewidth": 0.6},
                           medianprops={"color": "black", "linewidth": 0.9}, whiskerprops={"linewidth": 0.6},
                           capprops={"linewidth": 0.6})
            ax.plot(np.full(len(v), x), v, ls="none", marker=estimator_style(e)["marker"], ms=3.5,
                    color=st["color"], alpha=0.8)
            rows.append({"structure": s, "estimator": e, "datasets": len(v), "median": float(np.median(v)),
                         "q25": float(np.quantile(v, 0.25)), "q75": float(np.quantile(v, 0.75))})
    for k, s in enumerate(structs):
        ax.plot([], [], ls="none", marker="s", color=structure_style(s)["color"], label=s)
    ax.set_yscale("log")
    ax.set_xticks(np.arange(len(ests)) + 0.4 - w / 2, ests, rotation=45, ha="right", rotation_mode="anchor")
    ax.set_xlabel("estimator")
    ax.set_ylabel(label)
    ax.legend(title="sample structure", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    log_ticks(ax)
    n = int(r.groupby(["cfg_estimator.name", "cfg_structure.name"]).size().max())
    ax.set_title(_wrap(f"{name}: {what} (each point one run; {n} dataset{'s' if n > 1 else ''} per cell at most)",
                       80))
    b.figure(fig, name, out, f"{what} by estimator and structure, one point per run")
    b.table(pd.DataFrame(rows), name, out, f"{what} by estimator and structure: median and quartiles over runs")
    return True


def build(b: Builder, runs: pd.DataFrame, params: pd.DataFrame, name: str) -> list:
    """The generic figures of ``runs`` (finished runs of one sweep) under ``<out>/<name>/``; what
    was built, one line each (the reason when nothing could be)."""
    made = []
    r = runs[runs["status"] == "ok"] if "status" in runs else runs
    if not len(r):
        return [f"{name}: no finished run, nothing to draw"]
    for c in ("cfg_estimator.name", "cfg_structure.name"):
        if c not in r:
            r = r.assign(**{c: "(one)"})
    if _by_estimator_and_structure(b, r, name, "m_drift_median", "median relative coefficient error [-]",
                                   "drift", "median relative error of the identified coefficients"):
        made.append(f"{name}/drift: the runs' median coefficient error by estimator and structure")
    for m in sorted({c[len("m_val_"):-len("_nrmse_psi")] for c in r.columns
                     if c.startswith("m_val_") and c.endswith("_nrmse_psi")}):
        if _by_estimator_and_structure(b, r, name, f"m_val_{m}_nrmse_psi", "heading NRMSE [-]",
                                       f"validation_{m}", f"heading prediction error on {m}"):
            made.append(f"{name}/validation_{m}: the held-out heading error on {m}")
    if "t_fit" in r and r["t_fit"].notna().any():
        fit_time_figure(b, r, name)
        made.append(f"{name}/fit_time: the median fit time by estimator and structure")
    if any(c.startswith("m_cond_") for c in r.columns):
        collinearity_tables(b, r, name)
        made.append(f"{name}/collinearity: the regressors' condition numbers and VIFs")
    axes = [c[len("cfg_"):] for c in varied(r)]
    b.table(pd.DataFrame({"varied": axes or ["(nothing: one configuration)"]}), name, "varied",
            "the configuration keys the sweep varied")
    return made or [f"{name}: the runs carry no metric to draw (no truth, no validation records)"]
