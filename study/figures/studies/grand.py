"""The grand cross: every estimator and structure over vessels, noise levels, depths and sampling
intervals; does drift grow with noise?

``build`` writes the study's figures and tables into ``paper_figs/grand/`` and appends its claim to
``claims``; ``python -m study figures`` finds this module by the study's name
(``conf/experiment/grand.yaml``).

Nothing is pooled across models: every figure has one row of panels per vessel and model (each
with its own coefficient count), and the claim is decided per model with the dataset as the unit
(:mod:`study.figures.verdicts`), then per model x structure x estimator cell, with the verdict
under every other reasonable choice beside it."""
from __future__ import annotations

import pandas as pd

from ..plots import (
    ESTIMATOR_ORDER, STRUCTURE_ORDER, NOISE_ORDER, PRINT_WIDTH_IN, _plt, _order, _wrap, Builder, _hT,
    estimator_style, fit_time_figure, collinearity_tables, log_ticks, sampling_label, finest,
)
from ..verdicts import compare_datasets, dataset_sensitivity, dataset_verdict, summary, tidy_sensitivity

NAME = "grand"
SEED = None  # no seed paper's claim
#: relative errors below 0.1 % at both noise levels are a tie: neither is worse where both are exact enough
FLOOR = 1e-3
DEPTH_ORDER = ["deep", "5.6", "2.9", "1.46", "1.32"]


def _model(df: pd.DataFrame) -> pd.Series:
    return df["cfg_vessel.name"].astype(str) + " / " + df["cfg_model.name"].astype(str)


def _sampling(df: pd.DataFrame) -> list:
    """The sampling intervals the sweep asked for (``cfg_noise.sample_dt_LU``, in L/U0), finest
    first, as (column, value); [(None, None)] for a sweep that did not ask (each vessel at its
    default interval, named in the titles). The requested value, not the realised one: each
    vessel decimates a request to its own nearest step."""
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
    claims.append(claim(b, p, s, b.all_runs))


def _drift_figure(b: Builder, s: str, q: pd.DataFrame, axis: str, by: str, order: list, tag: str):
    """Median |relative error| against ``by``: a row of panels per model, a column per structure,
    a line per estimator. Medians are over depths (or noise levels), seeds and the model's own
    coefficients only."""
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


#: a model "is identified" when some estimator's median relative error at the lowest noise level is below this: one
#: that no estimator identifies is reported apart (its drift is the estimators' failure, not the noise's effect)
IDENTIFIED = 0.5
#: what names a dataset of a model (with the replicate): its depth, seed and sampling interval
DATASET = ["cfg_vessel.name", "cfg_model.name", "cfg_depth.h_T", "cfg_seed", "m_sample_dt_LU"]


