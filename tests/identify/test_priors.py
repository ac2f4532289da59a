"""Prior knowledge: empirical coefficients from the main particulars, the MAP estimator and emcee under a
prior, and the identifiability figure (posterior / prior standard deviation) checked against the truth."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from study.commands.app import CONF_DIR
from study.identify.priors import empirical_mmg_hull, empirical_resistance, vessel_m_nd
from study.run.pipeline import run_study
from study.configuration.compose import read_config
from study.sim import load_vessel

CFG_KEYS = {"m_x": "m_x", "m_y": "m_y", "J_z": "J_z", "Xvv": "X_vv", "Xvr": "X_vr", "Xrr": "X_rr",
            "Xvvvv": "X_vvvv", "Yv": "Y_v", "Yr": "Y_r", "Yvvv": "Y_vvv", "Yvvr": "Y_vvr", "Yvrr": "Y_vrr",
            "Yrrr": "Y_rrr", "Nv": "N_v", "Nr": "N_r", "Nvvv": "N_vvv", "Nvvr": "N_vvr", "Nvrr": "N_vrr",
            "Nrrr": "N_rrr"}


def _run(*overrides) -> dict:
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        # 1 % noise relative to each channel's RMS, as the README's table of these results states (not the
        # absolute sensor default, whose trials instruments are far more precise)
        cfg = compose(config_name="config", overrides=["noise=low_relative", *overrides])
    conf = OmegaConf.to_container(cfg, resolve=True)
    conf["progress"] = False
    return run_study(conf)


@pytest.mark.parametrize("vessel", ["kvlcc2_l7", "kcs"])
def test_empirical_linear_derivatives_and_added_masses_are_near_the_published_ones(vessel):
    """The regressions are a prior, not a truth; but for two well-known hulls their linear derivatives and added
    masses fall within 35 % of the published captive-test values (the prior's stated width for them)."""
    cfg = read_config("vessel", vessel)
    emp = empirical_mmg_hull(cfg["particulars"], vessel_m_nd(load_vessel(cfg)))
    for n in ("Yv", "Yr", "Nv", "Nr", "m_y", "J_z"):
        pub = float(cfg["hull"][CFG_KEYS[n]])
        assert abs(emp[n] - pub) <= 0.35 * abs(pub), (vessel, n, emp[n], pub)


def test_esso_osaka_has_its_own_empirical_hull_not_kvlcc2s():
    cfg = read_config("vessel", "esso_osaka")
    emp = empirical_mmg_hull(cfg["particulars"], vessel_m_nd(load_vessel(cfg)))
    for n, key in CFG_KEYS.items():
        assert float(cfg["hull"][key]) == pytest.approx(emp[n], abs=6e-4), n
    assert float(cfg["hull"]["R_0"]) == pytest.approx(
        empirical_resistance(cfg["particulars"], float(cfg["operation"]["U0"])), abs=6e-4)
    kv = read_config("vessel", "kvlcc2_l7")["hull"]
    assert sum(cfg["hull"][k] != kv[k] for k in CFG_KEYS.values()) >= 15


def test_map_identifiability_separates_determined_from_undetermined_coefficients():
    """The MMG hull of KVLCC2 from noisy zigzags and a random-rudder run, with a prior 20 % off the truth
    (alternately above and below). Where the records determine a coefficient (posterior sd under a third of the
    prior's), the estimate moved from the prior to the truth (median error under a fifth of the prior's, each
    within 3 posterior sd of the truth); where they do not (over 0.8), the error stayed of the prior's size or
    grew (median over 0.8 of it): the figure says which coefficients the records carry. The prior agrees with
    the records within its width, so it is not widened."""
    res = _run("estimator=map", "estimator.params.prior.source=offset", "estimator.params.prior.offset=0.2",
               "maneuvers.validate=[]")
    p = pd.DataFrame(res["params"])
    assert {"prior_mean", "prior_sd", "identifiability"} <= set(p.columns)
    p["err_ratio"] = (p["estimate"] - p["truth"]).abs() / (p["prior_mean"] - p["truth"]).abs()
    det = p[p["identifiability"] < 0.33]
    und = p[p["identifiability"] > 0.8]
    assert len(det) >= 4 and len(und) >= 4, p[["name", "identifiability"]]
    assert det["err_ratio"].median() < 0.2, det[["name", "estimate", "truth", "prior_mean"]]
    assert ((det["estimate"] - det["truth"]).abs() < 3 * det["std"]).all(), det[["name", "estimate", "truth", "std"]]
    assert und["err_ratio"].median() > 0.8, und[["name", "estimate", "truth", "prior_mean"]]
    assert res["metrics"]["prior_is_truth"] == 0.0 and res["metrics"]["prior_source"] == "offset"
    assert all(res["metrics"][f"est_{eq}_prior_widening"] == 1.0 for eq in "XYN")


def test_empirical_prior_beats_least_squares_on_a_turn_the_zigzags_do_not_contain():
    """KVLCC2's training records (two zigzags and random rudder at 1 % noise) leave the nonlinear hull terms
    poorly determined; least squares extrapolates them into a 35 deg turn, the empirical prior does not. Both
    are scored on the same held-out turning circle and 35/35 zigzag (mean NRMSE of u, v, r, psi)."""
    def err(res):
        m = res["metrics"]
        return float(np.mean([v for k, v in m.items() if k.startswith("val_") and "_nrmse_" in k]))

    ls = _run("estimator=ls")
    emp = _run("estimator=map", "estimator.params.prior.source=empirical")
    assert err(emp) < err(ls)
    assert res_ok(emp)


def _val_error(res) -> float:
    m = res["metrics"]
    return float(np.mean([v for k, v in m.items() if k.startswith("val_") and "_nrmse_" in k]))


# the default tier keeps the AUV; the MMG hulls and the waterjet USV (ten seconds or more each) run in the slow tier
@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c[0] != "auv" else c
                                  for c in (("kvlcc2", "mmg_hull"), ("kcs", "mmg_hull"), ("usv_waterjet", "usv_full"),
                                            ("auv", "auv"))])
