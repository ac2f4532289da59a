"""The manoeuvre that would tell two candidate explanations apart (study/doctor/separating.py): the score's
arithmetic, the noise it is measured against, and the doctor's report of it for a tie."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from study.doctor.diagnose import Doctor, Options
from study.doctor.html import render_html
from study.doctor.html_format import num
from study.doctor.separating import MENU, SEPARATES, SPEEDS_U0, channel_noise, separation

from test_doctor import KNOWN, VESSEL, records, scaled


def _frame(t, **cols):
    return pd.DataFrame({"time": t, **cols})


def test_the_score_is_the_rms_distance_in_units_of_the_misfit():
    t = np.arange(0.0, 10.0, 0.1)
    a = _frame(t, u=np.ones_like(t), v=np.zeros_like(t), r=np.zeros_like(t))
    b = _frame(t, u=np.ones_like(t) + 0.02, v=np.zeros_like(t), r=np.zeros_like(t))
    scale = {"u": 0.01, "v": 0.001, "r": 0.001}
    d = separation(a, b, scale)
    assert d["S"] == pytest.approx(2.0) and d["channel"] == "u" and d["max"] == pytest.approx(2.0)
    # a second channel apart by the same amount adds in quadrature; the record's length does not matter
    b2 = b.assign(r=0.002)
    assert separation(a, b2, scale)["S"] == pytest.approx(np.sqrt(8.0))
    assert separation(a.iloc[:50], b.iloc[:50], scale)["S"] == pytest.approx(2.0)
    assert separation(a, a, scale)["S"] == 0.0 and separation(b, a, scale)["S"] == pytest.approx(2.0)


def test_the_noise_is_the_records_own_white_noise():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 300.0, 0.1)
    smooth = 1.0 + 0.2 * np.sin(0.05 * t)
    recs = [_frame(t, u=smooth + 0.01 * rng.standard_normal(len(t)), v=0.1 * np.sin(0.03 * t),
                   r=0.01 * np.cos(0.02 * t) + 0.001 * rng.standard_normal(len(t))) for _ in range(3)]
    s = channel_noise(recs)
    assert s["u"] == pytest.approx(0.01, rel=0.1) and s["r"] == pytest.approx(0.001, rel=0.1)
    assert s.get("v", 0.0) < 1e-4  # noise-free: no noise to measure (at most rounding)


@pytest.fixture(scope="module")
def tied():
    """Records with a hidden current, the candidates' validation errors forced within the tie (as in
    test_doctor's decision-rule test), each candidate still fitted for real."""
    train, val = records([{"name": "current", "speed_U0": 0.1, "direction_deg": 45.0}], duration=60.0)
    d = Doctor(VESSEL, KNOWN, train, val, Options(candidates=("current", "wind", "yaw_bias")))
    real, scale = Doctor.evaluate, {"current": 0.40, "wind": 0.42, "yaw_bias": 0.95}
    base = real(d, ())

    def tie(self, effects, start=None, fixed=(), refine=False):
        ev = real(self, effects, start, fixed, refine)
        return scaled(ev, effects, scale[effects[-1]] * base.validation_error / ev.validation_error) if effects \
            else ev

    mp = pytest.MonkeyPatch()
    mp.setattr(Doctor, "evaluate", tie)
    try:
        d.run()
    finally:
        mp.undo()
    return d, d.report()


def test_a_tie_recommends_the_manoeuvre_where_the_two_fits_differ_most(tied):
    d, rep = tied
    assert rep["ambiguous"] == ["current", "wind"]
    sep = rep["separating_maneuver"]
    assert sep["pair"] == ["current", "wind"]
    assert len(sep["menu"]) == len(MENU) * 2 * len(SPEEDS_U0)
    S = [m["S"] for m in sep["menu"] if np.isfinite(m["S"])]
    assert S == sorted(S, reverse=True) and sep["best"] == sep["menu"][0]
    assert len(sep["recorded"]) == len(d.train_df) + len(d.val_df)
    # the scale is the current fit's misfit where it exceeds the sensors' noise (it does: the model is exact)
    assert set(sep["scale"]) == {"u", "v", "r"} and all(v > 0 for v in sep["scale"].values())
    # a current and a wind of these sizes predict different turns: some manoeuvre separates them
    assert sep["best"]["S"] > SEPARATES
    best = sep["best"]
    assert f"to {best['side']}" in sep["text"] and sep["text"] in rep["notes"]
    # the diagnosis with the page's own keys (write_report adds them) renders
    html = render_html(dict(rep, title="", created_by="", vessel="kvlcc2_l7", model="known", structure="",
                            worst_windows=[], catalogue=[], figures=[]))
    assert 'id="separating"' in html and 'href="#separating"' in html
    # the residual yaw moment per rudder-angle bin: its bins hold every training row, and the page shows it
    rr = rep["rudder_residual"]["baseline"]
    assert sum(b["rows"] for b in rr["bins"]) <= rr["rows"] and rr["N_rms"] > 0
    assert 'id="rudder_residual"' in html


