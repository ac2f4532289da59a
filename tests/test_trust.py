"""The trust verdict of an emcee regression run (study/identify/trust.py): a residual that is not white, after the
fitted noise model's whitening, is no noise the intervals cover."""
from study.identify.trust import ACF_LIMIT, run_verdict, whiteness


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
