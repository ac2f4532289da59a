"""emcee on Nomoto models: are the 90 % intervals calibrated, per likelihood, structure, noise and
sampling interval?

``build`` writes the study's figures and tables into ``paper_figs/emcee_kt/`` and appends its claims
to ``claims``; ``python -m study figures`` finds this module by the study's name
(``conf/experiment/emcee_kt.yaml``).

How a calibration verdict is decided: over the datasets (seeds) of one set-up, each coefficient's
90 % interval either holds the truth or not. The coverage (the share of intervals that hold it)
comes with a 95 % bootstrap interval over datasets: the intervals of one dataset miss together,
so they are resampled together (:func:`study.figures.verdicts.coverage_over_datasets`). "About 90
%" is the band 80-97 %: **holds** when the coverage lies in it; **does not hold** when its
interval lies wholly outside it; **cannot tell** otherwise (too few datasets to tell). Whether
the interval lies below or above 90 % is said beside the verdict. Each claim is then restated
under every other set-up of the sweep (noise definition, sampling interval): a verdict that
changes says "depends on ..."."""
from __future__ import annotations

import math

import pandas as pd

from ..plots import Builder, _first, _order, NOISE_ORDER, STRUCTURE_ORDER
from ..posterior_plots import emcee_figures
from ..verdicts import coverage_over_datasets, describe_coverage, settle

NAME = "emcee_kt"
SEED = None  # no seed paper's claim
# noise on the outputs only: the absolute and the relative definition (the study pins the relative one)
OUTPUTS_ONLY = ("low_outputs_relative", "low_outputs")
LIK = "cfg_estimator.params.likelihood"
CORRECT = "cfg_estimator.params.correct_rows"  # the rows' truncation and regressors' noise removed (row_errors)
BAND = (0.80, 0.97)  # 90 % intervals covering the truth 80-97 % of the time are called calibrated


def _likelihood(row) -> str:
    if row["cfg_structure.name"] == "output_error":
        return "output_error"
    lik = str(row.get(LIK) or "regression_iid")  # runs made before the likelihood was a setting: iid
    corrected = row.get(CORRECT)
    if lik == "regression" and (corrected is None or pd.isna(corrected) or not bool(corrected)):
        return "regression_uncorrected"  # correct_rows false, or a run made before the rows' errors were removed
    return lik


def coverage(p: pd.DataFrame) -> dict:
    """Coverage of the truth by the 90 % intervals of ``p``'s rows, the dataset (run) as the unit
    (:func:`study.figures.verdicts.coverage_over_datasets`)."""
    return coverage_over_datasets(p)


def build(b: Builder, runs, params, claims):
    s = NAME
    r, p = runs[runs["cfg_study"] == s].copy(), params[params["cfg_study"] == s]
    if not len(r):
        claims.extend(claim(pd.DataFrame()))
        return
    r["likelihood"] = r.apply(_likelihood, axis=1)
    # the run's own word on its intervals (emcee regression runs; study/identify/truncation.py); missing: not said
    r["trusted"] = r["m_intervals_trusted"].map(_trust) if "m_intervals_trusted" in r else "not said"
    p = p.merge(r[["run_id", "likelihood", "trusted"]], on="run_id")
    if "cfg_noise.sample_dt_LU" not in p:
        p["cfg_noise.sample_dt_LU"] = math.nan
    rows = []
    keys = ["likelihood", "cfg_structure.name", "cfg_noise.name", "cfg_noise.sample_dt_LU"]
    for key, d in p.groupby(keys, dropna=False):
        sec = d["m_sample_dt"].dropna()
        rows.append({"likelihood": key[0], "structure": key[1], "noise": key[2], "sample_dt_LU": key[3],
                     "sample_dt_s": f"{sec.min():g}-{sec.max():g}" if len(sec) and sec.min() != sec.max()
                     else (f"{sec.min():g}" if len(sec) else ""), "datasets": int(d["run_id"].nunique()),
                     **coverage(d)})
    cov = pd.DataFrame(rows)
    order = {v: i for i, v in enumerate(["output_error", "regression", "regression_uncorrected", "regression_iid"])}
    cov = cov.sort_values(["likelihood", "structure", "noise", "sample_dt_LU"],
                          key=lambda c: c.map(order) if c.name == "likelihood" else
                          (c.map({v: i for i, v in enumerate(STRUCTURE_ORDER)}) if c.name == "structure" else
                           (c.map({v: i for i, v in enumerate(NOISE_ORDER)}) if c.name == "noise" else c)))
    b.table(cov, s, "coverage", "coverage of emcee's 90 % intervals of the truth over the datasets (seeds), per "
            "likelihood, structure, noise (outputs only / rudder too) and sampling interval, with the binomial test "
            "against 0.9 and the verdict (module docstring)", floatfmt=".3g")
    # the figures show one dataset, chosen by name: the lowest seed at the finest sampling (named in their titles)
    run = None
    fine = r
    if "cfg_noise.sample_dt_LU" in r and r["cfg_noise.sample_dt_LU"].notna().any():
        fine = r[r["cfg_noise.sample_dt_LU"] == r["cfg_noise.sample_dt_LU"].min()]
    for nz in OUTPUTS_ONLY:
        run = run if run is not None else _first(fine, **{"cfg_structure.name": "output_error", "cfg_noise.name": nz})
    if run is not None:
        emcee_figures(b, s, run, p)
    claims.extend(claim(cov, b))
    claims.extend(trust_claim(p, b))


