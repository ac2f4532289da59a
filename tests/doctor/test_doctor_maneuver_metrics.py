"""The doctor's manoeuvre metrics (study.records.maneuver_metrics): turning-circle and zigzag characteristics of a
measured record against two model replays.

Records: the 7 m KVLCC2 model (kvlcc2_l7), a 35 deg turning circle and a 20/10 zigzag, 1 % white noise, 10 Hz
(as the doctor's tests). "Replays": the record's measured rudder and propeller fed open loop through a vessel
(study.sim.replay, as the doctor replays its models), the true one or one with a 20 % larger rudder or a changed
hull coefficient.
"""
import math

import numpy as np
import pandas as pd
import pytest

from study.doctor.html import metrics_table_html
from study.records.maneuver_metrics import maneuver_metrics
from study.records.measure import MeasurementModel
from study.records.metrics import turning_metrics, zigzag_metrics
from study.configuration.compose import read_config
from study.sim import load_vessel, replay, simulate

VESSEL = read_config("vessel", "kvlcc2_l7")
L = float(VESSEL["particulars"]["Lpp"])
TURNING = ["tactical_diameter", "advance", "transfer", "tactical_diameter_L", "advance_L", "transfer_L",
           "steady_turning_rate"]
ZIGZAG = ["first_overshoot", "second_overshoot", "period", "initial_turning_time", "time_to_check_yaw"]
COLS = ("measured", "baseline", "final")

_CACHE = {}


def measured(maneuver: str, seed: int = 0, duration=None) -> pd.DataFrame:
    key = (maneuver, seed, duration)
    if key not in _CACHE:
        clean = simulate(load_vessel(VESSEL), maneuver, duration=duration)
        _CACHE[key] = MeasurementModel(dt=0.1, noise_level=0.01, seed=seed).apply(clean.drop(columns="delta_cmd"))
    return _CACHE[key]


def vessel_cfg(rudder_area=1.0, **hull) -> dict:
    cfg = {k: (dict(v) if isinstance(v, dict) else v) for k, v in VESSEL.items()}
    cfg["rudder"]["A_R"] = VESSEL["rudder"]["A_R"] * rudder_area
    cfg["hull"].update(hull)
    return cfg


def replayed(cfg: dict, df: pd.DataFrame) -> pd.DataFrame:
    """The vessel replayed open loop through the record (its measured rudder and propeller, its first state)."""
    t = df["time"].to_numpy(float)
    s0 = [float(df[c].iloc[0]) for c in ("u", "v", "r", "x0", "y0", "psi")]
    out = replay(load_vessel(cfg), t, df["delta"].to_numpy(float), df["n"].to_numpy(float), s0)[:, :, 0]
    return pd.DataFrame({"time": t, "u": out[:, 0], "v": out[:, 1], "r": out[:, 2], "x0": out[:, 3],
                         "y0": out[:, 4], "psi": out[:, 5], "delta": out[:, 6]})


def table(rows) -> dict:
    return {r["metric"]: r for r in rows}


@pytest.mark.parametrize("maneuver, names", [("turning_35", TURNING), ("zigzag_20_10", ZIGZAG)])
def test_the_same_record_three_times_gives_three_equal_columns(maneuver, names):
    df = measured(maneuver)
    rows = maneuver_metrics("rec", df, df, df, L)
    assert [r["metric"] for r in rows] == names
    for r in rows:
        assert set(r) == {"record", "metric", "unit", *COLS} and r["record"] == "rec"
        assert math.isfinite(r["measured"]), r
        assert r["measured"] == r["baseline"] == r["final"], r


def test_turning_circle_metrics_are_those_of_study_metrics():
    df = measured("turning_35")
    tm = turning_metrics(df, L=L)
    rows = table(maneuver_metrics("turn", df, df, df, L))
    for k in ("tactical_diameter", "advance", "transfer"):
        assert rows[k]["measured"] == pytest.approx(tm[k], rel=0.03)
        assert rows[k]["unit"] == "m"
        assert rows[k + "_L"]["measured"] == pytest.approx(rows[k]["measured"] / L, rel=1e-9)
        assert rows[k + "_L"]["unit"] == "L"
    assert rows["steady_turning_rate"]["measured"] == pytest.approx(tm["steady_turning_rate_deg"], rel=0.03)
    assert rows["steady_turning_rate"]["unit"] == "deg/s"
    # and near the truth of the clean record (the noise moves the 180 deg crossing a little)
    clean = turning_metrics(simulate(load_vessel(VESSEL), "turning_35"), L=L)
    assert rows["tactical_diameter"]["measured"] == pytest.approx(clean["tactical_diameter"], rel=0.08)
    assert rows["steady_turning_rate"]["measured"] == pytest.approx(clean["steady_turning_rate_deg"], rel=0.03)


