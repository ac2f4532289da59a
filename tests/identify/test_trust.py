"""The trust verdict of an emcee regression run (study/identify/trust.py): a residual that is not white, after the
fitted noise model's whitening, is no noise the intervals cover; coefficients that differ where the states are small
and where they are large, or monomials of the states the model leaves out that explain its residual, say the model
lacks a term."""
import numpy as np
import pytest
from scipy import stats

from study.identify.trust import (ACF_LIMIT, HETEROGENEITY_P, NOISE_FREE_GAP, OMITTED_TERMS_P, heterogeneity, omitted_terms, range_key,
                                  run_verdict, whiteness)


def test_a_white_residual_leaves_the_truncation_verdict_alone():
    ok, note = run_verdict("regression", "central", {"K": 0.1}, 0, True,
                           {"est_N_whitened_acf1": 0.01, "est_N_whitened_acf2": -0.02})
    assert ok and "intervals trusted" in note


def test_a_residual_that_is_not_white_is_flagged_naming_equation_and_lag():
    m = {"est_X_whitened_acf1": 0.02, "est_N_whitened_acf1": -0.34, "est_N_whitened_acf2": 0.05}
    assert whiteness(m) == ("N", "1", -0.34)
    ok, note = run_verdict("regression", "central", {"K": 0.1}, 0, True, m)
    assert not ok and "lag-1 autocorrelation -0.34 in equation N" in note


def test_the_limit_is_an_effect_size_on_either_side():
    for v in (ACF_LIMIT * 1.01, -ACF_LIMIT * 1.01):
        assert not run_verdict("regression", "euler", {}, 0, True, {"est_Y_whitened_acf2": v})[0]
    assert run_verdict("regression", "euler", {}, 0, True, {"est_Y_whitened_acf2": ACF_LIMIT * 0.99})[0]


def test_the_iid_likelihood_is_never_trusted_whatever_its_residual():
    assert not run_verdict("regression_iid", "central", {}, 0, False, {"est_N_whitened_acf1": 0.0})[0]


def _rows(seed: int, missing: float, n: int = 4000):
    """Rows of y = 1.0 v - 0.5 r + 0.3 v^3 (+ ``missing`` v^2 r, a term the model lacks) + white noise, for a model
    with v, r and v^3 only: the missing term is absorbed by the others, unequally across their range."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 200, n)
    v = 0.4 * np.sin(0.11 * t) + 0.1 * rng.standard_normal(n)
    r = 0.5 * np.sin(0.11 * t + 0.8) + 0.1 * rng.standard_normal(n)
    X = np.column_stack([v, r, v ** 3])
    y = X @ np.array([1.0, -0.5, 0.3]) + missing * v ** 2 * r + 0.05 * rng.standard_normal(n)
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    return X, y, X @ beta


def test_heterogeneity_is_a_calibrated_test_where_the_model_holds():
    tails = [heterogeneity(*_rows(s, 0.0))[1] for s in range(200)]
    # uniform where the model holds: about 10 % of the tails below 0.1, none below the flag's 0.1 %
    assert 0.04 < np.mean(np.array(tails) < 0.1) < 0.18
    assert stats.kstest(tails, "uniform").pvalue > 1e-3


def test_heterogeneity_finds_a_missing_term_the_residual_does_not_show():
    per_dof, tail = heterogeneity(*_rows(0, 2.0))
    assert per_dof > 5 and tail < HETEROGENEITY_P


def test_heterogeneity_needs_more_rows_than_coefficients_in_each_group():
    X, y, f = _rows(0, 0.0, n=10)
    assert all(np.isnan(heterogeneity(X, y, f)))


def test_a_heterogeneous_run_is_flagged_naming_its_equation():
    m = {"est_N_whitened_acf1": 0.01, "est_N_heterogeneity": 3.9, "est_N_heterogeneity_p": 1e-9,
         "est_Y_heterogeneity": 1.1, "est_Y_heterogeneity_p": 0.3}
    ok, note = run_verdict("regression", "central", {"K": 0.1}, 0, True, m)
    assert not ok and "chi-square 3.90 per degree of freedom in equation N" in note


@pytest.mark.parametrize("tail, trusted", [(HETEROGENEITY_P * 0.99, False), (HETEROGENEITY_P * 1.01, True)])
def test_the_heterogeneity_flag_is_the_test_level(tail, trusted):
    m = {"est_X_heterogeneity": 2.0, "est_X_heterogeneity_p": tail}
    assert run_verdict("regression", "central", {}, 0, True, m)[0] is trusted


def test_a_rows_place_in_the_range_carries_none_of_the_noise_it_shares():
    """range_key: a row's key is its neighbours' mean |fitted value|, beyond the rows whose noise it shares; changing
    the row and those within ``shared`` of it leaves its key alone, changing a neighbour beyond them does not."""
    rng = np.random.default_rng(3)
    f = rng.standard_normal(60)
    key = range_key(f, shared=2, rows=5)
    assert key[30] == pytest.approx(np.mean(np.abs(np.r_[f[23:28], f[33:38]])))
    g = f.copy()
    g[28:33] += 100.0  # the row itself and the rows sharing its noise
    assert range_key(g, shared=2, rows=5)[30] == pytest.approx(key[30])
    g[33] += 100.0
    assert range_key(g, shared=2, rows=5)[30] != pytest.approx(key[30])


def _neighbours(X: np.ndarray) -> tuple[np.ndarray, list]:
    """The monomials of v and r up to degree 3 that ``_rows``'s model (v, r, v^3) lacks."""
    v, r = X[:, 0], X[:, 1]
    names = ["v^2", "v*r", "r^2", "v^2*r", "v*r^2", "r^3"]
    return np.column_stack([v ** 2, v * r, r ** 2, v ** 2 * r, v * r ** 2, r ** 3]), names