def _trust(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "not said"
    return "trusted" if bool(v) else "not trusted"


def trust_table(p: pd.DataFrame) -> pd.DataFrame:
    """Coverage of the regression likelihood's intervals split by the run's own flag, per
    structure, noise and sampling interval: the flag is worth having when the trusted runs are
    calibrated and the flagged ones are the runs that miss."""
    reg = p[p["likelihood"] == "regression"]
    rows = []
    keys = ["cfg_structure.name", "cfg_noise.name", "cfg_noise.sample_dt_LU", "trusted"]
    for key, d in reg.groupby(keys, dropna=False):
        rows.append({"structure": key[0], "noise": key[1], "sample_dt_LU": key[2], "trusted": key[3],
                     "datasets": int(d["run_id"].nunique()), **coverage(d)})
    t = pd.DataFrame(rows)
    if len(t):
        t = t.sort_values(["structure", "noise", "sample_dt_LU", "trusted"],
                          key=lambda c: c.map({v: i for i, v in enumerate(STRUCTURE_ORDER)}) if c.name == "structure"
                          else (c.map({v: i for i, v in enumerate(NOISE_ORDER)}) if c.name == "noise" else c))
    return t


def trust_claim(p: pd.DataFrame, b: Builder | None = None) -> list:
    """(c) The runs' own flag: over every regression set-up of the sweep, the intervals of the
    runs that call themselves trusted cover the truth about 90 % of the time (decided as every
    coverage verdict here, on the trusted runs of each structure, all noise definitions and
    sampling intervals of the one KT model together: the flag is meant to hold whatever the
    set-up); beside it the coverage of the runs that flag themselves."""
    text = ("an emcee regression run that says its intervals can be trusted (m_intervals_trusted, from its own "
            "records) has intervals that cover the truth about 90 % of the time")
    t = trust_table(p) if len(p) and "trusted" in p else pd.DataFrame()
    if not len(t) or not (t["trusted"] != "not said").any():
        return [{"seed": "(this harness)", "claim": text, "study": NAME, "verdict": "not run", "numbers": ""}]
    if b is not None:
        b.table(t, NAME, "trust", "emcee_kt: coverage of the regression likelihood's 90 % intervals split by the "
                "run's own flag (m_intervals_trusted, from its own records: study/identify/truncation.py), per "
                "structure, noise and sampling interval",
                floatfmt=".3g")
    reg = p[(p["likelihood"] == "regression") & (p["trusted"] != "not said")]
    per, lines = {}, []
    for st in _order(reg["cfg_structure.name"], STRUCTURE_ORDER):
        d = reg[reg["cfg_structure.name"] == st]
        yes, no = coverage(d[d["trusted"] == "trusted"]), coverage(d[d["trusted"] == "not trusted"])
        per[st] = yes["verdict"]
        n_no = int(d.loc[d["trusted"] == "not trusted", "run_id"].nunique())
        lines.append(f"{st}: trusted runs {_line(yes)}" if yes["intervals"] else f"{st}: no run trusted")
        lines[-1] += (f"; {n_no} of {d['run_id'].nunique()} runs flagged, their intervals "
                      f"{100 * no['coverage']:.0f} % covered" if n_no else "; no run flagged (the flag never fired)")
    verdicts = [v for v in per.values() if v != "not run"]
    verdict = ("not run" if not verdicts else
               "; ".join(f"{v} for {', '.join(k for k, x in per.items() if x == v)}" for v in dict.fromkeys(verdicts)))
    return [{"seed": "(this harness)", "claim": text, "study": NAME, "verdict": verdict, "numbers": "; ".join(lines) + "."}]


def _sensitivity(cov: pd.DataFrame, primary: pd.Series) -> pd.DataFrame:
    """The primary set-up's verdict, then the same likelihood and structure under every other
    noise and sampling interval of the sweep."""
    same = cov[(cov["likelihood"] == primary["likelihood"]) & (cov["structure"] == primary["structure"])]
    out = [{"choice": "primary", **primary.to_dict()}]
    for _, o in same.iterrows():
        if o["noise"] == primary["noise"] and o["sample_dt_LU"] == primary["sample_dt_LU"]:
            continue
        out.append({"choice": f"noise {o['noise']}, {o['sample_dt_LU']:g} L/U0", **o.to_dict()})
    return pd.DataFrame(out)


def _line(c) -> str:
    return describe_coverage(c)


def claim(cov: pd.DataFrame, b: Builder | None = None) -> list:
    """Two claims: (a) output error with noise on the outputs only, the likelihood's own
    assumption; (b) the regression likelihood that models the rows' noise, per regression
    structure (the iid likelihood beside it, for the record). Each at the finest sampling with
    noise on the outputs only, restated under the other set-ups."""
    texts = {"a": "emcee's 90 % intervals cover the truth about 90 % of the time when the output-error likelihood's "
                  "assumptions hold (noise on the outputs only)",
             "b": "with the regression likelihood that models the rows' noise and removes their truncation and the "
                  "regressors' noise (study/identify/row_noise.py, row_errors.py), emcee's 90 % intervals cover the "
                  "truth about 90 % of the time on every regression structure"}
    if not len(cov):
        return [{"seed": "(this harness)", "claim": t, "study": NAME, "verdict": "not run", "numbers": ""}
                for t in texts.values()]
    fine = cov["sample_dt_LU"].min() if cov["sample_dt_LU"].notna().any() else math.nan
    prim = cov[cov["noise"].isin(OUTPUTS_ONLY) & ((cov["sample_dt_LU"] == fine) | cov["sample_dt_LU"].isna())]
    out, tabs = [], []
    oe = prim[prim["likelihood"] == "output_error"]
    if len(oe):
        t = _sensitivity(cov, oe.iloc[0])
        tabs.append(t.assign(claim="a", structure="output_error"))
        out.append({"seed": "(this harness)", "claim": texts["a"], "study": NAME, "verdict": settle(t),
                    "numbers": "output error, " + _line(t.iloc[0]) + "; " + "; ".join(
                        f"{c['choice']}: {c['verdict']} ({100 * c['coverage']:.0f} %)" for _, c in t.iloc[1:].iterrows())
                    + "."})
    reg = prim[prim["likelihood"] == "regression"]
    per, lines = {}, []
    for st in _order(reg["structure"], STRUCTURE_ORDER):
        t = _sensitivity(cov, reg[reg["structure"] == st].iloc[0])
        tabs.append(t.assign(claim="b", structure=st))
        per[st] = settle(t)
        lines.append(f"{st}: {_line(t.iloc[0])}; " + "; ".join(
            f"{c['choice']}: {c['verdict']} ({100 * c['coverage']:.0f} %)" for _, c in t.iloc[1:].iterrows()))
    raw = cov[cov["likelihood"] == "regression_uncorrected"]
    if len(raw):  # the likelihood before the rows' errors were removed (correct_rows false), every set-up
        lines.append("without removing the rows' errors (correct_rows false): " + "; ".join(
            f"{c['structure']} at {c['sample_dt_LU']:g} L/U0, {c['noise']} {100 * c['coverage']:.0f} %"
            for _, c in raw.iterrows()))
    iid = prim[prim["likelihood"] == "regression_iid"]
    if len(iid):
        lines.append("the iid likelihood for comparison: " + "; ".join(
            f"{c['structure']} {100 * c['coverage']:.0f} % (median width {100 * c['median_rel_width']:.3g} % of the "
            "truth)" for _, c in iid.iterrows()))
    if per:
        agree = set(per.values())
        n = len(per)
        verdict = (next(iter(agree)) + (f" for all {n} structures" if n > 1 else f" for {next(iter(per))}")
                   if len(agree) == 1 else
                   "; ".join(f"{v} for {', '.join(k for k, x in per.items() if x == v)}" for v in dict.fromkeys(per.values())))
        out.append({"seed": "(this harness)", "claim": texts["b"], "study": NAME, "verdict": verdict,
                    "numbers": "; ".join(lines) + "."})
    if b is not None and tabs:
        t = pd.concat(tabs, ignore_index=True)
        cols = ["claim", "structure", "choice", "verdict", "datasets", "intervals", "covered", "coverage", "cov_low",
                "cov_high", "none_covered", "all_covered", "median_rel_width", "median_abs_rel_error"]
        b.table(t[cols], NAME, "claim_sensitivity", "emcee_kt: each calibration claim at its primary set-up (finest "
                "sampling, noise on the outputs only) and under every other set-up of the sweep", floatfmt=".3g")
    return out
