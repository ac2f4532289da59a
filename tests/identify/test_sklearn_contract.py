"""Every discovered estimator passes scikit-learn's own estimator checks (``check_estimator``) on the installed
scikit-learn: ``clone``, ``is_regressor``, ``cross_val_score`` and pipelines work on them, and they refuse what
scikit-learn's conventions refuse (sparse, complex, empty, missing or 2-D targets) with its messages."""
import warnings

import numpy as np
import pytest

from study.configuration.compose import read_config
from study.identify.estimators import list_estimators, make_estimator


#: short chains for the sampler, a coarse penalty grid, few folds and generations: the checks are of the API (clone,
#: shapes, refusals), not of the estimate (accuracy is tested on the ship models, in test_identify.py)
FAST = {"emcee": {"target_ess": 20, "min_tau_multiple": 5, "min_steps": 40, "check_every": 40, "max_steps": 80,
                  "n_probes": 4},
        "lasso": {"alphas": [1.0e-6, 1.0e+6, 13], "cv": 3},
        "sindy": {"n_splits": 2, "thresholds": [0.001, 0.01, 0.1]},
        "de": {"maxiter": 30, "popsize": 5},
        "de_staged": {"maxiter": 30, "popsize": 5}}


@pytest.mark.parametrize("name", list_estimators())
def test_the_estimator_passes_scikit_learns_checks(name):
    from sklearn.utils.estimator_checks import check_estimator

    est = make_estimator(read_config("estimator", name), **FAST.get(name, {}))
    if est.problem_types <= {"effects"}:
        pytest.skip(f"{name} fits only models with effects (no X, y to fit): scikit-learn's checks do not apply")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = check_estimator(est, on_fail=None)
    failed = {r["check_name"]: str(r["exception"])[:200] for r in results if r["status"] == "failed"}
    assert len(results) > 40 and not failed, failed


def test_scikit_learn_sees_a_regressor_and_cross_validates_it():
    from sklearn.base import clone, is_regressor
    from sklearn.model_selection import cross_val_score

    est = make_estimator(read_config("estimator", "ridge"))
    rng = np.random.default_rng(0)
    X = rng.normal(size=(60, 3))
    y = X @ np.array([1.0, -2.0, 0.5]) + 0.01 * rng.normal(size=60)
    assert is_regressor(est) and clone(est).get_params() == est.get_params()
    assert np.all(cross_val_score(est, X, y, cv=3) > 0.99)
