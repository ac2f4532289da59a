"""Metrics that mean what they say: each coefficient's error scaled by its term's weight in the
equation, per-equation drift metrics, and the prior and identifiability columns of a prior-anchored fit, all in
the results table itself (not only in the run's record)."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest


def _table(tmp_path, *overrides) -> tuple[pd.DataFrame, pd.DataFrame]:
    tmp_path.mkdir(parents=True, exist_ok=True)
    res = tmp_path / "results"
    p = subprocess.run([sys.executable, "-m", "study", "experiment=tiny", "progress=false", *overrides],
                       cwd=tmp_path, env=dict(os.environ, STUDY_RESULTS_DIR=str(res), OPENBLAS_NUM_THREADS="1"),
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    runs, params = pd.read_parquet(res / "runs.parquet"), pd.read_parquet(res / "params.parquet")
    assert (runs["status"] == "ok").all(), runs["error"].tolist()
    return runs, params


@pytest.mark.slow
def test_scaled_error_is_the_error_times_the_terms_weight_and_tames_near_zero_truths(tmp_path):
    runs, p = _table(tmp_path, "vessel=mariner", "model=abkowitz")
    q = p[p["truth_kind"] == "exact"]
    assert len(q) == len(p) and q["term_scale"].notna().all() and (q["term_scale"] > 0).all()
    np.testing.assert_allclose(q["scaled_error"], (q["estimate"] - q["truth"]).abs() * q["term_scale"], rtol=1e-12)
    # the Abkowitz Mariner has many near-zero coefficients whose terms hardly act: relative errors of 100 % and
    # more while each error moves its equation by a few % of the equation's own size
    assert q["rel_error"].abs().median() > 0.3
    assert q["scaled_error"].median() < 0.1 * q["rel_error"].abs().median()
    for eq in ("X", "Y", "N"):
        assert runs[f"m_scaled_drift_median_{eq}"].iloc[0] == pytest.approx(q.loc[q.equation == eq,
                                                                                  "scaled_error"].median())
        assert np.isfinite(runs[f"m_drift_median_{eq}"].iloc[0])


@pytest.mark.slow
def test_nomoto_parameters_have_no_term_scale(tmp_path):
    """K, T, ... are not regression columns: no scaled error is made up for them."""
    _, p = _table(tmp_path, "vessel=kt1_mariner", "model=nomoto1")
    assert len(p) and p["scaled_error"].isna().all() and p["rel_error"].notna().all()


@pytest.mark.slow
def test_prior_columns_reach_the_params_table(tmp_path):
    _, p = _table(tmp_path, "estimator=map")
    assert {"prior_mean", "prior_sd", "identifiability"} <= set(p.columns)
    assert p["prior_mean"].notna().all() and (p["prior_sd"] > 0).all()
    assert ((p["identifiability"] > 0) & (p["identifiability"] <= 1.0 + 1e-9)).all()


@pytest.mark.slow
def test_sampling_interval_in_the_ships_time_scale_is_decimated_and_reported(tmp_path):
    """noise.sample_dt_LU: the interval in units of L/U0, rounded to whole simulation steps; every run reports its
    interval in seconds and in L/U0."""
    runs, _ = _table(tmp_path, "vessel=kvlcc2", "noise=low", "noise.sample_dt_LU=0.02")
    r = runs.iloc[0]
    from study.sim import load_vessel

    v = load_vessel("kvlcc2")
    T = float(v.cfg["particulars"]["Lpp"]) / v.U0
    assert r["m_sample_dt"] == pytest.approx(round(0.02 * T / 0.1) * 0.1, abs=1e-9)  # whole steps of 0.1 s
    assert r["m_sample_dt_LU"] == pytest.approx(r["m_sample_dt"] / T)
    assert abs(r["m_sample_dt_LU"] - 0.02) < 0.5 * 0.1 / T  # within half a step of what was asked
    runs2, _ = _table(tmp_path / "b", "vessel=kvlcc2", "noise=low")
    assert runs2["m_sample_dt"].iloc[0] == pytest.approx(0.1)  # default: every integration step
    assert runs2["m_n_samples"].iloc[0] > 5 * r["m_n_samples"]


def test_both_sampling_settings_is_an_error_naming_them(tmp_path):
    res = tmp_path / "results"
    p = subprocess.run([sys.executable, "-m", "study", "experiment=tiny", "progress=false", "noise.sample_dt=0.5",
                        "noise.sample_dt_LU=0.01"], cwd=tmp_path,
                       env=dict(os.environ, STUDY_RESULTS_DIR=str(res)), capture_output=True, text=True, timeout=600)
    # refused before any work, in one line, nothing written (the settings are checked against each other first)
    assert p.returncode == 2 and not res.exists() and not any(tmp_path.iterdir())
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert lines == ["study: error: noise.sample_dt=0.5 and noise.sample_dt_LU=0.01: expected one of them (the other "
                     "null)"], p.stderr


def test_a_second_order_model_of_a_first_order_truth_is_degenerate_not_exact():
    from study.identify.models import make_model
    from study.configuration.compose import read_config
    from study.sim import load_vessel

    truth, how, exact = make_model(read_config("model", "nomoto2_nl"), load_vessel("kt1_mariner")).truth()
    assert not exact and how.startswith("degenerate") and truth["T2"] == 0.0
    _, how1, exact1 = make_model(read_config("model", "nomoto1_nl"), load_vessel("kt1_mariner")).truth()
    assert exact1 and how1.startswith("exact")
    _, _, exact2 = make_model(read_config("model", "nomoto2_nl"), load_vessel("kt_mariner")).truth()
    assert exact2