def test_a_larger_rudder_or_another_hull_gives_another_tactical_diameter():
    df = measured("turning_35")
    true = table(maneuver_metrics("turn", df, replayed(vessel_cfg(), df), None, L))
    rud = table(maneuver_metrics("turn", df, replayed(vessel_cfg(rudder_area=1.2), df),
                                 replayed(vessel_cfg(N_r=1.3 * VESSEL["hull"]["N_r"]), df), L))
    D = true["tactical_diameter"]["baseline"]
    assert D == pytest.approx(true["tactical_diameter"]["measured"], rel=0.08)  # the true model fits the record
    assert rud["tactical_diameter"]["measured"] == true["tactical_diameter"]["measured"]
    # a larger rudder turns tighter; more yaw damping turns wider
    assert rud["tactical_diameter"]["baseline"] < 0.97 * D
    assert rud["tactical_diameter"]["final"] > 1.03 * D
    assert rud["steady_turning_rate"]["baseline"] > true["steady_turning_rate"]["baseline"] * 1.03


def test_zigzag_overshoots_are_those_of_study_metrics_and_a_replay_measured_from_the_same_switch():
    df = measured("zigzag_20_10")
    zm = zigzag_metrics(df)
    other = replayed(vessel_cfg(N_r=1.5 * VESSEL["hull"]["N_r"]), df)
    rows = table(maneuver_metrics("zz", df, replayed(vessel_cfg(), df), other, L))
    assert rows["first_overshoot"]["measured"] == pytest.approx(zm["overshoot_1"], rel=1e-9)
    assert rows["second_overshoot"]["measured"] == pytest.approx(zm["overshoot_2"], rel=1e-9)
    for k in ("period", "initial_turning_time", "time_to_check_yaw"):
        assert rows[k]["measured"] == pytest.approx(zm[k], rel=1e-9) and rows[k]["unit"] == "s"
    assert 40 < rows["period"]["measured"] < 60
    assert {rows[k]["unit"] for k in ZIGZAG} == {"deg", "s"}
    # an open-loop replay reverses its rudder when the measurement did: the same period
    assert rows["period"]["final"] == pytest.approx(rows["period"]["measured"], abs=0.2)
    # the true model replayed: near the measured overshoots (the noise biases the measured ones up a little)
    assert rows["first_overshoot"]["baseline"] == pytest.approx(rows["first_overshoot"]["measured"], abs=1.5)
    # more yaw damping: the replay's overshoots are smaller, measured from the measured switch heading
    sw = math.radians(zm["psi_switch_deg"])
    assert rows["first_overshoot"]["final"] == pytest.approx(zigzag_metrics(other, psi_switch=sw)["overshoot_1"])
    assert rows["first_overshoot"]["final"] < rows["first_overshoot"]["baseline"] - 1.0
    assert rows["time_to_check_yaw"]["final"] < rows["time_to_check_yaw"]["baseline"] - 0.5
    assert rows["time_to_check_yaw"]["baseline"] == pytest.approx(rows["time_to_check_yaw"]["measured"], abs=0.5)


@pytest.mark.parametrize("maneuver", ["turning_35", "zigzag_20_10"])
def test_a_diverged_replay_is_nan(maneuver):
    df = measured(maneuver)
    rows = maneuver_metrics("rec", df, None, df, L)
    assert rows and all(math.isnan(r["baseline"]) for r in rows)
    assert all(math.isfinite(r["measured"]) and r["final"] == r["measured"] for r in rows)
    rows = maneuver_metrics("rec", df, None, None, L)
    assert all(math.isnan(r["baseline"]) and math.isnan(r["final"]) for r in rows)


def test_a_turn_short_of_180_deg_has_no_tactical_diameter_but_an_advance():
    df = measured("turning_35")
    short = df[df["time"] <= 50.0]  # the heading passes 90 deg (~36 s) but not 180 deg (~61 s)
    rows = table(maneuver_metrics("short", short, short, None, L))
    assert math.isnan(rows["tactical_diameter"]["measured"]) and math.isnan(rows["tactical_diameter_L"]["measured"])
    assert math.isfinite(rows["advance"]["measured"]) and math.isfinite(rows["transfer"]["baseline"])
    assert math.isnan(rows["advance"]["final"])


def test_random_rudder_and_odd_records_never_raise():
    df = measured("random_rudder")
    assert maneuver_metrics("rr", df, df, None, L) == []
    turn = measured("turning_35")
    odd = [turn.iloc[:2], turn.iloc[:0], turn.drop(columns=["x0"]), turn.assign(delta=0.0),
           turn.assign(psi=np.nan), pd.DataFrame({"a": [1, 2, 3]})]
    for o in odd:
        rows = maneuver_metrics("odd", o, o, o, L)
        assert isinstance(rows, list)
        for r in rows:  # a turning record without positions: its distances are NaN
            assert set(r) == {"record", "metric", "unit", *COLS}
    # odd replays of a good record: NaN, not an exception
    for o in odd + [42, "x"]:
        rows = maneuver_metrics("turn", turn, o, None, L)
        assert len(rows) == len(TURNING) and all(math.isnan(r["baseline"]) for r in rows)
    assert all(math.isnan(r["measured"]) for r in maneuver_metrics("turn", turn, None, None, float("nan"))
               if r["metric"].endswith("_L"))


