"""Plausibility checks of records against the vessel (study.records.vessel_checks), run before the doctor fits anything.

Records: the 7 m KVLCC2 model (kvlcc2_l7) simulated through a 10/10 zigzag (200 s) and measured at 10 Hz with
1 % white noise, as in tests/doctor/test_doctor.py. A clean record passes; a flipped rudder, a full-scale record given
to the model-scale vessel and n in rpm each raise with a message naming the file, the column and the fix; a
run without rudder motion says nothing about the rudder sign; other vessel kinds pass clean.
"""
import math
import re

import numpy as np
import pytest

from study.records import vessel_checks as checks
from study.records.vessel_checks import RecordCheckError, check_records
from study.records.measure import MeasurementModel
from study.records.schema import Record
from study.configuration.compose import read_config
from study.sim import load_vessel, simulate

VESSEL = read_config("vessel", "kvlcc2_l7")
FULL = read_config("vessel", "kvlcc2")
PATH = "data/train_zigzag_10_10.csv"


def measured(vessel_cfg, maneuver, duration=200.0, seed=0):
    df = simulate(load_vessel(vessel_cfg), maneuver, duration=duration)
    return MeasurementModel(dt=0.1, noise_level=0.01, seed=seed).apply(df.drop(columns="delta_cmd"))


@pytest.fixture(scope="module")
def zigzag():
    return measured(VESSEL, "zigzag_10_10")


def record(df, path=PATH, name="zigzag_10_10"):
    return Record(data=df.copy(), meta={"name": name}, path=path)


def one_line(problems):
    assert problems and all("\n" not in p for p in problems)


def test_clean_records_pass(zigzag):
    recs = [record(zigzag), record(measured(VESSEL, "zigzag_20_20", seed=1), "data/train_zigzag_20_20.csv"),
            measured(VESSEL, "random_rudder", seed=2)]  # a plain DataFrame too
    assert check_records(VESSEL, recs) == []
    facts = checks.vessel_facts(VESSEL)
    assert facts.yaw_sign == 1.0 and 0.5 < facts.response_time * facts.U0 / facts.L < 3.0


def test_flipped_rudder_raises_naming_file_and_column(zigzag):
    bad = record(zigzag)
    bad.data["delta"] = -bad.data["delta"]
    with pytest.raises(RecordCheckError) as err:
        check_records(VESSEL, [record(zigzag, "data/ok.csv"), bad])
    problems = err.value.problems
    assert len(problems) == 1
    one_line(problems)
    msg = str(err.value).splitlines()[0]
    assert msg.startswith(f"{PATH}: column 'delta' has the opposite sign")
    assert "expected > 0 for vessel kvlcc2_l7" in msg and "delta = -delta" in msg
    # strict=False returns it; a DataFrame is named by its position, or by the names given
    df = bad.data
    assert check_records(VESSEL, [bad], strict=False) == problems
    assert check_records(VESSEL, [zigzag, df], strict=False)[0].startswith("record 1: column 'delta'")
    assert check_records(VESSEL, [df], names=["val_zz"], strict=False)[0].startswith("val_zz: column 'delta'")


def test_flipped_yaw_rate_names_r(zigzag):
    bad = record(zigzag)
    bad.data["r"] = -bad.data["r"]  # r now disagrees with the rudder and with the heading
    problems = check_records(VESSEL, [bad], strict=False)
    assert len(problems) == 1 and problems[0].startswith(f"{PATH}: column 'r' has the opposite sign")
    assert "r = -r" in problems[0]


