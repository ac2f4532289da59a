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
