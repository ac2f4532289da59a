"""A turn predicted from zigzags (study/doctor/turn_prediction.py): on simulated records of the 7 m KVLCC2 whose
MMG hull is the truth, a hull identified from the zigzags and random-rudder run, anchored to a set 20 % off the
truth, predicts the truth's 35 deg turn, and its posterior interval holds the truth's tactical diameter."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from doctor_cases import KNOWN, MMG_HULL, VESSEL, make_records, perturbed_prior
from study.identify.with_effects import EffectsProblem, Fit, identify_effects
from study.doctor.turn_prediction import predict_turn


@pytest.fixture(scope="module")
def case():
    train, _, truth = make_records({}, seed=0)
    return train, truth, perturbed_prior(VESSEL, MMG_HULL, 0.2)


@pytest.mark.slow
def test_identified_hull_predicts_the_truths_turn_and_its_interval_holds_it(case):
    train, truth, prior_cfg = case
    none = Fit((), {}, {}, 0.0)
    want = predict_turn(EffectsProblem(truth, KNOWN, train, effects={}), none, draws=0)["tactical_diameter_L"]
    prior = predict_turn(EffectsProblem(prior_cfg, KNOWN, train, effects={}), none, draws=0)["tactical_diameter_L"]
    assert abs(prior / want - 1.0) > 0.10  # the prior alone is far off: the records must do the work
    pb = EffectsProblem(prior_cfg, MMG_HULL, train, effects={}, anchor=0.3)
    got = predict_turn(pb, identify_effects(pb), draws=64, seed=1)
    assert got["tactical_diameter_L"] == pytest.approx(want, rel=0.03)
    assert got["finite_draws"] == 64
    assert got["td_low"] <= want <= got["td_high"], got
    # the interval is an identification spread, not a blanket: narrower than the prior's miss
    assert got["td_high"] - got["td_low"] < abs(prior - want)


def test_fixed_rpm_and_own_self_propulsion_differ_when_resistance_does(case):
    train, truth, _ = case
    pb = EffectsProblem(truth, KNOWN, train, effects={})
    fit = Fit((), {}, {}, 0.0)
    own = predict_turn(pb, fit, draws=0)
    assert own["n"] == pytest.approx(pb.base.n0, rel=0.01)  # the config's n is its self-propulsion point
    slow = predict_turn(pb, fit, n=0.8 * own["n"], draws=0)
    assert slow["n"] == pytest.approx(0.8 * own["n"])
    assert np.isfinite(slow["tactical_diameter_L"]) and slow["tactical_diameter_L"] != own["tactical_diameter_L"]


@pytest.mark.slow
def test_cli_without_the_hsva_files_says_so_in_one_line_and_exits_2(tmp_path):
    p = subprocess.run([sys.executable, "-m", "study", "turn_prediction", "--data", str(tmp_path),
                        "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert p.returncode == 2
    assert p.stderr.strip().count("\n") == 0 and str(tmp_path) in p.stderr
    assert not (tmp_path / "out").exists()