def claim(b: Builder, p: pd.DataFrame, s: str = NAME, runs_all: pd.DataFrame | None = None) -> dict:
    """'Drift grows with the noise level', decided with the dataset as the unit: the same records
    (vessel, model, depth, seed, replicate, sampling interval) measured at the lowest and at the
    highest noise level of the sweep (the relative definition scales the same draws). Per model,
    one error per dataset: the median relative error over every structure, estimator and
    coefficient of its fits (the structures and estimators of one dataset are the same records,
    not more evidence); then per model x structure x estimator cell over its datasets (the claim
    says "every estimator and structure"). A model that no estimator identifies is reported
    apart."""
    text = "parameter drift grows with the noise level for every estimator and structure"
    noises = _order(p["cfg_noise.name"], NOISE_ORDER) if len(p) else []
    if len(noises) < 2:
        return {"seed": "(all)", "claim": text, "study": s, "verdict": "not run", "numbers": ""}
    lo, hi = noises[0], noises[-1]
    runs_all = runs_all if runs_all is not None else p.drop_duplicates("run_id")
    runs_all = runs_all.assign(model=_model(runs_all))
    per_model, tabs, cells, apart = {}, [], [], {}
    for m in sorted(p["model"].unique()):
        d, rd = p[p["model"] == m], runs_all[runs_all["model"] == m]
        own, other = finest(d)
        best = own[own["cfg_noise.name"] == lo].groupby(["cfg_structure.name", "cfg_estimator.name"])[
            "abs_rel_error"].median()
        if not len(best) or best.min() >= IDENTIFIED:
            apart[m] = float(best.min()) if len(best) else float("nan")
            continue
        ro = finest(rd)[0]
        subsets = [("deep water only", own[own["hT"] == "deep"], ro[ro["cfg_depth.h_T"].isna()])]
        for dt in other:
            sec = d.loc[d["m_sample_dt_LU"] == dt, "m_sample_dt"]
            subsets.append((f"sampled at {dt:.3g} L/U0 ({sec.min():g}-{sec.max():g} s)", d[d["m_sample_dt_LU"] == dt],
                            rd[rd["m_sample_dt_LU"] == dt]))
        for st in _order(own["cfg_structure.name"], STRUCTURE_ORDER):
            subsets.append((f"{st} rows only", own[own["cfg_structure.name"] == st], ro[ro["cfg_structure.name"] == st]))
        # "a is lower than b": the low noise level's errors are lower, i.e. drift grows with noise
        t = dataset_sensitivity(text, m, own, ro, "cfg_noise.name", lo, hi, DATASET, subsets, floor=FLOOR)
        per_model[m] = dataset_verdict(t)
        tabs.append(t)
        for (st, e), c in own.groupby(["cfg_structure.name", "cfg_estimator.name"]):
            rc = ro[(ro["cfg_structure.name"] == st) & (ro["cfg_estimator.name"] == e)]
            r = compare_datasets(c, "cfg_noise.name", lo, hi, DATASET, runs=rc, floor=FLOOR)
            cells.append({"model": m, "structure": st, "estimator": e, **r})
    if tabs:
        b.table(tidy_sensitivity(pd.concat(tabs, ignore_index=True)), s, "claim_sensitivity",
                f"grand: drift at noise {lo} against {hi} per model, the dataset as the unit (one error per dataset: "
                "the median over its fits' coefficients; ties within 5 % or both below 0.1 %), under each choice",
                floatfmt=".3g")
    c = pd.DataFrame(cells)
    if len(c):
        b.table(c[["model", "structure", "estimator", "verdict", "datasets", "wins", "losses", "ties", "failed_a",
                   "failed_b", "p", "p_reverse", "ratio", "ratio_low", "ratio_high", "detectable_ratio"]], s,
                "claim_cells", f"grand: drift at noise {lo} against {hi} per model x structure x estimator cell over its "
                "datasets (depths x replicates), finest sampling", floatfmt=".3g")
    counts = c["verdict"].value_counts() if len(c) else pd.Series(dtype=int)
    n_cells = len(c)
    holds_cells = int(counts.get("holds", 0))
    verdicts = {m: v for m, (v, _) in per_model.items()}
    verdict = (summary(verdicts) if verdicts else "not run") + (
        f"; per cell, in {holds_cells} of {n_cells} model x structure x estimator cells" if n_cells else "")
    worst = c[c["verdict"] != "holds"].sort_values("ratio", ascending=False).head(4) if len(c) else c
    exceptions = "; ".join(f"{w.model}, {w.structure}, {w.estimator}: {w.verdict} (median ratio {w.ratio:.2g})"
                           for w in worst.itertuples())
    apart_text = ("; reported apart, identified by no estimator (best median error at noise "
                  f"{lo}): " + ", ".join(f"{m} ({100 * v:.0f} %)" for m, v in apart.items())) if apart else ""
    return {"seed": "(all)", "claim": text, "study": s, "verdict": verdict,
            "numbers": "; ".join(f"{m}: {line}" for m, (_, line) in per_model.items())
            + f". Per cell: holds in {holds_cells}, cannot tell in {int(counts.get('cannot tell', 0))}, does not hold "
            f"in {int(counts.get('does not hold', 0))} of {n_cells}" + (f" (e.g. {exceptions})" if exceptions else "")
            + apart_text + "."}
