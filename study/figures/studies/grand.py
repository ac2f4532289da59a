"""The grand cross: every estimator and structure over vessels, noise levels, depths and sampling intervals; does
drift grow with noise?

``build`` writes the study's figures and tables into ``paper_figs/grand/`` and appends its claim to ``claims``;
``python -m study.figures`` finds this module by the study's name (``conf/experiment/grand.yaml``).

Nothing is pooled across models: every figure has one row of panels per vessel and model (each with its own
coefficient count), and the claim is decided per model by paired sign tests (:mod:`study.figures.verdicts`), then
per model x structure x estimator cell, with the verdict under every other reasonable choice beside it."""
from __future__ import annotations

import pandas as pd

from ..plots import (
    ESTIMATOR_ORDER, STRUCTURE_ORDER, NOISE_ORDER, PRINT_WIDTH_IN, _plt, _order, _wrap, Builder, _hT,
    estimator_style, fit_time_figure, collinearity_tables, log_ticks, sampling_label, finest,
)
from ..verdicts import compare, explain, sensitivity, summary

NAME = "grand"
SEED = None  # no seed paper's claim
#: the data a pair shares: the same vessel, model, depth, structure, estimator, seed and sampling interval
KEYS = ["cfg_vessel.name", "cfg_model.name", "cfg_depth.h_T", "cfg_structure.name", "cfg_estimator.name", "cfg_seed",
        "m_sample_dt_LU"]
#: relative errors below 0.1 % at both noise levels are a tie: neither is worse where both are exact enough
FLOOR = 1e-3
DEPTH_ORDER = ["deep", "5.6", "2.9", "1.46", "1.32"]


def _model(df: pd.DataFrame) -> pd.Series:
    return df["cfg_vessel.name"].astype(str) + " / " + df["cfg_model.name"].astype(str)


def _sampling(df: pd.DataFrame) -> list:
    """The sampling intervals the sweep asked for (``cfg_noise.sample_dt_LU``, in L/U0), finest first, as (column,
    value); [(None, None)] for a sweep that did not ask (each vessel at its default interval, named in the titles).
    The requested value, not the realised one: each vessel decimates a request to its own nearest step."""
    col = "cfg_noise.sample_dt_LU"
    if col in df and df[col].notna().any():
        return [(col, v) for v in sorted(df[col].dropna().unique())]
    return [(None, None)]


def _at(df: pd.DataFrame, col, v) -> pd.DataFrame:
    return df if col is None else df[df[col] == v]


def build(b: Builder, runs, params, claims, s="grand"):
    r, p = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    p = p[p["truth_kind"] == "exact"].copy()
    p["hT"] = p["cfg_depth.h_T"].map(_hT)
    p["model"] = _model(p)
    for col, v in _sampling(p):
        q = _at(p, col, v)
        tag = "" if col is None else f"_{v:g}LU"
        for axis, by, order in (("noise", "cfg_noise.name", NOISE_ORDER), ("hT", "hT", DEPTH_ORDER)):
            _drift_figure(b, s, q, axis, by, order, tag)
    piv = p.pivot_table(index=["cfg_structure.name", "cfg_estimator.name"], columns=["model", "cfg_noise.name"],
                        values="abs_rel_error", aggfunc="median")
    if len(piv):
        piv.columns = [f"{m}, {n}" for m, n in piv.columns]
        b.table(piv.reset_index(), s, "drift_by_vessel", "median |relative error| per structure, estimator, vessel "
                "and noise level (over depths, seeds, sampling intervals and the model's exact coefficients)")
    collinearity_tables(b, r, s, group=("cfg_vessel.name", "cfg_structure.name", "cfg_noise.name"))
    fit_time_figure(b, r, s)
    claims.append(claim(b, p, s))


def _drift_figure(b: Builder, s: str, q: pd.DataFrame, axis: str, by: str, order: list, tag: str):
    """Median |relative error| against ``by``: a row of panels per model, a column per structure, a line per
    estimator. Medians are over depths (or noise levels), seeds and the model's own coefficients only."""
    plt = _plt()
    vals = _order(q[by], order)
    if len(vals) < 2:
        return
    models = sorted(q["model"].unique())
    structs = _order(q["cfg_structure.name"], STRUCTURE_ORDER)
    fig, axes = plt.subplots(len(models), len(structs), figsize=(PRINT_WIDTH_IN, 1.45 * len(models) + 1.6),
                             sharex=True, sharey="row", squeeze=False, layout="constrained")
    rows, handles = [], {}
    for i, m in enumerate(models):
        for j, st in enumerate(structs):
            ax = axes[i, j]
            d = q[(q["model"] == m) & (q["cfg_structure.name"] == st)]
            for e in _order(d["cfg_estimator.name"], ESTIMATOR_ORDER):
                med = d[d["cfg_estimator.name"] == e].groupby(by)["abs_rel_error"].median().reindex(vals)
                (h,) = ax.plot(vals, med.to_numpy(float), lw=1.0, ms=4, label=e, **estimator_style(e))
                handles.setdefault(e, h)
                rows += [{"model": m, "structure": st, "estimator": e, axis: x, "median_abs_rel_error": med[x]}
                         for x in vals]
            ax.set_yscale("log")
            log_ticks(ax)
            if i == 0:
                ax.set_title(f"{st} samples")
            if j == 0:
                ax.set_ylabel(f"{m}\nmedian |rel. error| [-]")
            else:  # the row shares the first panel's axis and label
                ax.tick_params(labelleft=False, which="both")
            if i == len(models) - 1:
                ax.set_xlabel("noise level" if axis == "noise" else "h/T [-]")
    ests = _order(list(handles), ESTIMATOR_ORDER)
    fig.legend([handles[e] for e in ests], ests, loc="outside lower center", ncol=min(len(ests), 6), title="estimator")
    over = "depths" if axis == "noise" else "noise levels"
    fig.suptitle(_wrap(f"Median |relative error| of each model's exact coefficients against the "
                       f"{'noise level' if axis == 'noise' else 'water depth h/T'} (over {over} and seeds; "
                       f"{sampling_label(q) or 'each vessel at its default sampling interval'})"))
    b.figure(fig, s, f"drift_vs_{axis}{tag}", f"median parameter drift against the {axis}, per model, structure "
             f"and estimator ({sampling_label(q) or 'default sampling'})")
    b.table(pd.DataFrame(rows), s, f"drift_vs_{axis}{tag}", f"median parameter drift against the {axis} per model, "
            f"structure and estimator ({sampling_label(q) or 'default sampling'})")