def test_map_with_a_prior_20_percent_off_is_not_worse_than_least_squares_on_every_vessel_kind(case):
    """On simulated records of each vessel kind (the default training zigzags and random rudder at 1 % noise,
    validated on the held-out turn and zigzag), MAP with the default prior (the truth moved 20 %, sd 30 %) is
    not worse than least squares at predicting the held-out manoeuvres, averaged over three noise seeds.
    Measured (mean NRMSE, LS / MAP): KVLCC2 0.048 / 0.017, KCS 0.023 / 0.012, USV 0.18 / 0.12, AUV 0.020 /
    0.008. (KCS's Nomoto-1, whose derived truth is itself far from the records, is 0.903 / 0.908: equal within
    1 %, the prior widened by the records; not asserted.)"""
    vessel, model = case
    ls, mp = [], []
    for seed in range(3):
        common = [f"vessel={vessel}", f"model={model}", f"seed={seed}"]
        ls.append(_val_error(_run(*common, "estimator=ls")))
        mp.append(_val_error(_run(*common, "estimator=map")))
    assert np.isfinite(ls).all() and np.isfinite(mp).all(), (ls, mp)
    assert np.mean(mp) <= np.mean(ls), (ls, mp)


@pytest.mark.parametrize("vessel", ["kvlcc2", "kcs"])
def test_a_prior_the_records_flatly_contradict_is_widened_and_map_follows_least_squares(vessel):
    """The first-order Nomoto truth of a big hull is a linearisation (KVLCC2's T is 60,000 s, the records' 80 s);
    a prior 20 % off it is contradicted by the records, which widen it (type-II maximum likelihood) at least
    5 times, and MAP then predicts the held-out turn and zigzag within 2 % of least squares (measured: KVLCC2
    0.814 against 0.807, KCS 0.902 against 0.897; the prior is never fully discarded, so not better)."""
    common = [f"vessel={vessel}", "model=nomoto1"]
    ls = _run(*common, "estimator=ls")
    mp = _run(*common, "estimator=map")
    assert mp["metrics"]["est_N_prior_widening"] > 5.0
    assert _val_error(mp) <= 1.02 * _val_error(ls), (_val_error(mp), _val_error(ls))


def res_ok(res) -> bool:
    return all(np.isfinite(p["estimate"]) for p in res["params"])


def test_emcee_under_the_prior_agrees_with_the_map_estimate():
    """emcee samples the same posterior the MAP estimator approximates (Gaussian prior, block-robust data
    covariance): the posterior medians agree with the MAP estimates to a fraction of a posterior sd on the
    AUV's yaw equation."""
    common = ["case=auv", "maneuvers.validate=[]"]
    m = pd.DataFrame(_run("estimator=map", "estimator.params.prior.source=offset", *common)["params"])
    e = pd.DataFrame(_run("estimator=emcee", "estimator.params.target_ess=400",
                          "estimator.params.prior={source: offset, sd: 0.3, offset: 0.2}", *common)["params"])
    m, e = m.set_index("name"), e.set_index("name").loc[m["name"]]
    assert (np.abs(e["estimate"] - m["estimate"]) < 0.5 * m["std"] + 1e-12).mean() >= 0.9
    assert np.allclose(e["identifiability"], m["identifiability"], rtol=0.15)


def test_doctor_reports_which_coefficients_the_records_determine():
    """The doctor's anchored hull (prior 20 % off the truth) on clean-ish zigzags and random rudder: the linear
    yaw derivatives come out determined and near the truth, and the report names some nonlinear term as not
    determined, in a plain sentence."""
    from doctor_cases import MMG_HULL, make_records, perturbed_prior
    from study.identify.with_effects import EffectsProblem, identify_effects

    train, _, truth_cfg = make_records({}, duration=200.0)
    prior_cfg = perturbed_prior(truth_cfg, MMG_HULL, 0.2)
    P = EffectsProblem(prior_cfg, MMG_HULL, train, anchor=0.3)
    rows = {r["coefficient"]: r for r in P.identifiability(identify_effects(P))}
    truth = load_vessel(truth_cfg)
    for n in ("Nv", "Nr", "Yv"):
        assert rows[n]["ratio"] < 0.5, rows[n]
        t = float(truth.params[truth.param_names.index(n)])
        assert abs(rows[n]["estimate"] - t) < 0.5 * abs(rows[n]["prior"] - t), rows[n]
    und = [r for r in rows.values() if r["ratio"] > 0.9]
    assert und and all("NOT determined" in r["sentence"] for r in und)


