"""Verdicts with the dataset as the unit (study/figures/verdicts.py): the coefficients of one fit count once, a
failed fit is a loss, the effect comes with its interval over datasets, and "cannot tell" says how large an effect
its datasets could have seen."""
import math

import numpy as np
import pandas as pd
import pytest

from study.figures.verdicts import (dataset_errors, describe_datasets, detectable_win_rate, label_invariant,
                                    paired_datasets)


def _errors(n, ratio, spread=0.3, seed=1):
    rng = np.random.default_rng(seed)
    b = np.exp(rng.normal(-3.0, 0.5, n))
    a = b * ratio * np.exp(rng.normal(0.0, spread, n))
    return a, b


def test_a_real_effect_over_thirty_datasets_holds_with_an_interval_that_excludes_one():
    a, b = _errors(30, 0.7)
    r = paired_datasets(a, b)
    assert r["verdict"] == "holds" and r["datasets"] == 30
    assert r["ratio_low"] < r["ratio"] < r["ratio_high"] < 1.0
    assert 0.55 < r["ratio"] < 0.85
    assert "holds (" in describe_datasets(r)


def test_no_effect_cannot_tell_and_says_what_it_could_have_seen():
    a, b = _errors(40, 1.0, seed=2)
    r = paired_datasets(a, b)
    assert r["verdict"] == "cannot tell" and r["ratio_low"] < 1.0 < r["ratio_high"]
    assert 0.7 < r["detectable_ratio"] < 1.0  # forty datasets see a 10-30 % effect of this spread
    assert "power only for ratios below" in describe_datasets(r)
    # a handful of datasets cannot see anything: said so
    few = paired_datasets(a[:4], b[:4])
    assert few["verdict"] == "cannot tell" and math.isinf(few["detectable_ratio"])
    assert "no effect detectable" in describe_datasets(few)


def test_the_reverse_effect_does_not_hold():
    a, b = _errors(25, 1.5, seed=3)
    assert paired_datasets(a, b)["verdict"] == "does not hold"


def test_detectable_win_rate_falls_with_more_datasets():
    assert math.isinf(detectable_win_rate(4))  # a one-sided sign test needs 5 of 5
    rates = [detectable_win_rate(n) for n in (10, 20, 50, 200)]
    assert all(0.5 < q < 1.0 for q in rates) and rates == sorted(rates, reverse=True)


def _table(n_data=6, failing=()):
    """params of two methods on n_data datasets, 4 coefficients each; method 'a' 20 % better on every one."""
    rows, runs = [], []
    for d in range(n_data):
        for m, f in (("a", 0.8), ("b", 1.0)):
            rid = f"{m}{d}"
            status = "failed" if (m, d) in failing else "ok"
            runs.append({"run_id": rid, "status": status, "method": m, "replicate": d})
            if status == "failed":
                continue
            for k in range(4):
                rows.append({"run_id": rid, "method": m, "replicate": d, "abs_rel_error": f * (0.1 + 0.01 * k + d)})
    return pd.DataFrame(rows), pd.DataFrame(runs)


def test_one_error_per_dataset_and_a_failure_is_a_loss():
    p, runs = _table(6, failing={("a", 2)})
    e = dataset_errors(p, "method", ["replicate"], runs=runs)
    assert e.shape == (6, 2)  # the coefficients of one fit are one number
    assert np.isinf(e.loc[2, "a"]) and np.isfinite(e.loc[2, "b"])
    r = paired_datasets(e["a"], e["b"])
    assert (r["wins"], r["losses"], r["failed_a"]) == (5, 1, 1)
    # without the runs table the failure would silently drop out; with it the loss is counted
    e2 = dataset_errors(p, "method", ["replicate"])
    assert paired_datasets(e2["a"], e2["b"])["losses"] == 0


def test_exchangeable_time_constants_are_scored_without_their_labels():
    p = pd.DataFrame({"run_id": ["r"] * 3, "name": ["T1", "T2", "K"], "estimate": [5.0, 100.0, 1.0],
                      "truth": [100.0, 5.0, 1.0]})
    p["rel_error"] = (p["estimate"] - p["truth"]) / p["truth"].abs()
    p["abs_rel_error"] = p["rel_error"].abs()
    q = label_invariant(p, [("T1", "T2")])
    assert q["abs_rel_error"].max() == pytest.approx(0.0)
    assert list(q["estimate"]) == [100.0, 5.0, 1.0] and p["abs_rel_error"].max() > 10  # the input is not changed


# ------------------------------------------------------------------ one sensitivity display, failures, coverage

