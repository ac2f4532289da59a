"""Candidates that fit the place, and set-up effects that stay with their set-up (``study.records.facility``).

- a record's ``facility`` is read from a CSV header and from Parquet metadata, and the real datasets' loaders set
  it; an unknown one is refused in one line naming the file, the key, the value and what was expected;
- a towing-tank (or basin) record never gets wind or current candidates; a pond or the sea does;
- a pond's fitted current faster than the wind's drift is rejected with the reason, and never named;
- a set-up effect (yaw bias) is left out of the prediction of a record from another facility, kept for a record
  of the same facility, and kept everywhere when asked (``keep_setup_effects``); the report says which.

Records: the KVLCC2 L7 model (tests/doctor/test_doctor.py's simulator and noise), 60 s each, so every case runs in
seconds.
"""
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from study.records import facility as fac
from study.doctor.diagnose import Doctor, Options
from study.doctor.model_error import without_effects
from study.records.schema import Record, SchemaError, read_record, write_record

from test_doctor import KNOWN, U0, VESSEL, records

BIAS = [{"name": "yaw_bias", "Y": 0.0, "N": 5e-4}]


def tagged(dfs, prefix, **meta):
    return [Record(data=df, meta={"name": f"{prefix}{i}", **meta}) for i, df in enumerate(dfs)]


@pytest.fixture(scope="module")
def biased():
    return records(BIAS, duration=60.0)


# ------------------------------------------------------------------------------------------- the field
@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_facility_is_read_from_csv_and_parquet_metadata(tmp_path, biased, ext):
    p = tmp_path / f"r{ext}"
    write_record(Record(data=biased[0][0], meta={"name": "r", "facility": "basin"}), p)
    assert read_record(p).meta["facility"] == "basin"


def test_a_hand_written_csv_header_names_the_facility(tmp_path, biased):
    p = tmp_path / "hand.csv"
    p.write_text("# facility: towing_tank\n" + biased[0][0].to_csv(index=False))
    assert read_record(p).meta["facility"] == "towing_tank"


def test_an_unknown_facility_is_refused_naming_file_key_value_and_choices(tmp_path, biased):
    p = tmp_path / "lake.parquet"
    with pytest.raises(SchemaError, match="facility: lake: expected one of towing_tank, basin, pond, sea"):
        write_record(Record(data=biased[0][0], meta={"facility": "lake"}), p)
    assert not p.exists()
    csv = tmp_path / "lake.csv"
    csv.write_text("# facility: lake\n" + biased[0][0].to_csv(index=False))
    with pytest.raises(SchemaError, match=f"^{csv}: facility: lake: expected one of "):
        read_record(csv)