def claim(b: Builder, p: pd.DataFrame, s: str = NAME) -> dict:
    """'Drift grows with the noise level', decided per model: the same data (vessel, model, depth, structure,
    estimator, seed, sampling interval) identified at the lowest and at the highest noise level of the sweep,
    paired per coefficient (relative errors; ties within 5 % or both below 0.1 %), one-sided sign test at 5 %.
    Then per model x structure x estimator cell (the claim says "every estimator and structure"). Alternatives:
    the scaled error, one pair per equation, each sampling interval, deep water only."""
    text = "parameter drift grows with the noise level for every estimator and structure"
    noises = _order(p["cfg_noise.name"], NOISE_ORDER) if len(p) else []
    if len(noises) < 2:
        return {"seed": "(all)", "claim": text, "study": s, "verdict": "not run", "numbers": ""}
    lo, hi = noises[0], noises[-1]
    per_model, rows, cells = {}, [], []
    for m in sorted(p["model"].unique()):
        d = p[p["model"] == m]
        own, other = finest(d)
        choices = [(f"relative error per coefficient, {lo} against {hi}, finest sampling", own, "abs_rel_error",
                    "coefficient"),
                   ("scaled error per coefficient", own, "scaled_error", "coefficient"),
                   ("median relative error per equation and run", own, "abs_rel_error", "equation"),
                   ("deep water only", own[own["hT"] == "deep"], "abs_rel_error", "coefficient")]
        for dt in other:
            sec = d.loc[d["m_sample_dt_LU"] == dt, "m_sample_dt"]
            choices.append((f"sampled at {dt:.3g} L/U0 ({sec.min():g}-{sec.max():g} s)", d[d["m_sample_dt_LU"] == dt],
                            "abs_rel_error", "coefficient"))
        # a choice the table cannot make (a metric it does not hold, no deep-water runs) is left out, not a verdict
        choices = [c for c in choices if len(c[1]) and c[1][c[2]].notna().any()]
        # "a is lower than b": the low noise level's errors are lower, i.e. drift grows with noise
        tab = sensitivity(d, "cfg_noise.name", lo, hi, KEYS, choices, floor=FLOOR)
        per_model[m] = (tab.iloc[0]["verdict"], explain(tab))
        rows.append(tab.assign(model=m))
        for (st, e), c in own.groupby(["cfg_structure.name", "cfg_estimator.name"]):
            r = compare(c, "cfg_noise.name", lo, hi, KEYS, "abs_rel_error", floor=FLOOR)
            cells.append({"model": m, "structure": st, "estimator": e, **r})
    t = pd.concat(rows, ignore_index=True)
    t = t[["model", "what", "verdict", "pairs", "wins", "losses", "ties", "p", "p_reverse", "p_wilcoxon",
           "median_ratio"]].rename(columns={"what": "choice"})
    b.table(t, s, "claim_sensitivity", f"grand: drift at noise {lo} against {hi}, per model, paired per coefficient "
            "(ties: within 5 % or both below 0.1 %), under each choice", floatfmt=".3g")
    c = pd.DataFrame(cells)
    b.table(c[["model", "structure", "estimator", "verdict", "pairs", "wins", "losses", "ties", "p", "p_reverse",
               "median_ratio"]], s, "claim_cells", f"grand: drift at noise {lo} against {hi} per model x structure x "
            "estimator cell, finest sampling, paired per coefficient", floatfmt=".3g")
    counts = c["verdict"].value_counts()
    n_cells = len(c)
    holds_cells = int(counts.get("holds", 0))
    verdicts = {m: v for m, (v, _) in per_model.items()}
    all_models = all(v == "holds" for v in verdicts.values())
    verdict = summary(verdicts) + ("" if not all_models or holds_cells == n_cells else
                                   f"; per cell, in {holds_cells} of {n_cells} model x structure x estimator cells")
    worst = c[c["verdict"] != "holds"].sort_values("median_ratio", ascending=False).head(4)
    exceptions = "; ".join(f"{w.model}, {w.structure}, {w.estimator}: {w.verdict} (median ratio "
                           f"{w.median_ratio:.2g})" for w in worst.itertuples())
    return {"seed": "(all)", "claim": text, "study": s, "verdict": verdict,
            "numbers": "; ".join(f"{m}: {line}" for m, (_, line) in per_model.items())
            + f". Per cell: holds in {holds_cells}, cannot tell in {int(counts.get('cannot tell', 0))}, does not hold "
            f"in {int(counts.get('does not hold', 0))} of {n_cells}" + (f" (e.g. {exceptions})" if exceptions else "")
            + "."}
