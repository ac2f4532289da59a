"""A replay's initial state on a record whose u, v, r were estimated from positions and heading
(study/identify/with_effects/initial_state.py): fitted by output error on the measured positions and
heading of the record's first three ship lengths, not taken from the smoother's first (least accurate)
estimates; and such a record is scored on its positions (measured) as well as on u, v, r (estimated) and psi.

The record: the 7 m KVLCC2 model's 20/20 zigzag (the truth vessel replayed, so any error is the start's),
positions and heading only with noise as tests/doctor/test_doctor_effects.py puts it on (1 % of each channel's
spread: 0.71 m on the positions, 0.23 deg on the heading), u, v, r estimated by the loader's filter and
smoother. Measured: the smoother's first v is 0.039 m/s off (3 % of the speed) and the heading of a replay from
it is off by 0.70 of the heading's spread (RMS); from the fitted start the heading is within 0.4 %, v and r
within 0.1 % and u within 0.5 % (tolerance 2 % on v, r and the heading).
"""
from __future__ import annotations

import numpy as np
import pytest

from study.identify.with_effects import EffectsProblem, Fit, record_errors, scored_channels
from study.identify.with_effects import problem as problem_module
from study.records.measure import MeasurementModel
from study.records.schema import Record, with_estimated_states
from study.configuration.compose import read_config
from study.sim import load_vessel, simulate

VESSEL = read_config("vessel", "kvlcc2_l7")
KNOWN = {"name": "known", "type": "kind", "equations": {}}


@pytest.fixture(scope="module")
def records():
    clean = MeasurementModel(dt=0.1).apply(simulate(load_vessel(VESSEL), "zigzag_20_20", duration=300.0))
    clean = clean.drop(columns="delta_cmd")
    noisy = MeasurementModel(dt=0.1, noise_level=0.01, seed=3, channels=("psi", "x0", "y0", "delta")).apply(clean)
    est = with_estimated_states(Record(data=noisy.drop(columns=["u", "v", "r"]), meta={"name": "zigzag"}))
    return clean, est


def test_the_start_is_fitted_to_the_measured_positions_and_heading(records, monkeypatch):
    clean, est = records
    assert est.meta["states"] == "ekf" and scored_channels(est.meta) == ("u", "v", "r", "psi", "x0", "y0")
    pb = EffectsProblem(VESSEL, KNOWN, [est])
    fit = Fit((), {}, {}, 0.0)
    info = pb.info_for(est.data, est.meta, "zigzag")
    fitted = pb.predict(fit, est.data, info)
    monkeypatch.setattr(problem_module, "states_estimated", lambda meta: False)
    smoother = pb.predict(fit, est.data, info)
    truth = {c: clean[c].iloc[0] for c in ("u", "v", "r")}
    assert abs(fitted["v"].iloc[0] - truth["v"]) <= 0.01 * pb.U0
    assert abs(fitted["r"].iloc[0] - truth["r"]) <= 0.01 * pb.U0 / pb.L
    e_fit, e_smo = record_errors(clean, fitted, pb.floors), record_errors(clean, smoother, pb.floors)
    for c in ("v", "r", "psi"):
        assert e_fit[c]["nrmse"] <= 0.02, (c, e_fit[c], e_smo[c])
    assert e_fit["psi"]["nrmse"] <= 0.2 * e_smo["psi"]["nrmse"]


def test_measured_states_keep_their_own_start_and_channels(records):
    clean, _ = records
    meta = {"name": "zigzag"}
    assert scored_channels(meta) == ("u", "v", "r", "psi")
    pb = EffectsProblem(VESSEL, KNOWN, [clean])
    pred = pb.predict(Fit((), {}, {}, 0.0), clean, pb.info_for(clean, meta, "zigzag"))
    assert pred["v"].iloc[0] == pytest.approx(clean["v"].iloc[0], abs=1e-6)
    errs = record_errors(clean, pred, pb.floors, scored_channels(meta))
    assert errs["scored"] == ("u", "v", "r", "psi") and errs["x0"]["nrmse"] < 0.01


def test_noise_levels_come_from_the_estimator_or_an_assumed_default():
    from study.identify.with_effects.initial_state import noise_sd

    meta = {"state_estimation": {"noise_std": {"x0": 0.5, "y0": 0.4, "psi": 0.002}}}
    assert noise_sd(meta, 7.0) == pytest.approx([0.5, 0.4, 0.002])
    assert noise_sd({}, 7.0) == pytest.approx([7e-3, 7e-3, np.radians(0.1)])
    assert noise_sd({"state_estimation": {"noise_std": {"x0": 0.0}}}, 320.0)[0] == pytest.approx(0.32)