def _replicates(kind: str, reps: int = 200, n: int = 3000, dt: float = 0.1, seed: int = 1):
    """Least-squares estimates and their block-robust standard errors over replicated records of a smooth
    three-term regression with residuals of one kind."""
    from scipy.signal import lfilter

    from study.identify.estimators.prior import data_covariance

    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    X = np.column_stack([np.sin(0.05 * t), np.cos(0.031 * t) * np.sin(0.011 * t + 1), np.sin(0.05 * t) ** 3])
    theta = np.array([1.0, -0.5, 0.3])
    est, se = [], []
    for _ in range(reps):
        if kind == "differenced":  # a central difference of white noise, as a measured derivative has
            m = rng.normal(0, 0.01, n + 2)
            e = (m[2:] - m[:-2]) / (2 * dt) + rng.normal(0, 0.002, n)
        elif kind == "ar1":  # a slowly varying misfit, as a model error gives
            e = lfilter([1.0], [1.0, -0.98], rng.normal(0, 0.01, n))
        else:
            e = rng.normal(0, 0.05, n)
        b, V, _ = data_covariance(X, X @ theta + e)
        est.append(b)
        se.append(np.sqrt(np.diag(V)))
    return np.mean(se, axis=0) / np.std(est, axis=0)


@pytest.mark.parametrize("kind", ["white", "ar1"])
def test_data_covariance_is_calibrated_for_white_and_slowly_correlated_residuals(kind):
    """The records' covariance (consecutive blocks, cluster-robust) states the spread of the estimates over
    replicated records: mean standard error / actual spread within 0.6-1.5 for white residuals and for an AR(1)
    misfit correlated over ~50 samples (where counting rows as independent understates it 8-11 times)."""
    ratio = _replicates(kind)
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio


def test_data_covariance_never_understates_differenced_noise():
    """Central differences of white noise cancel when summed; the block covariance sees the cancellation inside
    each block but not across the block edges, so it overstates the spread (by 1.3-3.7 times on this smooth
    synthetic case, 1.1-1.3 on simulated KVLCC2 and KCS hulls), and never understates it."""
    ratio = _replicates("differenced")
    assert np.all(ratio > 0.9), ratio


def test_prior_widening_is_one_when_the_records_agree_and_large_when_they_contradict():
    """Empirical Bayes on the prior's width: a prior within its stated sd of the records' estimate is kept as
    stated; one 20 sd away is widened (at least 5 times), and the MAP estimate then follows the records."""
    from study.identify.estimators.prior import gaussian_posterior

    rng = np.random.default_rng(0)
    X = rng.normal(size=(2000, 3))
    theta = np.array([1.0, -2.0, 0.5])
    y = X @ theta + rng.normal(0, 0.1, 2000)
    sd0 = np.full(3, 0.05)
    m, _, d = gaussian_posterior(X, y, theta + 0.5 * sd0 * np.array([1, -1, 1]), sd0)
    assert d["prior_widening"] == 1.0
    m, _, d = gaussian_posterior(X, y, theta + 20 * sd0 * np.array([1, -1, 1]), sd0)
    assert d["prior_widening"] > 5.0
    assert np.all(np.abs(m - theta) < 0.1 * 20 * sd0), m
    m, _, d = gaussian_posterior(X, y, theta + 20 * sd0 * np.array([1, -1, 1]), sd0, widen=False)
    assert d["prior_widening"] == 1.0


def test_rounding_in_the_records_null_space_is_not_inverted_into_a_precision(monkeypatch):
    # a block-robust covariance of 2 blocks has rank 1; what a BLAS kernel leaves in its null space (here -1.2e-15
    # and 7e-16 of the largest eigenvalue, as measured on one) must count as "not determined", whatever its sign
    from study.identify.estimators import prior

    rng = np.random.default_rng(0)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    cov = Q @ np.diag([0.28, -1.2e-15 * 0.28, 7e-16 * 0.28]) @ Q.T
    monkeypatch.setattr(prior, "data_covariance", lambda Z, y: (np.zeros(3), cov, 2))
    X = rng.uniform(size=(10, 3))
    mean, post_cov, _ = prior.gaussian_posterior(X, rng.normal(size=10), np.zeros(3), np.full(3, np.inf), widen=False)
    assert np.all(np.isfinite(mean)) and np.all(np.linalg.eigvalsh(post_cov) > 0)
    # the determined direction keeps the records' variance; the two others are left open (the flat prior's)
    s = np.sqrt(np.mean(X * X, axis=0))
    v = np.linalg.eigvalsh(post_cov * np.outer(s, s))
    assert v[-1] > 1e6 * 0.28 and abs(v[0] - 0.28) < 1e-3 * 0.28  # (eigvalsh beside 1e12: about 1e-4 absolute)