def _fits(n_datasets, ratio, n_coef=5, seed=0, fail_a=()):
    """params and runs of methods a and b on the same datasets (replicates): a's errors ``ratio`` times b's."""
    rng = np.random.default_rng(seed)
    p, r = [], []
    for k in range(n_datasets):
        base = np.exp(rng.normal(-3, 0.3, n_coef))
        for m, f in (("a", ratio), ("b", 1.0)):
            rid = f"{m}{k}"
            failed = m == "a" and k in fail_a
            r.append({"run_id": rid, "method": m, "cfg_x": "s", "replicate": k,
                      "status": "failed" if failed else "ok"})
            if failed:
                continue
            err = base * f * np.exp(rng.normal(0, 0.003, n_coef))
            p += [{"run_id": rid, "method": m, "cfg_x": "s", "replicate": k, "name": f"c{j}", "equation": "N",
                   "abs_rel_error": e, "scaled_error": e} for j, e in enumerate(err)]
    return pd.DataFrame(p), pd.DataFrame(r)


def test_every_choice_is_a_row_and_a_flip_is_named():
    from study.figures.verdicts import dataset_sensitivity, dataset_verdict

    p, r = _fits(25, 0.97)  # a 3 % effect: a tie within 5 %, a win within 1 %
    t = dataset_sensitivity("claim", "a vs b", p, r, "method", "a", "b", ["cfg_x"])
    assert list(t["choice"])[:3] == ["primary", "ties within 1 %", "ties within 10 %"]
    assert "coefficients as the unit (not independent)" in set(t["what"])
    assert t.iloc[0]["verdict"] == "cannot tell" and t.iloc[0]["datasets"] == 25
    assert t.set_index("what").loc["ties within 1 %", "verdict"] == "holds"
    verdict, numbers = dataset_verdict(t)
    assert verdict.startswith("cannot tell; depends on the choice: holds with") and "ties within 1 %" in verdict
    assert "flips: ties within 1 %: holds" in numbers


def test_a_failed_fit_is_a_loss_not_a_dropped_pair():
    from study.figures.verdicts import compare_datasets

    p, r = _fits(10, 0.5, fail_a=range(10))  # a better wherever it runs, but it never does
    res = compare_datasets(p, "method", "a", "b", ["cfg_x"], runs=r)
    assert res["losses"] == 10 and res["failed_a"] == 10 and res["verdict"] == "does not hold"
    ok = compare_datasets(p, "method", "a", "b", ["cfg_x"])  # without the runs the failures vanish: said why here
    assert ok["datasets"] == 0


def test_coverage_resamples_datasets_whole():
    """Intervals that miss together (every coefficient of a dataset at once) give the same share as independent
    misses but a much wider interval over datasets."""
    from study.figures.verdicts import coverage_over_datasets

    def table(joint):
        rows, rng = [], np.random.default_rng(3)
        for d in range(40):
            miss_all = rng.random() < 0.1
            for j in range(10):
                miss = miss_all if joint else rng.random() < 0.1
                rows.append({"run_id": d, "truth": 1.0, "estimate": 1.0, "ci_low": 1.1 if miss else 0.9,
                             "ci_high": 1.2})
        return pd.DataFrame(rows)

    ind, jnt = coverage_over_datasets(table(False)), coverage_over_datasets(table(True))
    assert jnt["none_covered"] >= 1 and ind["none_covered"] == 0
    assert (jnt["cov_high"] - jnt["cov_low"]) > 2 * (ind["cov_high"] - ind["cov_low"])
    assert ind["datasets"] == jnt["datasets"] == 40 and ind["intervals"] == 400


def test_a_configuration_that_draws_nothing_is_one_dataset():
    from study.commands.app import distinct_datasets

    none = {"noise": {"kind": "relative", "level": 0.0}, "maneuvers": {"train": ["zigzag_10_10"]}}
    assert distinct_datasets(none, 20) == 1
    assert distinct_datasets({**none, "noise": {"kind": "relative", "level": 0.01}}, 20) == 20
    assert distinct_datasets({**none, "noise": {"kind": "relative", "level": {"r": 0.0, "psi": 0.01}}}, 20) == 20
    assert distinct_datasets({**none, "noise": {"kind": "absolute"}}, 20) == 20
    assert distinct_datasets({**none, "maneuvers": {"train": ["random_rudder"]}}, 20) == 20
    assert distinct_datasets({**none, "noise": {"level": 0.0, "colored": {"tau": 2.0, "level": 0.01}}}, 20) == 20