@pytest.mark.slow
def test_the_omitted_terms_test_is_calibrated_where_the_model_holds():
    tails = []
    for s in range(200):
        X, y, _ = _rows(s, 0.0)
        tails.append(omitted_terms(X, _neighbours(X)[0], y)[1])
    assert 0.04 < np.mean(np.array(tails) < 0.1) < 0.18
    assert stats.kstest(tails, "uniform").pvalue > 1e-3


def test_the_omitted_terms_test_finds_a_term_the_heterogeneity_check_misses():
    """A missing term small enough for the groups of the heterogeneity check to agree on most datasets is still
    wanted by the residual, and named, on most of 20 datasets (measured: the heterogeneity check flags 2, this
    test 13, and names v^2 r on 18)."""
    het, flagged, named = 0, 0, 0
    for s in range(20):
        X, y, f = _rows(s, 0.2)
        het += heterogeneity(X, y, f)[1] < HETEROGENEITY_P
        Z, names = _neighbours(X)
        _, tail, top = omitted_terms(X, Z, y, names=names)
        flagged += tail < OMITTED_TERMS_P
        named += top == "v^2*r"
    assert het <= 5 and flagged >= 10 and named >= 15, (het, flagged, named)


def test_the_omitted_terms_test_needs_a_column_the_model_does_not_span():
    X, y, _ = _rows(0, 0.0)
    assert all(np.isnan(omitted_terms(X, X[:, :0], y)[:2]))
    assert all(np.isnan(omitted_terms(X, 2.0 * X[:, :1], y)[:2]))  # a copy of a model column adds nothing


def test_a_run_whose_records_ask_for_a_term_is_flagged_naming_it():
    m = {"est_N_whitened_acf1": 0.01, "est_N_heterogeneity_p": 0.2, "est_N_omitted_terms": 5.9,
         "est_N_omitted_terms_p": 2e-10, "est_N_omitted_terms_top": "v'^2*r'",
         "est_Y_omitted_terms": 1.4, "est_Y_omitted_terms_p": 0.14}
    ok, note = run_verdict("regression", "central", {"K": 0.1}, 0, True, m)
    assert not ok and "5.90 per degree of freedom in equation N" in note and "v'^2*r'" in note


@pytest.mark.parametrize("tail, trusted", [(OMITTED_TERMS_P * 0.99, False), (OMITTED_TERMS_P * 1.01, True)])
def test_the_omitted_terms_flag_is_the_test_level(tail, trusted):
    m = {"est_X_omitted_terms": 2.0, "est_X_omitted_terms_p": tail}
    assert run_verdict("regression", "central", {}, 0, True, m)[0] is trusted


def test_rows_without_noise_are_not_trusted_whatever_their_residual_looks_like():
    """Noise-free records: the rows fit to numerical error, which the intervals would measure; the note names the
    equation. Rows with noise at the limit pass."""
    m = {"fit_r2_X": 1 - 3e-6, "fit_r2_N": 0.98, "est_X_whitened_acf1": 0.01}
    ok, note = run_verdict("regression", "central", {"K": 0.1}, 0, True, m)
    assert not ok and "equation X fit to within 3.0e-06" in note and "cannot tell" in note
    m["fit_r2_X"] = 1 - NOISE_FREE_GAP * 1.01
    assert run_verdict("regression", "central", {"K": 0.1}, 0, True, m)[0]