def test_manual_steering_before_the_turn_is_cut_off():
    """A real record starts with the helmsman's course keeping (the Esso Osaka pond runs): the execution of
    study.records.metrics (the first rudder movement) would fall there; the metrics are taken from the turn's own start,
    and the replays are cut at the same instant."""
    v = load_vessel(VESSEL)
    t = np.arange(0.0, 160.0, 0.1)
    rng = np.random.default_rng(3)
    steer = np.repeat(rng.uniform(-12, 12, 8), 50)  # 5 s steps of up to 12 deg for 40 s
    delta = np.radians(np.where(t < 40.0, np.concatenate([steer, np.zeros(len(t))])[:len(t)], 35.0))
    out = replay(v, t, delta, np.full(len(t), v.n0), [v.U0, 0, 0, 0, 0, 0])[:, :, 0]
    rec = pd.DataFrame({"time": t, "u": out[:, 0], "v": out[:, 1], "r": out[:, 2], "x0": out[:, 3],
                        "y0": out[:, 4], "psi": out[:, 5], "delta": out[:, 6]})
    turn_start = rec[rec["time"] >= 39.0].reset_index(drop=True)
    truth = turning_metrics(turn_start, L=L)
    rows = table(maneuver_metrics("manual", rec, rec, None, L))
    assert rows["tactical_diameter"]["measured"] == pytest.approx(truth["tactical_diameter"], rel=0.01)
    assert rows["advance"]["measured"] == pytest.approx(truth["advance"], rel=0.01)
    assert rows["advance"]["baseline"] == rows["advance"]["measured"]
    naive = turning_metrics(rec, L=L)  # from the first rudder movement: a much longer "advance"
    assert naive["advance"] > 1.5 * truth["advance"]


def test_the_html_table_shows_names_units_and_na():
    df = measured("turning_35")
    rows = maneuver_metrics("val_<turning>&35", df, None, df, L) + \
        maneuver_metrics("zigzag", measured("zigzag_20_10"), None, None, L)
    page = metrics_table_html(rows)
    assert page.lstrip().startswith("<table") and page.rstrip().endswith("</table>")
    for name in TURNING + ZIGZAG:
        assert f">{name}<" in page
    for unit in ("m", "L", "deg/s", "deg", "s"):
        assert f'<td class="unit">{unit}</td>' in page
    assert "val_&lt;turning&gt;&amp;35" in page and "<turning>" not in page
    assert page.count("<tr>") == len(rows) + 1  # header + one row each
    assert page.count(">n/a<") == len(TURNING) + 2 * len(ZIGZAG)  # the None columns
    D = table(rows)["tactical_diameter"]["measured"]
    assert f">{D:.4g}<" in page and ">nan<" not in page.lower()
    assert "No turning circle or zigzag" in metrics_table_html([])


def test_the_doctor_replays_a_record_with_an_approach_from_the_manoeuvre_start():
    """study.doctor.report.manoeuvre_predictions: the replay the metrics compare starts where the manoeuvre
    does (from the measured state there), not at the start of the approach; a record taken whole keeps its
    whole-record replay."""
    from types import SimpleNamespace

    from study.doctor.report import manoeuvre_predictions
    from study.records.maneuver_metrics import manoeuvre_start

    v = load_vessel(VESSEL)
    t = np.arange(0.0, 160.0, 0.1)
    steer = np.repeat(np.random.default_rng(3).uniform(-12, 12, 8), 50)
    delta = np.radians(np.where(t < 40.0, np.concatenate([steer, np.zeros(len(t))])[:len(t)], 35.0))
    out = replay(v, t, delta, np.full(len(t), v.n0), [v.U0, 0, 0, 0, 0, 0])[:, :, 0]
    approach = pd.DataFrame({"time": t, "u": out[:, 0], "v": out[:, 1], "r": out[:, 2], "x0": out[:, 3],
                             "y0": out[:, 4], "psi": out[:, 5], "delta": out[:, 6], "n": v.n0})
    whole = measured("turning_35")
    seen = {}

    def predict(fit, df, info):
        seen[info] = df
        return replayed(VESSEL, df)

    doctor = SimpleNamespace(mode="given", val_names=["approach", "whole"], val_df=[approach, whole],
                             val_infos=["approach", "whole"], problem=SimpleNamespace(predict=predict),
                             predict=lambda problem, fit, df, info, fold=None: problem.predict(fit, df, info))
    got = manoeuvre_predictions(doctor, SimpleNamespace(fit="fit"), {"approach": "old", "whole": "kept"})
    t0 = manoeuvre_start(approach)
    assert 30.0 < t0 < 40.5
    assert seen["approach"]["time"].iloc[0] == pytest.approx(t0, abs=0.11)
    assert seen["approach"]["u"].iloc[0] == pytest.approx(approach.loc[approach["time"] >= t0 - 1e-9, "u"].iloc[0])
    assert "whole" not in seen and got["whole"] == "kept"
    rows = table(maneuver_metrics("approach", approach, got["approach"], None, L))
    assert rows["tactical_diameter"]["baseline"] == pytest.approx(rows["tactical_diameter"]["measured"], rel=0.02)
