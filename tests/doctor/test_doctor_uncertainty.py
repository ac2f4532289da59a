"""The doctor's predicted metrics with their intervals, extrapolation and carriers (study/doctor/uncertainty.py,
study/doctor/model_error.py) in a real report.

Fast: simulated records of the 7 m KVLCC2 (the doctor's test records: 10/10 and 20/20 zigzags and a random
rudder for training, a 20/10 zigzag and a 35 deg turn for validation, 200 s, 1 % noise), the MMG hull identified
and anchored to a set 20 % off the truth, two candidates. Slow (real data, skipped without it): HSVA's KVLCC2
zigzags, the doctor's settings, the report says the 35 deg turn extrapolates and names what carries it.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from doctor_cases import MMG_HULL, VESSEL, make_records, perturbed_prior
from study.doctor import model_error as me
from study.doctor.diagnose import Doctor, Options
from study.doctor.report import write_report


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    train, val, _ = make_records({}, seed=0, duration=200.0)
    d = Doctor(perturbed_prior(VESSEL, MMG_HULL, 0.2), MMG_HULL, train, val,
               Options(candidates=("yaw_bias", "rudder_dynamics")))
    d.run()
    out = tmp_path_factory.mktemp("unc")
    write_report(d, out, "kvlcc2_l7", "mmg_hull")
    return d, json.loads((out / "report.json").read_text()), (out / "report.html").read_text()


@pytest.mark.slow
def test_a_batch_of_coefficient_sets_replays_as_predict_does(report):
    d, _, _ = report
    pb, fit = d.problem, d.result["final"].fit
    df, info = d.val_df[1], d.val_infos[1]
    one = pb.predict(fit, df, info)
    post, draws = me.posterior_draws(pb, fit, 3, seed=0)
    frames = me.replay_members(pb, fit, df, info, [dict(fit.coefs)] + draws)
    assert np.allclose(frames[0][["u", "v", "r", "psi"]].to_numpy(), one[["u", "v", "r", "psi"]].to_numpy())
    assert not np.allclose(frames[1]["r"].to_numpy(), one["r"].to_numpy())  # a draw is another model


@pytest.mark.slow
def test_every_predicted_metric_has_an_interval_around_it_with_its_parts(report):
    _, rep, _ = report
    rows = [r for r in rep["maneuver_metrics"] if math.isfinite(r["final"]) and r["metric"] != "period"]
    assert len(rows) >= 10
    for r in rows:
        for col in ("final", "baseline"):
            assert r[f"{col}_low"] < r[col] < r[f"{col}_high"], (r["record"], r["metric"], col)
            u = r[f"{col}_uncertainty"]
            assert {"s_id", "s_struct", "s_extrap", "distance", "half_width", "growth_source"} <= set(u)
            # s_extrap may be 0 here: the model's form is the truth's, so the held-out errors can all lie within
            # the held-out fits' own identification spread, which is taken out of them
            assert u["s_id"] > 0 and u["s_extrap"] >= 0 and u["draws"] >= 16
    for r in rep["maneuver_metrics"]:  # a replay copies the period from the record: no prediction, no interval
        if r["metric"] == "period":
            assert "final_low" not in r and "record's by construction" in r["final_uncertainty"]["why"]
    turn = {r["metric"]: r for r in rows if r["record"].endswith("turning_35")}
    # the turn is replayed far outside the zigzags' envelope and its intervals say which coefficients carry it
    assert turn["tactical_diameter_L"]["final_uncertainty"]["distance"] > 0.3
    assert any(c["coefficient"].startswith("N") for c in turn["tactical_diameter_L"]["carriers"])
    sec = rep["prediction_uncertainty"]
    assert sec["final"]["records"]["validate_1_turning_35"]["text"].startswith("EXTRAPOLATES")
    assert sec["final"]["alternatives"] and sec["final"]["calibration"]["splits"]
    cal = sec["final"]["calibration"]
    assert cal["growth"]["net_of_own"] >= 2  # the held-out predictions' own spreads were measured and taken out
    assert any(p["own_sd"].get("rms_yaw_rate", 0) > 0 for p in cal["pairs"])


@pytest.mark.slow
def test_a_measured_value_carries_its_record_s_noise_and_the_report_counts_agreement(report):
    _, rep, html = report
    turn = {r["metric"]: r for r in rep["maneuver_metrics"] if r["record"].endswith("turning_35")}
    for m in ("tactical_diameter_L", "advance_L", "transfer_L"):
        r = turn[m]
        assert r["measured_low"] < r["measured"] < r["measured_high"], r
        assert r["measured_noise"]["s_meas"] > 0 and r["measured_noise"]["probes"] >= 8
    summary = rep["prediction_uncertainty"]["summary"][-1]
    assert "hold the measured value" in summary and "agree on" in summary
    assert "its noise, 90 %" in html and "Agree, noise included" in html


@pytest.mark.slow
def test_the_report_predicts_both_turns_and_says_they_extrapolate(report):
    _, rep, page = report
    turns = rep["prediction_uncertainty"]["predicted_turns"]
    assert [t["maneuver"] for t in turns] == ["35 deg turning circle to starboard", "35 deg turning circle to port"]
    for t in turns:
        td = t["metrics"]["tactical_diameter_L"]
        assert td["low"] < td["value"] < td["high"] and 2.5 < td["value"] < 4.0
        assert t["extrapolation"]["text"].startswith("EXTRAPOLATES") and t["extrapolation"]["excess"]["r'"] > 0.3
        assert td["carriers"]
    assert 'id="uncertainty"' in page and "How far the predictions can be trusted" in page
    assert "EXTRAPOLATES beyond the training records" in page and 'class="interval">90 %:' in page
    assert any("35 deg turning circle to starboard" in s for s in rep["prediction_uncertainty"]["summary"])


@pytest.mark.slow
def test_kvlcc2_from_hsvas_zigzags_the_report_says_the_turn_extrapolates_and_names_its_carriers(tmp_path):
    from study.doctor.run import diagnose_conf, run
    from study.records.loaders import real_data_dir

    d = real_data_dir() / "kvlcc2_hsva" / "raw_data"
    if not list(d.glob("HSVA_CPMC_KVLCC2_Z_*_0?.dat")):
        pytest.skip(f"HSVA's KVLCC2 records are not in {d}")
    rep = run(diagnose_conf(vessel="kvlcc2_l7", model="mmg_hull", train=f"{d}/HSVA_CPMC_KVLCC2_Z_*_0?.dat",
                            validate=f"{d}/HSVA_CPMC_KVLCC2_Z_*_10_?.dat", out=str(tmp_path / "r"),
                            candidates=["yaw_bias"]))
    page = (tmp_path / "r" / "report.html").read_text()
    for t in rep["prediction_uncertainty"]["predicted_turns"]:
        ex, td = t["extrapolation"], t["metrics"]["tactical_diameter_L"]
        assert ex["text"].startswith("EXTRAPOLATES") and ex["distance"] > 0.3, ex
        names = [c["coefficient"] for c in td["carriers"]]
        assert "Nvvr" in names, names
        assert any("extrapolated" in c["sentence"] for c in td["carriers"])
        assert td["half_width"] > 0.05  # wider than the posterior draws' +-2 %
    assert "EXTRAPOLATES beyond the training records" in page and "Nvvr" in page


@pytest.mark.slow
def test_a_part_that_cannot_be_computed_is_said_and_the_rest_is_still_reported(report, monkeypatch):
    from study.doctor import uncertainty

    d, _, _ = report

    def singular(doctor, fit):
        raise np.linalg.LinAlgError("singular matrix")

    monkeypatch.setattr(uncertainty, "calibration", singular)
    sec = uncertainty.annotate(d, [], d.result["base"], d.result["final"], {}, {})
    assert len(sec["errors"]) == 3 and all("LinAlgError: singular matrix" in e for e in sec["errors"])
    assert sec["predicted_turns"] == [] and sec["summary"][-3:] == sec["errors"]
    assert sec["training_envelope"]["v'"] > 0