def test_full_scale_record_for_model_scale_vessel():
    full = record(measured(FULL, "zigzag_10_10", duration=600.0), "data/kvlcc2_full.csv")
    with pytest.raises(RecordCheckError) as err:
        check_records(VESSEL, [full])
    problems = err.value.problems
    one_line(problems)
    speed = problems[0]
    assert speed.startswith("data/kvlcc2_full.csv: columns 'u', 'v'")
    assert "full-scale record for a model-scale vessel?" in speed
    assert "U0 = 1.179 m/s" in speed and "Lpp 7 m" in speed
    assert "use the vessel config kvlcc2 (Lpp 320 m" in speed and "Froude-scale" in speed
    # its implied scale is the real one (320 / 7 = 45.7)
    lam = float(re.search(r"= sqrt\(([0-9.]+)\)", speed).group(1))
    assert lam == pytest.approx(320.0 / 7.0, rel=0.05)
    # n is flagged as consistent with the scale, and no false rudder-sign alarm (the lag is Froude-scaled)
    assert any("'n'" in p and "another scale" in p for p in problems)
    assert not any("opposite sign" in p for p in problems)


def test_model_scale_record_for_full_scale_vessel(zigzag):
    problems = check_records(FULL, [record(zigzag)], strict=False)
    assert problems and "model-scale record for a full-scale vessel?" in problems[0]
    assert "use the vessel config kvlcc2_l7" in problems[0]
    assert not any("opposite sign" in p for p in problems)


def test_n_in_rpm(zigzag):
    bad = record(zigzag)
    bad.data["n"] = bad.data["n"] * 60.0
    with pytest.raises(RecordCheckError) as err:
        check_records(VESSEL, [bad])
    problems = err.value.problems
    assert len(problems) == 1
    one_line(problems)
    assert problems[0].startswith(f"{PATH}: column 'n'")
    assert "rpm" in problems[0] and "divide by 60" in problems[0]
    assert "n0 = 11.8 rps" in problems[0]


def test_no_rudder_motion_no_rudder_sign_message(monkeypatch):
    straight = {"name": "straight", "type": "turning", "amp_deg": 0.0, "pullout_deg": 1e9, "duration": 200.0}
    df = measured(VESSEL, straight)
    assert np.all(df["delta"] == 0.0)
    assert check_records(VESSEL, [df]) == []
    # small course corrections (a 1.5/1 deg zigzag), even flipped: too little rudder to judge its sign
    small = {"name": "small", "type": "zigzag", "stages": [{"amp_deg": 1.5, "switch_deg": 1.0, "switches": 20}],
             "duration": 200.0}
    df = measured(VESSEL, small)
    df["delta"] = -df["delta"]
    assert math.degrees(np.std(df["delta"])) < checks.MIN_RUDDER_SPREAD_DEG
    assert check_records(VESSEL, [df]) == []
    # ... which only the spread threshold keeps quiet: the flipped response itself is clear
    monkeypatch.setattr(checks, "MIN_RUDDER_SPREAD_DEG", 0.0)
    assert any("'delta'" in p for p in check_records(VESSEL, [df], strict=False))


def test_unclear_correlation_no_rudder_sign_message(zigzag, monkeypatch):
    # a rudder column that carries only noise (a broken sensor): 5 deg spread, no relation to r
    bad = record(zigzag)
    bad.data["delta"] = np.radians(5.0) * np.random.default_rng(1).standard_normal(len(bad.data))
    assert check_records(VESSEL, [bad]) == []
    # ... which only the correlation threshold keeps quiet (the weak correlation happens to be negative)
    monkeypatch.setattr(checks, "MIN_RUDDER_CORR", 0.0)
    assert any("'delta'" in p for p in check_records(VESSEL, [bad], strict=False))


@pytest.mark.parametrize("name", ["mariner", "usv_waterjet"])
def test_other_vessel_kinds(name):
    cfg = read_config("vessel", name)
    df = measured(cfg, "zigzag_10_10", duration=None)  # the manoeuvre's own length for this vessel
    assert check_records(cfg, [df]) == []
    bad = df.copy()
    bad["delta"] = -bad["delta"]
    problems = check_records(cfg, [bad], strict=False)
    assert len(problems) == 1 and f"vessel {name}" in problems[0] and "delta = -delta" in problems[0]
    # mariner: no propeller speed in the model; usv_waterjet: n is the jet velocity -> n is not checked
    bad = df.copy()
    bad["n"] = bad["n"] * 60.0 + 1.0
    assert check_records(cfg, [bad]) == []