@pytest.mark.slow
def test_the_command_refuses_an_unknown_facility_in_one_line(tmp_path, biased):
    csv = tmp_path / "lake.csv"
    csv.write_text("# facility: lake\n" + biased[0][0].to_csv(index=False))
    p = subprocess.run([sys.executable, "-m", "study", "diagnose", f"train={csv}", f"out={tmp_path / 'o'}",
                        "log_runs=false"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 2
    assert p.stderr.strip() == (f"study diagnose: error: {csv}: facility: lake: expected one of towing_tank, basin, "
                                "pond, sea")
    assert not (tmp_path / "o" / "report.json").exists()


def test_the_real_datasets_loaders_set_their_facility():
    from study.records.loaders import list_real_records, load_real

    hsva = list_real_records("kvlcc2_hsva")
    esso = list_real_records("esso_osaka", kind="zigzag")
    if not hsva or not esso:
        pytest.skip("the real datasets are not here")
    assert load_real(hsva[0]).meta["facility"] == "towing_tank"
    assert load_real(esso[0]).meta["facility"] == "pond"


# ------------------------------------------------------------------------------------------ candidates
@pytest.mark.parametrize("where", ["towing_tank", "basin"])
def test_an_indoor_record_never_gets_wind_or_current_candidates(biased, where):
    train, val = biased
    d = Doctor(VESSEL, KNOWN, tagged(train, "t", facility=where), tagged(val, "v"))
    assert "wind" not in d.candidates and "current" not in d.candidates
    assert "indoors: no wind" in d.not_applicable["wind"]
    assert "still water: no current" in d.not_applicable["current"]
    # the vessel config's facility stands for records that state none
    d = Doctor({**VESSEL, "facility": where}, KNOWN, tagged(train, "t"), tagged(val, "v"))
    assert "wind" not in d.candidates and "current" not in d.candidates


def test_outdoors_or_unknown_wind_and_current_stay_candidates(biased):
    train, val = biased
    for meta in ({"facility": "pond"}, {"facility": "sea"}, {}):
        d = Doctor(VESSEL, KNOWN, tagged(train, "t", **meta), tagged(val, "v"))
        assert {"wind", "current"} <= set(d.candidates), meta
    mixed = tagged(train[:2], "t", facility="towing_tank") + tagged(train[2:], "p", facility="pond")
    d = Doctor(VESSEL, KNOWN, mixed, tagged(val, "v"))  # one record outdoors: wind can act there
    assert {"wind", "current"} <= set(d.candidates)


def test_a_wind_effect_in_a_towing_tank_model_is_refused():
    train, val = records([], duration=60.0)
    with pytest.raises(ValueError, match="towing tank is indoors"):
        Doctor(VESSEL, {**KNOWN, "effects": ["wind"]}, tagged(train, "t", facility="towing_tank"), tagged(val, "v"))


def pond_records(wind_speed: float):
    """A current of 10 % of U0 and a measured true wind of ``wind_speed`` (both in the truth)."""
    hidden = [{"name": "current", "speed_U0": 0.1, "direction_deg": 45.0},
              {"name": "wind", "speed": wind_speed, "direction_deg": 90.0}]
    train, val = records(hidden, duration=60.0)
    for df in train + val:
        df["wind_speed"] = wind_speed
        df["wind_dir"] = math.pi / 2
    return train, val


@pytest.mark.slow
def test_a_pond_current_faster_than_the_winds_drift_is_rejected_with_the_reason():
    train, val = pond_records(0.5)  # the drift bound: 7 % of 0.5 m/s = 0.035 m/s, the current 0.118 m/s
    opt = Options(candidates=("current", "yaw_bias"))
    d = Doctor(VESSEL, KNOWN, tagged(train, "t", facility="pond"), tagged(val, "v", facility="pond"), opt)
    d.run()
    rep = d.report()
    row = next(r for r in rep["ranking"] if r["effect"] == "current")
    assert row["parameters"]["current_speed"] > fac.POND_DRIFT_SHARE * 0.5
    assert "in a pond" in row["implausible"] and "Wu 1975" in row["implausible"]
    assert row["significant"] is False and "rejected" in row["note"]
    assert rep["missing_effect"] != "current" and "current" not in rep["ambiguous"]
    assert any("physically implausible" in n for n in rep["notes"])
    # the same records at sea: nothing bounds the current, and it is named
    d = Doctor(VESSEL, KNOWN, tagged(train, "t", facility="sea"), tagged(val, "v", facility="sea"), opt)
    d.run()
    assert d.report()["missing_effect"] == "current"


def test_the_pond_bound_itself():
    class C:
        needs = ("current",)

    df = pd.DataFrame({"wind_speed": np.full(5, 2.0)})
    assert fac.implausible(C(), {"current_speed": 0.1}, ["pond"], [df]) is None  # 0.1 <= 0.14
    assert "0.14 m/s" in fac.implausible(C(), {"current_speed": 0.2}, ["pond"], [df])
    assert fac.implausible(C(), {"current_speed": 0.2}, ["sea"], [df]) is None
    assert fac.implausible(C(), {"current_speed": 0.2}, ["pond"], [df.drop(columns="wind_speed")]) is None


# -------------------------------------------------------------------------------------- set-up effects
def _bias_prediction_check(d, keep_expected: bool):
    ev = d.evaluate(("yaw_bias",))
    assert ev.fit.coefs["yaw_bias_N"] == pytest.approx(5e-4, rel=0.3)
    without = without_effects(d.problem, ev.fit, ["yaw_bias"])
    assert without.effects == () and "yaw_bias_N" not in without.coefs
    info, df = d.val_infos[0], d.val_df[0]
    got = d.predict(d.problem, ev.fit, df, info)
    full = d.problem.predict(ev.fit, df, info)
    bare = d.problem.predict(without, df, info)
    assert not np.allclose(full["psi"], bare["psi"])  # the bias matters to this prediction
    assert np.allclose(got["psi"], (full if keep_expected else bare)["psi"])


def test_a_setup_effect_is_left_out_of_a_prediction_for_another_facility_and_kept_when_asked(biased):
    train, val = biased
    t, v = tagged(train, "t", facility="towing_tank"), tagged(val, "v", facility="basin")
    d = Doctor(VESSEL, KNOWN, t, v, Options(candidates=("yaw_bias",)))
    _bias_prediction_check(d, keep_expected=False)
    d.run()
    rep = d.report()
    row = rep["ranking"][0]
    assert row["setup_effect"] and set(row["left_out_of"]) == {"v0", "v1"}
    assert "another facility (basin; trained in towing_tank)" in row["note"]
    kept = Doctor(VESSEL, KNOWN, t, v, Options(candidates=("yaw_bias",), keep_setup_effects=True))
    _bias_prediction_check(kept, keep_expected=True)
    kept.run()
    rep = kept.report()
    assert rep["missing_effect"] == "yaw_bias"
    assert rep["setup_effects"] == {"effects": ["yaw_bias"], "kept": True, "left_out": {}}
    assert any("yaw_bias: attributed to the test set-up" in n and "keep_setup_effects=true" in n
               for n in rep["notes"])


def test_a_setup_effect_stays_in_a_prediction_for_the_same_facility_or_an_unknown_one(biased):
    train, val = biased
    for tm, vm in (({"facility": "towing_tank"}, {"facility": "towing_tank"}), ({"facility": "towing_tank"}, {}),
                   ({}, {})):
        d = Doctor(VESSEL, KNOWN, tagged(train, "t", **tm), tagged(val, "v", **vm), Options(candidates=("yaw_bias",)))
        _bias_prediction_check(d, keep_expected=True)


def test_another_scale_is_another_setup():
    assert fac.other_setup(("towing_tank", "1:20"), [("towing_tank", "1:45.714")]).startswith("another scale")
    assert fac.other_setup(("towing_tank", None), [("towing_tank", "1:45.714")]) is None
    assert fac.other_setup(("pond", None), [(None, None)]) is None


@pytest.mark.slow
def test_a_turn_predicted_elsewhere_leaves_the_setup_effect_out_unless_asked(biased):
    from study.doctor.turn_prediction import predict_turn
    from study.identify.effects import registry
    from study.identify.with_effects import EffectsProblem, identify_effects

    pb = EffectsProblem(VESSEL, KNOWN, tagged(biased[0], "t", facility="towing_tank"), effects=registry(["yaw_bias"]))
    fit = identify_effects(pb, ("yaw_bias",))
    bare = predict_turn(pb, without_effects(pb, fit, ["yaw_bias"]), draws=0)
    elsewhere = predict_turn(pb, fit, draws=0)  # a turn nobody measured: not the training set-up
    other = predict_turn(pb, fit, draws=0, facility="basin")
    same = predict_turn(pb, fit, draws=0, facility="towing_tank")
    kept = predict_turn(pb, fit, draws=0, facility="basin", keep_setup_effects=True)
    assert elsewhere["setup_left_out"] == other["setup_left_out"] == ["yaw_bias"]
    assert "another facility (basin; trained in towing_tank)" == other["setup_why"]
    assert same["setup_left_out"] == kept["setup_left_out"] == []
    td = lambda p: p["tactical_diameter_L"]  # noqa: E731
    assert td(elsewhere) == td(other) == td(bare)
    assert td(same) == td(kept) != td(bare)
