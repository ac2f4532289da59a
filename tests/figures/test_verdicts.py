"""The verdict machinery of the claims (study/figures/verdicts.py): paired sign tests with ties, and a verdict
that names what it depends on."""
from __future__ import annotations

import numpy as np
import pandas as pd

from study.figures.verdicts import compare, paired, sensitivity, settle, summary


def test_clear_wins_hold_clear_losses_do_not_and_noise_cannot_tell():
    rng = np.random.default_rng(0)
    b = rng.uniform(1, 2, 30)
    assert paired(0.5 * b, b)["verdict"] == "holds"
    assert paired(2.0 * b, b)["verdict"] == "does not hold"
    r = paired(b * rng.uniform(0.8, 1.25, 30), b)
    assert r["verdict"] == "cannot tell" and r["wins"] + r["losses"] + r["ties"] == 30


def test_ties_are_counted_not_won_and_few_pairs_cannot_tell():
    r = paired([1.0, 1.0, 1.0, 0.5], [1.02, 0.99, 1.0, 1.0])
    assert (r["wins"], r["losses"], r["ties"]) == (1, 0, 3) and r["verdict"] == "cannot tell"
    assert paired([0.1, 0.1, 0.1], [1, 1, 1])["verdict"] == "cannot tell"  # 3 of 3: p = 0.125
    r = paired([1e-9, 0.5], [2e-9, 1.0], floor=1e-6)
    assert r["ties"] == 1 and r["wins"] == 1  # both below the floor: a tie, whatever their ratio


def test_compare_pairs_the_same_coefficient_of_the_same_data_and_settle_names_the_dissent():
    rows = []
    for seed in range(10):
        for eq, names in (("Y", ["Yv", "Yr", "Yvvv"]), ("N", ["Nv", "Nr", "Nvvv"])):
            for n in names:
                for st, err in (("a", 0.1), ("b", 0.3 if n not in ("Nv", "Nvvv") else 0.01)):
                    rows.append({"seed": seed, "equation": eq, "name": n, "st": st, "err": err,
                                 "scaled": err * (0.01 if n.endswith("vvv") else 1.0)})
    p = pd.DataFrame(rows)
    r = compare(p, "st", "a", "b", ["seed"], "err")
    assert (r["pairs"], r["wins"], r["losses"]) == (60, 40, 20) and r["verdict"] == "holds"
    t = sensitivity(p, "st", "a", "b", ["seed"], [("relative error, per coefficient", None, "err", "coefficient"),
                                                    ("per equation", None, "err", "equation"),
                                                    ("only Y", p[p.equation == "Y"], "err", "coefficient")])
    assert list(t["choice"]) == ["primary", "per equation", "only Y"]
    assert settle(t) == "holds; depends on the choice: cannot tell with per equation"  # Y's median wins, N's loses
    assert summary({"kcs": "holds", "kvlcc2": "holds", "usv": "cannot tell"}) == "holds for 2 of 3 models (usv: cannot tell)"
    assert summary({"a": "holds", "b": "holds"}, "estimators") == "holds for both estimators"
    assert summary({"a": "holds", "b": "does not hold"}) == "mixed over the 2 models: holds for a; does not hold for b"
