"""emcee on larger exact models (the MMG hull of KVLCC2, the waterjet USV's full model): are the
regression likelihood's 90 % intervals calibrated, per dataset and per coefficient, and does the
run's own trust flag fire where they are not (no noise, coarse sampling, coloured noise, a model
missing a term)?

``build`` writes the study's figures and tables into ``paper_figs/emcee_calibration/`` and appends
its claims to ``claims``; ``python -m study figures`` finds this module by the study's name
(``conf/experiment/emcee_calibration.yaml``). Coverage verdicts as in emcee_kt, the dataset as the
unit
(:func:`study.figures.verdicts.coverage_over_datasets`)."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd

from ..plots import PRINT_WIDTH_IN, Builder, _plt, _wrap, fit_time_figure
from ..verdicts import COVERAGE_BAND, coverage_over_datasets, describe_coverage, summary

NAME = "emcee_calibration"
SEED = None
NOMINAL = {"cfg_noise.name": "low_relative", "omit": "none"}


def _condition(row) -> str:
    """The set-up's departure from the likelihood's assumptions, in words."""
    parts = []
    if row["cfg_noise.name"] == "none":
        parts.append("no noise")
    elif "colored" in str(row["cfg_noise.name"]):
        parts.append("coloured noise")
    if row["omit"] != "none":
        parts.append(f"model without {row['omit']}")
    if row["coarse"]:
        parts.append("coarse sampling")
    return ", ".join(parts) or "as assumed"


def _prepare(r: pd.DataFrame, p: pd.DataFrame) -> pd.DataFrame:
    r = r.copy()
    omit = r["cfg_model.omit"] if "cfg_model.omit" in r else pd.Series("[]", index=r.index)
    r["omit"] = omit.map(lambda x: ", ".join(json.loads(x)) if isinstance(x, str) and x.startswith("[") else "")
    r["omit"] = r["omit"].replace("", "none")
    fine = r.groupby("cfg_model.name")["m_sample_dt_LU"].transform("min")
    r["coarse"] = r["m_sample_dt_LU"] > 1.5 * fine
    r["trusted"] = r["m_intervals_trusted"].map(lambda v: "not said" if pd.isna(v) else
                                                ("trusted" if bool(v) else "flagged"))
    r["condition"] = r.apply(_condition, axis=1)
    cols = ["run_id", "omit", "coarse", "trusted", "condition", "cfg_noise.name"]
    return p.drop(columns=[c for c in cols if c != "run_id" and c in p]).merge(r[cols], on="run_id")


def build(b: Builder, runs, params, claims):
    r, p = runs[runs["cfg_study"] == NAME], params[params["cfg_study"] == NAME]
    if not len(r):
        return
    # a model missing a term has approximate truths: its other coefficients' values in the simulated vessel
    p = _prepare(r, p[p["truth_kind"].isin(["exact", "approximate"])])
    keys = ["cfg_model.name", "cfg_structure.name", "condition"]
    rows = []
    for k, d in p.groupby(keys):
        for who, dd in (("all", d), ("trusted", d[d["trusted"] == "trusted"]), ("flagged", d[d["trusted"] == "flagged"])):
            c = coverage_over_datasets(dd)
            rows.append({**dict(zip(["model", "structure", "condition"], k)), "runs": who, **c})
    cov = pd.DataFrame(rows)
    b.table(cov, NAME, "coverage", "coverage of emcee's 90 % intervals of the truth per model, structure and "
            "condition, all runs and split by the run's own flag (intervals_trusted), the dataset as the unit (95 % "
            "bootstrap interval over datasets; datasets missing every / none of their coefficients)", floatfmt=".3g")
    nom = p[(p["condition"] == "as assumed")]
    per = []
    for (m, st, n), d in nom.groupby(["cfg_model.name", "cfg_structure.name", "name"]):
        c = coverage_over_datasets(d)
        per.append({"model": m, "structure": st, "coefficient": n, "coverage": c["coverage"],
                    "cov_low": c["cov_low"], "cov_high": c["cov_high"], "datasets": c["datasets"]})
    per = pd.DataFrame(per)
    if len(per):
        b.table(per, NAME, "coverage_per_coefficient", "coverage of each coefficient's 90 % interval over the "
                "datasets, set-ups as the likelihood assumes (white noise, finest sampling, the exact model)",
                floatfmt=".3g")
        _per_coefficient_figure(b, per)
    miss = (nom.assign(hit=(nom["ci_low"] <= nom["truth"]) & (nom["truth"] <= nom["ci_high"]))
            .groupby(["cfg_model.name", "cfg_structure.name", "run_id"])
            .agg(missed=("hit", lambda h: int((~h).sum())), k=("hit", "size")).reset_index())
    if len(miss):
        joint = (miss.groupby(["cfg_model.name", "cfg_structure.name", "missed"]).size().rename("datasets")
                 .reset_index().rename(columns={"cfg_model.name": "model", "cfg_structure.name": "structure",
                                                "missed": "coefficients_missed"}))
        b.table(joint, NAME, "joint_misses", "how many coefficients each dataset's intervals miss together (set-ups "
                "as the likelihood assumes): calibrated independent intervals would give a binomial spread")
    _trust_figure(b, cov)
    own = _own_best_fit(p)
    if len(own):
        b.table(own, NAME, "coverage_of_own_best_fit", "a model missing a term: coverage of the trusted runs' 90 % "
                "intervals of the vessel's values and of the model's own best fit (its estimate from the noise-free "
                "records of the same dataset: the same random rudder, no noise), the dataset as the unit",
                floatfmt=".3g")
    fit_time_figure(b, r, NAME)
    claims.extend(claim(cov, own))


def _own_best_fit(p: pd.DataFrame) -> pd.DataFrame:
    """Where the model lacks a term, what the trusted runs' intervals cover: the vessel's values,
    and the model's own best fit, its estimate from the noise-free records of the same dataset
    (same dataset seed, so the same random rudder; same model, structure and sampling interval).
    The gap between the two is the missing term's error, which the intervals do not claim to
    hold."""
    key = ["cfg_model.name", "cfg_structure.name", "omit", "coarse", "replicate", "name"]
    if "replicate" not in p:
        return pd.DataFrame()
    lack = p[p["omit"] != "none"]
    clean = lack[lack["cfg_noise.name"] == "none"][key + ["estimate"]].rename(columns={"estimate": "own"})
    noisy = lack[(lack["cfg_noise.name"] != "none") & (lack["trusted"] == "trusted")].merge(clean, on=key)
    rows = []
    for k, d in noisy.groupby(["cfg_model.name", "cfg_structure.name", "condition"]):
        vessel = coverage_over_datasets(d)
        own = coverage_over_datasets(d.assign(truth=d["own"]))
        rows.append({**dict(zip(["model", "structure", "condition"], k)), "datasets": vessel["datasets"],
                     "vessel_coverage": vessel["coverage"], "vessel_low": vessel["cov_low"],
                     "vessel_high": vessel["cov_high"], "own_coverage": own["coverage"], "own_low": own["cov_low"],
                     "own_high": own["cov_high"], "own_verdict": own["verdict"]})
    return pd.DataFrame(rows)


def _per_coefficient_figure(b: Builder, per: pd.DataFrame):
    plt = _plt()
    groups = list(per.groupby(["model", "structure"]))
    fig, axes = plt.subplots(len(groups), 1, figsize=(PRINT_WIDTH_IN, 1.9 * len(groups) + 0.8), squeeze=False,
                             layout="constrained")
    for ax, ((m, st), d) in zip(axes[:, 0], groups):
        x = np.arange(len(d))
        ax.axhspan(*COVERAGE_BAND, color="0.9", zorder=0)
        ax.axhline(0.9, color="grey", lw=0.8, ls="--")
        err = np.vstack([d["coverage"] - d["cov_low"], d["cov_high"] - d["coverage"]]).clip(min=0)
        ax.errorbar(x, d["coverage"], yerr=err, fmt="o", color="black", ms=4, lw=0.8)
        ax.set_xticks(x, d["coefficient"], rotation=60, fontsize=8)
        ax.set_xlabel("coefficient")
        ax.set_ylim(0, 1.02)
        ax.set_ylabel("coverage [-]")
        ax.set_title(f"{m}, {st} ({int(d['datasets'].max())} datasets)", fontsize=8)
    fig.suptitle(_wrap("emcee's 90 % intervals: coverage of each coefficient over the datasets with its 95 % "
                       "bootstrap interval (grey band: 80-97 %), set-ups as the likelihood assumes"))
    b.figure(fig, NAME, "coverage_per_coefficient", "coverage of each coefficient's 90 % interval over the datasets, "
             "per model and structure")


def _trust_figure(b: Builder, cov: pd.DataFrame):
    plt = _plt()
    d = cov[cov["runs"].isin(["trusted", "flagged"]) & (cov["datasets"] > 0)]
    if not len(d):
        return
    models = sorted(d["model"].unique())
    fig, axes = plt.subplots(1, len(models), figsize=(PRINT_WIDTH_IN, 3.6), squeeze=False, layout="constrained",
                             sharey=True)
    conds = sorted(d["condition"].unique(), key=lambda c: (c != "as assumed", c))
    for ax, m in zip(axes[0], models):
        dm = d[d["model"] == m]
        ax.axhspan(*COVERAGE_BAND, color="0.9", zorder=0)
        for j, (who, mk, col) in enumerate((("trusted", "o", "tab:blue"), ("flagged", "x", "tab:red"))):
            q = dm[dm["runs"] == who]
            xs = [conds.index(c) + (j - 0.5) * 0.25 for c in q["condition"]]
            ax.scatter(xs, q["coverage"], marker=mk, color=col, s=18, label=f"{who} runs")
        ax.set_xticks(range(len(conds)), conds, rotation=45, ha="right", fontsize=8)
        ax.set_xlabel("condition")
        ax.set_ylim(0, 1.02)
        ax.set_title(m, fontsize=9)
        ax.set_ylabel("coverage [-]")
    h, lab = axes[0, 0].get_legend_handles_labels()
    fig.legend(h, lab, loc="outside lower center", ncol=2)
    fig.suptitle(_wrap("emcee's 90 % intervals split by the run's own trust flag, per condition (each point a "
                       "structure; grey band: 80-97 %)"))
    b.figure(fig, NAME, "trust_by_condition", "coverage of trusted and flagged runs per model and condition")


def _flagged_only(cov: pd.DataFrame) -> str:
    """'; no run trusted in k of K conditions, ... where the flagged runs covered a-b %': the
    conditions where the flag fired on every dataset, and how their intervals did."""
    allr = cov[cov["runs"] == "all"]
    tr = cov[(cov["runs"] == "trusted") & (cov["datasets"] > 0)]
    key = ["model", "structure", "condition"]
    none = allr.merge(tr[key], on=key, how="left", indicator=True)
    none = none[none["_merge"] == "left_only"]
    if not len(none):
        return ""
    return (f"; no run trusted in {len(none)} of {len(allr)} model x structure x condition cells, whose "
            f"runs' intervals covered {100 * none['coverage'].min():.0f}-{100 * none['coverage'].max():.0f} % "
            f"(median {100 * none['coverage'].median():.0f} %): the flag fires wherever the likelihood's "
            "assumptions fail, also where the intervals still hold")


def claim(cov: pd.DataFrame, own: pd.DataFrame | None = None) -> list:
    """(a) the regression likelihood's intervals are calibrated on each model and structure where
    its assumptions hold; (b) wherever a run says its intervals are trusted they cover 80-97 %
    (every condition), and runs are flagged where the assumptions fail; (c) where the model lacks
    a term, the trusted runs' intervals cover the model's own best fit (what "trusted" can
    promise where the flag misses a term the model's others absorb)."""
    out = []
    allr = cov[cov["runs"] == "all"]
    nom = allr[allr["condition"] == "as assumed"]
    per = {f"{x.model}/{x.structure}": (x.verdict, describe_coverage(x._asdict())) for x in nom.itertuples()}
    if per:
        out.append({"seed": "(this harness)", "study": NAME,
                    "claim": "with the regression likelihood, emcee's 90 % intervals cover the truth about 90 % of "
                             "the time on models larger than a KT model (the MMG hull of KVLCC2, the waterjet USV's "
                             "full model), white noise, finest sampling",
                    "verdict": summary({k: v for k, (v, _) in per.items()}, "model x structure cells"),
                    "numbers": "; ".join(f"{k}: {line}" for k, (_, line) in per.items()) + "."})
    tr, fl = cov[cov["runs"] == "trusted"], cov[cov["runs"] == "flagged"]
    tr = tr[tr["datasets"] > 0]
    if len(tr) or len(fl):
        bad = tr[tr["verdict"] != "holds"]
        n_fl = int(fl["datasets"].sum())
        verdict = ("holds" if len(tr) and not len(bad) and n_fl else
                   "does not hold" if (bad["verdict"] == "does not hold").any() or not n_fl else "cannot tell")
        worst = bad.sort_values("coverage").head(6)
        out.append({"seed": "(this harness)", "study": NAME,
                    "claim": "wherever an emcee regression run says its intervals can be trusted, they cover the truth "
                             "80-97 % of the time (every model, structure and condition: no noise, coarse sampling, "
                             "coloured noise, a model missing a term), and runs are flagged where they do not "
                             "(decided per cell: the trusted runs' coverage in the band; wholly outside it, with its "
                             "interval over datasets, does not hold)",
                    "verdict": verdict,
                    "numbers": (f"trusted runs hold in {len(tr) - len(bad)} of {len(tr)} cells; "
                                f"{n_fl} datasets flagged in all" + _flagged_only(cov) + "." +
                                (" Cells where the trusted runs do not: " + "; ".join(
                                    f"{x.model}/{x.structure}, {x.condition}: {x.verdict} ({100 * x.coverage:.0f} %, "
                                    f"{x.datasets} datasets)" for x in worst.itertuples()) + "." if len(bad) else ""))})
    lacking = cov[(cov["runs"] == "all") & cov["condition"].str.contains("without")]
    if (own is None or not len(own)) and len(lacking):
        n = int(lacking["datasets"].sum())
        out.append({"seed": "(this harness)", "study": NAME,
                    "claim": "where the model lacks a term the truth has, an emcee regression run that says its "
                             "intervals can be trusted covers the model's own best fit (its estimate from the "
                             "noise-free records of the same dataset) 80-97 % of the time: the intervals hold the "
                             "identification spread of the model as given, not the missing term's error",
                    "verdict": "cannot tell",
                    "numbers": f"no run whose model lacks a term called its intervals trusted ({n} datasets in "
                               f"{len(lacking)} model x condition cells, every one flagged): what trusted intervals "
                               "cover there is not measured."})
    if own is not None and len(own):
        out.append({"seed": "(this harness)", "study": NAME,
                    "claim": "where the model lacks a term the truth has, an emcee regression run that says its "
                             "intervals can be trusted covers the model's own best fit (its estimate from the "
                             "noise-free records of the same dataset) 80-97 % of the time: the intervals hold the "
                             "identification spread of the model as given, not the missing term's error",
                    "verdict": summary(dict(zip(own["model"] + "/" + own["structure"] + ", " + own["condition"],
                                                own["own_verdict"])), "cells"),
                    "numbers": "; ".join(
                        f"{x.model}/{x.structure}, {x.condition}: the model's own best fit {100 * x.own_coverage:.0f} "
                        f"% (95 % over datasets {100 * x.own_low:.0f}-{100 * x.own_high:.0f} %), the vessel's values "
                        f"{100 * x.vessel_coverage:.0f} % ({100 * x.vessel_low:.0f}-{100 * x.vessel_high:.0f} %), "
                        f"{x.datasets} datasets" for x in own.itertuples()) + "."})
    return out
