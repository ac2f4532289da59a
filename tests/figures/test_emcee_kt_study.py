"""The emcee_kt study's claim on the runs' own trust flag (study/figures/studies/emcee_kt.py), on a table built
here: trusted runs that cover the truth 90 % of the time, flagged runs that miss."""
import numpy as np
import pandas as pd

from study.figures.studies import emcee_kt


def _params(structure: str, n_runs: int, covered: int, trusted) -> pd.DataFrame:
    rows = []
    for i in range(n_runs):
        hit = i < covered
        rows.append({"run_id": f"{structure}-{trusted}-{i}", "likelihood": "regression",
                     "trusted": emcee_kt._trust(trusted), "cfg_structure.name": structure,
                     "cfg_noise.name": "low_outputs_relative", "cfg_noise.sample_dt_LU": 0.0048,
                     "truth": 1.0, "ci_low": 0.9 if hit else 1.1, "ci_high": 1.2, "abs_rel_error": 0.01})
    return pd.DataFrame(rows)


def test_trusted_runs_decide_the_claim_and_flagged_runs_are_reported_beside():
    p = pd.concat([_params("central", 100, 90, True),            # calibrated: holds
                   _params("euler", 40, 36, True),               # the trusted euler runs are calibrated too
                   _params("euler", 60, 20, False),              # the flagged ones miss
                   _params("integral", 100, 60, True)],          # trusted but missing: does not hold
                  ignore_index=True)
    (c,) = emcee_kt.trust_claim(p)
    assert c["verdict"] == "holds for euler, central; does not hold for integral", c["verdict"]
    assert "60 of 100 runs flagged, their intervals 33 % covered" in c["numbers"], c["numbers"]
    t = emcee_kt.trust_table(p)
    row = t[(t["structure"] == "euler") & (t["trusted"] == "not trusted")].iloc[0]
    assert row["covered"] == 20 and row["intervals"] == 60 and row["verdict"] == "does not hold"


def test_runs_without_the_flag_are_not_run():
    p = _params("central", 10, 9, None)
    (c,) = emcee_kt.trust_claim(p)
    assert c["verdict"] == "not run"
    assert emcee_kt._trust(np.nan) == "not said" and emcee_kt._trust(np.False_) == "not trusted"


def test_the_uncorrected_regression_likelihood_is_its_own_row():
    """Runs with ``correct_rows`` false, and regression runs made before the setting existed (NaN), are the
    likelihood before the rows' errors were removed; the default and the other likelihoods keep their names."""
    row = {"cfg_structure.name": "euler", emcee_kt.LIK: "regression"}
    assert emcee_kt._likelihood({**row, emcee_kt.CORRECT: True}) == "regression"
    assert emcee_kt._likelihood({**row, emcee_kt.CORRECT: False}) == "regression_uncorrected"
    assert emcee_kt._likelihood({**row, emcee_kt.CORRECT: np.False_}) == "regression_uncorrected"
    assert emcee_kt._likelihood({**row, emcee_kt.CORRECT: np.True_}) == "regression"
    assert emcee_kt._likelihood({**row, emcee_kt.CORRECT: np.nan}) == "regression_uncorrected"
    assert emcee_kt._likelihood({**row, emcee_kt.LIK: "regression_iid", emcee_kt.CORRECT: True}) == "regression_iid"
    assert emcee_kt._likelihood({"cfg_structure.name": "output_error"}) == "output_error"
