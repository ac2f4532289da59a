"""The arithmetic of a predicted metric's interval (study/doctor/prediction_interval.py) and the sensitivity
ranking and carriers (study/doctor/model_error.py, study/doctor/predictions.py), on numbers whose answer is known."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from study.doctor import model_error as me
from study.doctor import prediction_interval as pi
from study.doctor.predictions import carriers, extrapolation_text, metric_interval

Z90 = 1.6448536269514722


def frame(v, r, U=1.0, delta=0.0, L=1.0) -> pd.DataFrame:
    """A frame at speed U whose states are v' = v and r' = r (u = U sqrt(1 - v'^2))."""
    n = len(np.atleast_1d(v))
    U = np.broadcast_to(U, n).astype(float)
    v = np.broadcast_to(v, n).astype(float)
    return pd.DataFrame({"time": np.arange(n, dtype=float), "u": U * np.sqrt(1.0 - v ** 2), "v": U * v,
                         "r": np.broadcast_to(r, n) * U / L, "delta": np.broadcast_to(delta, n)})


# ------------------------------------------------------------------------------------------- combination
def test_identification_and_form_add_in_quadrature_and_the_form_is_counted_once():
    got = pi.combine(2.0, 0.03, 0.04, 0.0, level=0.9)
    assert got["log_sd"] == pytest.approx(0.05)
    assert got["low"] == pytest.approx(2.0 * math.exp(-Z90 * 0.05))
    assert got["high"] == pytest.approx(2.0 * math.exp(Z90 * 0.05))
    assert got["half_width"] == pytest.approx(math.exp(Z90 * 0.05) - 1.0)
    assert got["low"] * got["high"] == pytest.approx(4.0)  # symmetric in the log
    # the structural spread and the held-out error estimate the same error of the form: the larger counts
    wider = pi.combine(2.0, 0.03, 0.04, 0.12)
    assert wider["log_sd"] == pytest.approx(math.hypot(0.03, 0.12)) and wider["high"] > got["high"]
    assert pi.combine(2.0, 0.03, 0.12, 0.04)["log_sd"] == pytest.approx(wider["log_sd"])
    assert pi.combine(2.0, 0.03, 0.04, 0.12)["log_sd"] < math.sqrt(0.03 ** 2 + 0.04 ** 2 + 0.12 ** 2)


def test_growth_is_net_of_the_held_out_predictions_own_identification_spread():
    d = np.array([0.0, 0.0, 0.2, 0.5, 1.0])
    form = np.sqrt(0.03 ** 2 + (0.1 * d) ** 2)
    own = np.array([0.04, 0.02, 0.05, 0.03, 0.06])
    g = pi.fit_growth(d, np.sqrt(form ** 2 + own ** 2), own)
    assert g["sigma0"] == pytest.approx(0.03, rel=1e-6) and g["k"] == pytest.approx(0.1, rel=1e-6)
    whole = pi.fit_growth(d, np.sqrt(form ** 2 + own ** 2))  # without it the spread is counted in the floor
    assert whole["sigma0"] > 0.04
    # unknown spreads (NaN) are not taken out: the wide side
    g_nan = pi.fit_growth(d, np.sqrt(form ** 2 + own ** 2), np.full(5, np.nan))
    assert g_nan["sigma0"] == pytest.approx(whole["sigma0"]) and g_nan["k"] == pytest.approx(whole["k"])
    with pytest.raises(ValueError, match="differ in length"):
        pi.fit_growth(d, form, own[:3])


def test_a_component_that_could_not_be_measured_gives_no_interval_rather_than_a_narrow_one():
    assert math.isnan(pi.combine(2.0, math.nan, 0.01, 0.01)["low"])
    assert math.isnan(pi.combine(2.0, 0.01, 0.01, math.nan)["high"])
    assert math.isnan(pi.combine(-1.0, 0.01, 0.01, 0.01)["low"])  # the log scale needs a positive value
    assert math.isnan(pi.combine(0.0, 0.01, 0.01, 0.01)["high"])


def test_level_must_be_a_fraction():
    assert pi.z_of(0.9) == pytest.approx(Z90)
    with pytest.raises(ValueError, match="level=90"):
        pi.z_of(90)


def test_draws_spread_is_the_lognormal_sd_and_is_refused_when_most_draws_failed():
    rng = np.random.default_rng(0)
    draws = 3.0 * np.exp(0.05 * rng.standard_normal(4000))
    s, n = pi.draws_log_sd(draws)
    assert n == 4000 and s == pytest.approx(0.05, rel=0.05)
    half_failed = np.where(np.arange(4000) < 2100, np.nan, draws)
    s2, n2 = pi.draws_log_sd(half_failed)
    assert n2 == 1900 and math.isnan(s2)


def test_structural_spread_is_the_rms_log_deviation_from_the_chosen_model():
    s, n = pi.structural_log_sd(2.0, [2.0 * math.e ** 0.1, 2.0 * math.e ** -0.1, np.nan, -1.0])
    assert n == 2 and s == pytest.approx(0.1)
    assert pi.structural_log_sd(2.0, []) == (0.0, 0)


def test_growth_recovers_floor_and_slope_from_exact_pairs():
    d = np.array([0.0, 0.0, 0.2, 0.5, 1.0])
    e = np.sqrt(0.03 ** 2 + (0.1 * d) ** 2)
    g = pi.fit_growth(d, e)
    assert g["sigma0"] == pytest.approx(0.03, rel=1e-6) and g["k"] == pytest.approx(0.1, rel=1e-6)
    assert g["n"] == 5 and g["d_max"] == 1.0
    assert pi.extrapolation_log_sd(2.0, g) == pytest.approx(math.hypot(0.03, 0.2))
    assert pi.extrapolation_log_sd(-1.0, g) == pytest.approx(0.03)  # inside the envelope: the floor


def test_growth_is_not_invented_without_a_pair_outside_the_envelope():
    g = pi.fit_growth([0.0, 0.0, 0.0], [0.02, 0.04, 0.03])
    assert g["k"] == 0.0 and "not measured" in g["note"]
    assert g["sigma0"] == pytest.approx(math.sqrt(np.mean(np.square([0.02, 0.04, 0.03]))))
    none = pi.fit_growth([], [])
    assert math.isnan(none["sigma0"]) and none["n"] == 0
    with pytest.raises(ValueError, match="differ in length"):
        pi.fit_growth([0.1, 0.2], [0.1])


def test_metric_interval_says_why_it_has_none():
    g = {"sigma0": 0.02, "k": 0.1, "source": "x"}
    ok = metric_interval(3.0, 3.0 * np.exp(0.01 * np.random.default_rng(1).standard_normal(64)), [3.1], 0.5, g)
    assert ok["why"] is None and ok["low"] < 3.0 < ok["high"] and ok["alternatives"] == 1
    assert ok["s_extrap"] == pytest.approx(math.hypot(0.02, 0.05))
    failed = metric_interval(3.0, [np.nan] * 60 + [3.0] * 4, [], 0.0, g)
    assert math.isnan(failed["low"]) and "4 of 64" in failed["why"]
    nocal = metric_interval(3.0, [], [], 0.0, {"sigma0": math.nan, "k": math.nan, "note": "too few records"})
    assert math.isnan(nocal["high"]) and nocal["why"] == "too few records"


# ------------------------------------------------------------------------------------------- envelope
def test_envelope_is_the_99th_percentile_and_slow_samples_hardly_count():
    v = np.linspace(0.0, 0.3, 1001)
    env = pi.state_envelope(frame(v, 0.5 * v), L=1.0, U0=1.0)
    assert env["v'"] == pytest.approx(0.297, abs=0.002) and env["r'"] == pytest.approx(0.1485, abs=0.002)
    assert env["drift_deg"] == pytest.approx(math.degrees(math.asin(0.297)), abs=0.2)
    # the same with a slow stretch at large drift: weighted by (U/U0)^4 it moves the envelope little
    slow = frame(np.full(200, 0.9), 0.0, U=0.2)
    both = pi.state_envelope([frame(v, 0.5 * v), slow], L=1.0, U0=1.0)
    assert both["v'"] < 0.32
    with pytest.raises(ValueError, match="must be positive"):
        pi.state_envelope(frame(v, v), L=0.0, U0=1.0)


def test_distance_is_the_largest_relative_excess_and_zero_inside():
    train = {"v'": 0.2, "r'": 0.5, "drift_deg": 12.0, "rudder_deg": 20.0}
    far = pi.envelope_distance({"v'": 0.3, "r'": 0.6, "drift_deg": 10.0, "rudder_deg": 35.0}, train)
    assert far["distance"] == pytest.approx(0.75) and far["state"] == "rudder_deg"
    assert far["excess"]["v'"] == pytest.approx(0.5) and far["excess"]["drift_deg"] == 0.0
    inside = pi.envelope_distance({"v'": 0.1, "r'": 0.2, "drift_deg": 5.0, "rudder_deg": 10.0}, train)
    assert inside["distance"] == 0.0 and inside["state"] is None
    unknown = pi.envelope_distance({"v'": math.nan}, {"v'": 0.2})
    assert math.isnan(unknown["distance"])
    assert extrapolation_text(far, {"v'": 0.3, "r'": 0.6, "drift_deg": 10.0, "rudder_deg": 35.0},
                              train).startswith("EXTRAPOLATES")
    edge = pi.envelope_distance({"v'": 0.204}, train)
    assert extrapolation_text(edge, {"v'": 0.204}, train) == "at the edge of the training envelope"


def test_coefficient_names_give_the_state_product_they_multiply():
    assert pi.monomial_of("Yvvr") == "vvr" and pi.monomial_of("Nrar") == "rr" and pi.monomial_of("Xdd") == "dd"
    assert pi.monomial_of("Nv") == "v"
    for name in ("R0", "tR", "wind_factor_N", "Xu", "yaw_bias_N"):
        assert pi.monomial_of(name) is None, name
    f = frame(np.array([0.1, 0.2]), np.array([0.5, 1.0]))
    vals, _ = pi.monomial_values(f, "vvr", 1.0, 1.0)
    assert vals == pytest.approx([0.1 ** 2 * 0.5, 0.2 ** 2 * 1.0], rel=1e-6)


# ------------------------------------------------------------------------------------------- sensitivity
def table(*rows, estimates=None):
    est = estimates or [1.0] * len(rows)
    return [{"coefficient": n, "estimate": x, "sd": sd, "anchor": a, "ratio": ratio}
            for (n, sd, a, ratio), x in zip(rows, est)]


def test_sensitivities_rank_by_share_of_variance_and_give_the_reset_shift():
    t = table(("Nv", 0.1, 0.8, 0.1), ("Nvvr", 0.2, 1.5, 0.6), ("wind_factor_N", 0.3, None, None))
    # metric = 10 + 2 Nv + 5 Nvvr + 0 wind; members: +sd, -sd, reset per coefficient (value 17 at the estimates)
    vals = [17 + 0.2, 17 - 0.2, 17 + 2 * (0.8 - 1.0),
            17 + 1.0, 17 - 1.0, 17 + 5 * (1.5 - 1.0),
            17.0, 17.0, 17.0]
    rows = me.sensitivities(t, 17.0, vals)
    assert [r["coefficient"] for r in rows] == ["Nvvr", "Nv", "wind_factor_N"]
    assert rows[0]["share"] == pytest.approx(1.0 / 1.04) and rows[1]["share"] == pytest.approx(0.04 / 1.04)
    assert rows[0]["per_sd"] == pytest.approx(1.0) and rows[0]["reset"] == pytest.approx(2.5)
    assert rows[1]["reset"] == pytest.approx(-0.4) and math.isnan(rows[2]["reset"])
    with pytest.raises(ValueError, match="three per coefficient"):
        me.sensitivities(t, 17.0, vals[:-1])


def test_sensitivity_members_move_one_coefficient_at_a_time():
    post = {"names": ["a", "b"], "mean": np.array([1.0, 2.0])}
    sets = me.sensitivity_sets(post, table(("a", 0.1, 0.5, 0.2), ("b", 0.3, None, None), estimates=[1.0, 2.0]))
    want = [{"a": 1.1, "b": 2.0}, {"a": 0.9, "b": 2.0}, {"a": 0.5, "b": 2.0},
            {"a": 1.0, "b": 2.3}, {"a": 1.0, "b": 1.7}, {"a": 1.0, "b": 2.0}]
    assert [{k: pytest.approx(v) for k, v in w.items()} for w in want] == sets


def test_carriers_name_the_big_shares_and_a_determined_coefficient_that_moves_the_prediction_far():
    training = frame(np.linspace(0, 0.2, 200), np.linspace(0, 0.5, 200))
    turn = frame(np.full(200, 0.4), np.full(200, 0.9))
    rows = [{"coefficient": "Nvvr", "share": 0.6, "per_sd": 0.1, "reset": 0.05, "ratio": 0.3},
            {"coefficient": "Nrrr", "share": 0.37, "per_sd": 0.08, "reset": 0.01, "ratio": 0.95},
            {"coefficient": "Nv", "share": 0.02, "per_sd": 0.01, "reset": 0.7, "ratio": 0.05},
            {"coefficient": "R0", "share": 0.01, "per_sd": 0.005, "reset": 0.01, "ratio": 0.1}]
    got = {c["coefficient"]: c for c in carriers(rows, turn, training, 1.0, 1.0, "L", half_width=0.2)}
    assert list(got) == ["Nvvr", "Nrrr", "Nv"]  # R0: neither a share nor a move beyond the interval
    assert got["Nvvr"]["reach_ratio"] > 5 and not got["Nvvr"]["determined"]  # determined, but not out there
    assert "extrapolated" in got["Nvvr"]["sentence"] and "determined by the records" in got["Nvvr"]["sentence"]
    assert "NOT determined" in got["Nrrr"]["sentence"]
    assert "more than the interval's half-width" in got["Nv"]["sentence"] and "+0.7 L" in got["Nv"]["sentence"]


def test_splits_train_the_gentler_half_and_leave_each_record_out():
    envs = [{"v'": x, "r'": x, "drift_deg": 10 * x, "rudder_deg": 20.0} for x in (0.3, 0.1, 0.2, math.nan)]
    s = me.splits(envs)
    # ranked by the mean relative reach over the states (the rudder's is the same for all): 3 (none), 1, 2, 0
    assert s[0][0].startswith("gentler") and sorted(s[0][1]) == [1, 3] and sorted(s[0][2]) == [0, 2]
    loo = s[1:]
    assert len(loo) == 4 and all(len(te) == 1 and len(tr) == 3 and te[0] not in tr for _, tr, te in loo)
    assert me.splits(envs[:1]) == []


def test_growth_for_a_metric_no_record_carries_falls_back_to_the_yaw_rate_and_counts_divergence():
    cal = {"pairs": [{"distance": 0.0, "errors": {"rms_yaw_rate": 0.02, "first_overshoot": 0.5}},
                     {"distance": 0.4, "errors": {"rms_yaw_rate": 0.06}},
                     {"distance": math.nan, "errors": {}, "diverged": True}]}
    td = me.growth_for(cal, "tactical_diameter_L")
    assert td["source"] == "rms_yaw_rate" and td["n"] == 3  # two pairs and the divergence at the farthest distance
    assert td["k"] > 0 and td["net_of_own"] == 0
    # a pair's own identification spread comes out of its squared error; a divergence keeps its whole error
    cal["pairs"][0]["own_sd"] = {"rms_yaw_rate": 0.02}
    cal["pairs"][1]["own_sd"] = {"rms_yaw_rate": 0.05}
    net = me.growth_for(cal, "tactical_diameter_L")
    assert net["net_of_own"] == 2 and net["sigma0"] == pytest.approx(0.0, abs=1e-6) and 0 < net["k"] < td["k"]
    assert me.growth_for(cal, "first_overshoot")["source"] == "rms_yaw_rate"  # one pair is not two


def test_a_turns_advance_is_calibrated_on_the_zigzags_onset_as_well_as_on_the_yaw_rate_it_settles_at():
    """The advance depends on how soon the ship starts turning and on the rate it settles at: the larger of the
    errors of the initial turning time (two pairs or more carry it) and the RMS yaw rate counts; the tactical
    diameter keeps the RMS yaw rate."""
    cal = {"pairs": [{"distance": 0.0, "errors": {"rms_yaw_rate": 0.02, "initial_turning_time": 0.2}},
                     {"distance": 0.0, "errors": {"rms_yaw_rate": 0.04, "initial_turning_time": 0.3}},
                     {"distance": 0.0, "errors": {"rms_yaw_rate": 0.03}}]}
    adv, td = me.growth_for(cal, "advance_L"), me.growth_for(cal, "tactical_diameter_L")
    assert adv["source"] == "initial_turning_time" and adv["n"] == 2
    assert adv["sigma0"] == pytest.approx(math.sqrt((0.2 ** 2 + 0.3 ** 2) / 2))
    assert me.growth_for(cal, "advance")["source"] == "initial_turning_time"  # the advance in metres too
    assert td["source"] == "rms_yaw_rate" and td["n"] == 3
    for p in cal["pairs"]:  # the rate the turn settles at is worse predicted than its onset: it counts
        p["errors"]["rms_yaw_rate"] = 0.5
    assert me.growth_for(cal, "advance_L")["source"] == "rms_yaw_rate"
    for p in cal["pairs"]:
        p["errors"]["rms_yaw_rate"] = 0.03
    del cal["pairs"][1]["errors"]["initial_turning_time"]  # one pair is not two: the RMS yaw rate stands in
    assert me.growth_for(cal, "advance_L")["source"] == "rms_yaw_rate"


def test_a_records_end_with_the_propeller_stopped_is_no_part_of_its_envelope():
    f = frame(np.r_[np.full(100, 0.1), np.full(20, 0.9)], 0.2)
    f["n"] = np.r_[np.full(100, 10.0), np.zeros(20)]
    assert len(pi.running(f)) == 100
    assert pi.state_envelope(f, 1.0, 1.0)["v'"] == pytest.approx(0.1)
    replay = f.drop(columns="n")  # a replay has no n: the measured record's says when the propeller ran
    assert len(pi.running(replay, measured=f)) == 100 and len(pi.running(replay)) == 120


def test_an_effect_parameter_on_a_bound_of_its_box_marks_a_fit_as_not_identified():
    from types import SimpleNamespace

    problem = SimpleNamespace(outer_params=lambda effects: [("wP0", 0.1, 0.7, ()), ("h_T", 1.1, 8.0, ())])
    fit = SimpleNamespace(effects=("propeller_wake", "shallow_water"), outer={"wP0": 0.7, "h_T": 3.2})
    assert me.at_bounds(problem, fit) == ["wP0 = 0.7 (bounds 0.1, 0.7)"]
    fit.outer = {"wP0": 0.45, "h_T": 1.1, "formula": "kijima_1990"}
    assert [b.split(" ")[0] for b in me.at_bounds(problem, fit)] == ["h_T"]
    fit.outer = {"wP0": 0.45, "h_T": 3.0}
    assert me.at_bounds(problem, fit) == []
    delay = SimpleNamespace(outer_params=lambda effects: [("rudder_delay", 0.0, 6.67, ())])
    assert me.at_bounds(delay, SimpleNamespace(effects=("rudder_dynamics",), outer={"rudder_delay": 0.0})) == []


def test_a_prediction_beyond_the_farthest_held_out_record_says_its_growth_is_assumed():
    g = {"sigma0": 0.05, "k": 0.1, "d_max": 0.3, "source": "rms_yaw_rate"}
    near = metric_interval(3.0, [], [], 0.2, g)
    far = metric_interval(3.0, [], [], 1.5, g)
    assert near["caveat"] is None
    assert "measured only up to 0.3" in far["caveat"] and far["s_extrap"] == pytest.approx(math.hypot(0.05, 0.15))


# ------------------------------------------------------------------------------------------- a tie
def test_a_tie_mixes_the_readings_and_one_reading_is_its_own_interval():
    one = pi.tie_mixture([(3.6, 3.6 * math.exp(-Z90 * 0.06), 3.6 * math.exp(Z90 * 0.06))])
    assert (one["value"], one["low"], one["high"]) == pytest.approx((3.6, 3.6 * math.exp(-Z90 * 0.06),
                                                                      3.6 * math.exp(Z90 * 0.06)), rel=1e-9)
    a, b = (3.6, 3.2, 4.05), (3.25, 2.85, 3.7)
    got = pi.tie_mixture([a, b])
    # the equal mixture of the two log-normals, sampled
    rng = np.random.default_rng(0)
    mus = np.log([a[0], b[0]])
    sds = np.array([np.log(a[2] / a[1]), np.log(b[2] / b[1])]) / (2 * Z90)
    pick = rng.integers(0, 2, 400_000)
    x = np.exp(rng.normal(mus[pick], sds[pick]))
    assert (got["low"], got["value"], got["high"]) == pytest.approx(tuple(np.quantile(x, [0.05, 0.5, 0.95])),
                                                                     rel=5e-3)
    assert got["low"] < b[0] < got["value"] < a[0] < got["high"]  # each reading's value inside, neither chosen
    assert got["high"] - got["low"] > max(a[2] - a[1], b[2] - b[1])  # wider than either reading alone


def test_a_tie_with_a_reading_that_has_no_interval_has_none():
    got = pi.tie_mixture([(3.6, 3.2, 4.0), (3.3, math.nan, math.nan)])
    assert math.isnan(got["low"]) and math.isnan(got["value"])


def test_the_turn_predictions_verdict_is_the_committed_doctor_verdict():
    """The KVLCC2 turn table's answer for another basin is the case of the effects the doctor's committed report on
    the same records names (or, for a tie, the mixture of the two readings)."""
    import json
    from pathlib import Path

    from study.doctor.turn_prediction import CASES, VERDICT

    report = json.loads((Path(__file__).resolve().parents[2] / "paper_figs/doctor/kvlcc2_hsva_identified/"
                         "report.json").read_text())
    effects = {label: effs for label, _, effs in CASES}
    if report["ambiguous"]:
        assert sorted(e for label in VERDICT for e in effects[label]) == sorted(report["ambiguous"])
    else:
        assert len(VERDICT) == 1 and sorted(effects[VERDICT[0]]) == sorted(report["final"]["effects"])


def test_posterior_draws_do_not_depend_on_the_signs_lapack_gives_the_eigenvectors(monkeypatch):
    """A seed gives the same draws whichever sign each eigenvector of the covariance comes out with (LAPACK's
    kernels may choose differently on another CPU)."""
    rng = np.random.default_rng(4)
    A = rng.standard_normal((5, 8))
    post = {"cov": A @ A.T, "mean": np.arange(5.0), "names": list("abcde")}
    problem = type("P", (), {"posterior": lambda self, fit, nonlinear=False: post})()
    _, one = me.posterior_draws(problem, None, 6, seed=3)
    eigh = np.linalg.eigh
    monkeypatch.setattr(np.linalg, "eigh", lambda c: (lambda w, V: (w, V * np.array([1, -1, 1, -1, -1])))(*eigh(c)))
    _, flipped = me.posterior_draws(problem, None, 6, seed=3)
    assert all(a == pytest.approx(b, abs=1e-12) for x, y in zip(one, flipped) for a, b in zip(x.values(), y.values()))
    sample = np.array([list(d.values()) for d in me.posterior_draws(problem, None, 20000, seed=0)[1]])
    assert np.cov(sample.T) == pytest.approx(post["cov"], abs=0.1 * np.abs(post["cov"]).max())