def test_a_settled_verdict_recommends_nothing():
    train, val = records([{"name": "current", "speed_U0": 0.1, "direction_deg": 45.0}], duration=60.0)
    d = Doctor(VESSEL, KNOWN, train, val, Options(candidates=("current", "yaw_bias")))
    d.run()
    rep = d.report()
    assert rep["missing_effect"] == "current"
    st = rep["stability"][0]
    assert (rep["separating_maneuver"] is None) == (st["k"] is None or st["k"] == st["n"])


def test_records_with_and_without_a_depth_are_warned_of():
    """Trained deep (no depth) and at h/T 2.0, validated at 1.5 without its depth: the records without one share
    one h/T, which the report says, naming them."""
    from doctor_cases import make_records

    from study.records.schema import Record

    train, val, _ = make_records({"depth_h_T": {"train": [None, 2.0, None], "validate": [1.5, 1.5]}}, duration=60.0)
    val = [Record(data=r.data.drop(columns=["depth"]), meta=r.meta) for r in val]
    d = Doctor(VESSEL, KNOWN, train, val, Options(candidates=("shallow_water", "yaw_bias")))
    notes = d.depth_notes()
    assert len(notes) == 1 and "water depth given for 1 record(s)" in notes[0]
    assert "validate_0_zigzag_20_10_port" in notes[0] and "train_0_zigzag_10_10" in notes[0]
    assert not Doctor(VESSEL, KNOWN, train, val, Options(candidates=("yaw_bias",))).depth_notes()


def test_a_tie_predicts_the_turn_with_both_readings_mixed_not_with_one(tied):
    """With a tie for a verdict the predicted 35 deg turn is conditioned on neither reading: each predicts it with
    its own interval (as ``predict_turn`` gives for its fit) and the report's value and interval are their equal
    mixture, which holds both readings' values."""
    from study.doctor.predictions import predict_turn
    from study.doctor.uncertainty import alternative_evaluations, calibration, setting_alternatives, tie_turns

    d, rep = tied
    got = tie_turns(d, d.opt.tie)
    assert got["readings"] == ["current", "wind"] and len(got["turns"]) == 2
    ev = d.result["tie_evaluations"]["wind"]
    alts = [(label, d.problem, e.fit) for label, e in alternative_evaluations(d, ev, d.opt.tie)[0]]
    alone = predict_turn(d.problem, ev.fit, draws=64, maneuver="turning_35", alternatives=alts +
                         setting_alternatives(d, ev.fit, d.opt.tie)[0], cal=calibration(d, ev.fit))
    td = got["turns"][0]["metrics"]["tactical_diameter_L"]
    own = alone["metrics"]["tactical_diameter_L"]
    assert [td["readings"]["wind"][k] for k in ("value", "low", "high")] == pytest.approx(
        [own["value"], own["low"], own["high"]], rel=1e-9)
    values = [x["value"] for x in td["readings"].values()]
    assert values[0] != pytest.approx(values[1], rel=1e-3)  # the two readings turn differently (see above)
    assert td["low"] < min(values) <= max(values) < td["high"]
    assert min(values) < td["value"] < max(values)
    assert td["low"] >= min(x["low"] for x in td["readings"].values()) - 1e-9
    assert td["high"] <= max(x["high"] for x in td["readings"].values()) + 1e-9
    # the page shows both readings and their mixture
    html = render_html(dict(rep, title="", created_by="", vessel="kvlcc2_l7", model="known", structure="",
                            worst_windows=[], catalogue=[], figures=[], prediction_uncertainty={"tie": got}))
    assert "The verdict is a tie: the turns as current and wind predict them" in html
    assert num(td["value"]) in html
    assert all(f"{e} {num(x['value'])} ({num(x['low'])}-{num(x['high'])})" in html for e, x in td["readings"].items())


def test_a_tie_gives_every_validation_metric_both_readings_mixed(tied):
    """Under a tie the final model is the baseline, which both readings beat: each validation metric is also
    predicted by each tied reading (its replay, its own interval) and by their equal mixture, which holds both
    readings' values; the period, which a replay copies from the record, gets none."""
    from study.doctor.report import manoeuvre_predictions, predictions
    from study.doctor.uncertainty import BY_CONSTRUCTION, tie_records
    from study.records.maneuver_metrics import maneuver_metrics

    d, _ = tied
    meas = dict(zip(d.val_names, d.val_df))
    base = d.result["base"]
    mb = manoeuvre_predictions(d, base, predictions(d, base))
    mm = [r for n, df in meas.items() for r in maneuver_metrics(n, df, mb.get(n), mb.get(n), d.problem.L)]
    got = tie_records(d, mm, meas, lambda ev: manoeuvre_predictions(d, ev, predictions(d, ev)), d.opt.tie)
    rows = [r for r in mm if "tie" in r]
    assert got["readings"] == ["current", "wind"] and got["rows"] == len(rows) >= 3
    for r in rows:
        assert r["metric"] not in BY_CONSTRUCTION and set(r["tie_readings"]) == {"current", "wind"}
        values = [x["value"] for x in r["tie_readings"].values()]
        assert r["tie_low"] <= min(values) <= max(values) <= r["tie_high"], r
    assert not any("tie" in r for r in mm if r["metric"] in BY_CONSTRUCTION)
