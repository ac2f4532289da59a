"""CLAIMS.md's headline numbers recomputed from the committed study tables with code of this test's own (plain pandas
and scipy, not study.figures), and the committed tables checked against the code that would compute them.

For each dataset-unit comparison it can recompute, the test selects the claim's primary rows by hand, reduces each
fit to the median |relative error| of its coefficients (a failed run: infinite), pairs the two methods on the same
dataset and counts wins, losses and ties; for each coverage claim it counts the intervals that hold the truth. The
numbers must appear in the claim's row of paper_figs/CLAIMS.md."""
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2] / "paper_figs"
TIE = 0.05


def _table(study):
    d = ROOT / study / "table"
    if not (d / "runs.parquet").is_file():
        pytest.skip(f"{study}: no committed table")
    return pd.read_parquet(d / "runs.parquet"), pd.read_parquet(d / "params.parquet")


def _claim_rows(study):
    return [ln for ln in (ROOT / "CLAIMS.md").read_text(encoding="utf-8").splitlines() if f"`{study}`" in ln]


def _counts(a: pd.Series, b: pd.Series, floor: float) -> tuple:
    """(wins, losses, ties, datasets) of "a is lower than b" over paired per-dataset errors."""
    both = pd.concat([a.rename("a"), b.rename("b")], axis=1).dropna()
    x, y = both["a"].to_numpy(float), both["b"].to_numpy(float)
    xf, yf = np.where(np.isinf(x), 1e300, x), np.where(np.isinf(y), 1e300, y)
    same = np.isinf(x) & np.isinf(y)
    xf, yf = np.where(same, 0, xf), np.where(same, 0, yf)
    scale = np.maximum(np.maximum(xf, yf), 1e-300)
    small = (xf <= floor) & (yf <= floor)
    wins = int(np.sum(((yf - xf) > TIE * scale) & ~small))
    losses = int(np.sum(((xf - yf) > TIE * scale) & ~small))
    return wins, losses, len(x) - wins - losses, len(x)


def _per_dataset(runs, params, method_col, keys, relabel=()):
    """method -> Series of per-dataset median |relative error| (index: the dataset), failed runs infinite."""
    p = params.merge(runs[["run_id"] + [k for k in keys + [method_col] if k not in params]], on="run_id")
    p = p.assign(err=(p["estimate"] - p["truth"]).abs() / p["truth"].abs())
    for a, b in relabel:  # exchangeable pair (T1, T2): the better of the two assignments
        for rid, g in p[p["name"].isin([a, b])].groupby("run_id"):
            if len(g) != 2:
                continue
            e, t = g.set_index("name")["estimate"], g.set_index("name")["truth"]
            swap = abs(e[b] - t[a]) / abs(t[a]) + abs(e[a] - t[b]) / abs(t[b])
            if swap < g["err"].sum():
                p.loc[g.index[g["name"] == a], "err"] = abs(e[b] - t[a]) / abs(t[a])
                p.loc[g.index[g["name"] == b], "err"] = abs(e[a] - t[b]) / abs(t[b])
    per = p.groupby(keys + [method_col])["err"].median()
    failed = runs[runs["status"] == "failed"].set_index(keys + [method_col]).index
    per = pd.concat([per, pd.Series(np.inf, index=failed)]).groupby(level=list(range(len(keys) + 1))).max()
    return {m: per.xs(m, level=method_col) for m in per.index.get_level_values(method_col).unique()}


def _finest_noisy(runs):
    fine = runs.groupby("cfg_model.name")["m_sample_dt_LU"].transform("min")
    return runs[np.isclose(runs["m_sample_dt_LU"], fine) & (runs["cfg_noise.name"] != "none")]


@pytest.mark.parametrize("study, a, b, method_col, floor, relabel", [
    ("seed004_stepwise", "de", "de_staged", "cfg_estimator.name", 0.01, [("T1", "T2")]),
    ("seed004_kt_de", "output_error", "central", "cfg_structure.name", 0.01, [("T1", "T2")]),
])
def test_paired_dataset_counts_match_claims(study, a, b, method_col, floor, relabel):
    runs, params = _table(study)
    runs = runs.assign(replicate=runs["replicate"].fillna(0) if "replicate" in runs else 0)
    params = params[params["truth_kind"] == "exact"]
    runs = _finest_noisy(runs[runs["run_id"].isin(params["run_id"]) | (runs["status"] == "failed")])
    rows = _claim_rows(study)
    assert rows, f"{study}: no row in CLAIMS.md"
    for model, g in runs.groupby("cfg_model.name"):
        keys = ["cfg_vessel.name", "cfg_noise.name", "m_sample_dt_LU", "replicate"]
        keys += [k for k in ("cfg_maneuvers.name",) if k in g and g[k].nunique() > 1]
        per = _per_dataset(g, params[params["run_id"].isin(g["run_id"])], method_col, keys, relabel)
        w, l, t, n = _counts(per[a], per[b], floor)
        text = f"({w} wins, {l} losses, {t} ties of {n} datasets"
        assert any(f"{model}:" in r and text in r for r in rows), (study, model, text)


@pytest.mark.parametrize("study", ["emcee_calibration"])
def test_coverage_counts_match_claims(study):
    runs, params = _table(study)
    runs = runs[runs["status"] == "ok"]
    fine = runs.groupby("cfg_model.name")["m_sample_dt_LU"].transform("min")
    nominal = runs[np.isclose(runs["m_sample_dt_LU"], fine) & (runs["cfg_noise.name"] == "low_relative")
                   & (runs.get("cfg_model.omit", pd.Series("[]", index=runs.index)).fillna("[]") == "[]")]
    p = params[params["run_id"].isin(nominal["run_id"]) & params["truth_kind"].isin(["exact", "approximate"])]
    p = p.merge(nominal[["run_id", "cfg_model.name", "cfg_structure.name"]], on="run_id", suffixes=("_p", ""))
    rows = _claim_rows(study)
    for (m, st), g in p.groupby(["cfg_model.name", "cfg_structure.name"]):
        hit = int(((g["ci_low"] <= g["truth"]) & (g["truth"] <= g["ci_high"])).sum())
        text = f"{m}/{st}: {hit}/{len(g)} intervals of {g['run_id'].nunique()} datasets covered"
        assert any(text in r for r in rows), text


def test_a_missing_terms_trusted_coverage_of_the_models_own_fit_matches_claims():
    """The runs without N'vvr (white noise, the finest interval), trusted: the share of their intervals that hold
    the estimate of the noise-free run of the same model, structure, interval and dataset (replicate)."""
    runs, params = _table("emcee_calibration")
    runs = runs[(runs["status"] == "ok") & runs["cfg_model.omit"].astype(str).str.contains("Nvvr")]
    fine = runs[np.isclose(runs["m_sample_dt_LU"], runs.groupby("cfg_model.name")["m_sample_dt_LU"].transform("min"))]
    keys = ["cfg_model.name", "cfg_structure.name", "replicate"]
    p = params[params["truth_kind"].isin(["exact", "approximate"])][["run_id", "name", "ci_low", "ci_high"]
                                                                      + ["estimate"]]
    p = p.merge(fine[["run_id", "cfg_noise.name", "m_intervals_trusted"] + keys], on="run_id")
    clean = p[p["cfg_noise.name"] == "none"][keys + ["name", "estimate"]].rename(columns={"estimate": "own"})
    noisy = p[(p["cfg_noise.name"] == "low_relative") & (p["m_intervals_trusted"] == True)]  # noqa: E712
    both = noisy.merge(clean, on=keys + ["name"])
    rows = _claim_rows("emcee_calibration")
    for m, g in both.groupby("cfg_model.name"):
        cov = ((g["ci_low"] <= g["own"]) & (g["own"] <= g["ci_high"])).mean()
        assert any(f"{m}/central, model without Nvvr: the model's own best fit {100 * cov:.0f} %" in r
                   for r in rows), (m, cov)


def _stale(study_dir: Path) -> int:
    from study.figures import code_status

    runs = pd.read_parquet(study_dir / "runs.parquet")
    return code_status(runs)["stale"]


@pytest.mark.slow  # every committed table's runs fingerprinted against the code on disk (seconds per study)
@pytest.mark.parametrize("study", sorted(p.parent.name for p in ROOT.glob("*/table")))
def test_every_committed_table_is_current(study):
    assert _stale(ROOT / study / "table") == 0, f"{study}: runs computed by code that has changed since; re-run it"


@pytest.mark.slow  # seconds per study: every committed table read
@pytest.mark.parametrize("study", sorted(p.parent.name for p in ROOT.glob("*/table")))
def test_every_noisy_cell_of_a_committed_table_has_twenty_datasets(study):
    """The dataset is the unit: each configuration whose records carry random noise holds at least 20 datasets
    (a noise-free configuration is one dataset by construction). Counted here by the configuration's scientific
    keys (the run id's: not the progress bar, the launcher or the output folder)."""
    from study.store.records import NON_SCIENTIFIC_KEYS

    runs, _ = _table(study)
    runs = runs[(runs["cfg_study"] == study) & runs["status"].isin(["ok", "failed"])]
    keys = [c for c in runs.columns if c.startswith("cfg_") and c != "cfg_seed"
            and c[4:].split(".")[0] not in NON_SCIENTIFIC_KEYS]
    n = runs[keys].astype(str).groupby(keys, dropna=False).size()
    noisy = runs[keys].astype(str).groupby(keys, dropna=False)["cfg_noise.name"].first() != "none"
    assert n[noisy.to_numpy()].min() >= 20, n[noisy.to_numpy()].nsmallest(3)


def test_datasets_per_cell_ignores_settings_that_change_no_science():
    from study.figures import datasets_per_cell

    runs = pd.DataFrame({"cfg_vessel.name": ["a"] * 4 + ["b"] * 2, "cfg_noise.name": ["low"] * 4 + ["none"] * 2,
                         "cfg_progress": [True, False, True, False, True, True], "cfg_seed": 0})
    assert datasets_per_cell(runs) == {"min": 4, "max": 4, "cells": 2, "one_dataset_cells": 1}


def test_claims_md_says_which_runs_are_current():
    """The section on the runs behind each study agrees with each study's index (and so with its table)."""
    text = (ROOT / "CLAIMS.md").read_text(encoding="utf-8")
    for idx_path in ROOT.glob("*/index.json"):
        idx = json.loads(idx_path.read_text(encoding="utf-8"))
        code = idx.get("code")
        if not idx.get("claims") or not code:
            continue
        row = next((ln for ln in text.splitlines() if ln.startswith(f"| `{idx['study']}` | {code['runs']} |")), None)
        assert row is not None, idx["study"]
        assert ("every run" in row) == (code["stale"] == 0), row
