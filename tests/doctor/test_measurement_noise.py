"""The measured value's own interval (study/doctor/measurement_noise.py) and the agreement of a prediction with a
measurement once it is included (study/doctor/prediction_interval.py: agrees)."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from study.doctor import measurement_noise as mn
from study.doctor.prediction_interval import agrees, z_of


def record(noise: float, n: int = 2000, seed: int = 0) -> pd.DataFrame:
    t = np.arange(n) * 0.1
    rng = np.random.default_rng(seed)
    smooth = {"time": t, "u": 1.0 + 0.1 * np.sin(0.05 * t), "psi": 0.3 * np.sin(0.02 * t), "delta": 0.0 * t}
    return pd.DataFrame({k: v + (noise * rng.standard_normal(n) if k in ("u", "psi") else 0.0)
                         for k, v in smooth.items()})


def test_the_noise_of_each_channel_is_read_off_the_record_and_a_clean_channel_has_none():
    sd = mn.record_noise(record(0.01))
    assert set(sd) == {"u", "psi"}  # delta is clean, time is no channel
    assert sd["u"] == pytest.approx(0.01, rel=0.1) and sd["psi"] == pytest.approx(0.01, rel=0.1)
    assert mn.record_noise(record(0.0)) == {}


def test_the_comparison_spread_is_the_noise_s_effect_on_log_replayed_over_measured():
    df = record(0.0)
    copies = mn.noisy_copies(df, {"psi": 0.2}, probes=400, seed=1)
    # a metric read off one sample of psi (sd 0.2 around 10), a replay that does not see the noise: the spread of
    # log(10 / (10 + e)) is about 0.2 / 10
    got = mn.comparison_spread(copies, lambda c: {"m": 10.0 + float(c["psi"].iloc[0]), "never": math.nan},
                               lambda c: {"m": 10.0})
    assert set(got) == {"m"} and got["m"]["probes"] == 400
    assert got["m"]["s_meas"] == pytest.approx(0.02, rel=0.15)
    again = mn.noisy_copies(df, {"psi": 0.2}, probes=3, seed=1)
    assert all(a.equals(b) for a, b in zip(again, copies[:3]))  # deterministic in the seed


def test_the_measured_interval_is_set_only_where_the_metric_has_a_spread():
    row = {"metric": "advance", "measured": 20.0}
    mn.measured_interval(row, {"advance": {"s_meas": 0.05, "probes": 16}})
    w = math.exp(z_of(0.9) * 0.05)
    assert row["measured_low"] == pytest.approx(20.0 / w) and row["measured_high"] == pytest.approx(20.0 * w)
    assert row["measured_noise"] == {"s_meas": 0.05, "probes": 16}
    other = {"metric": "period", "measured": 40.0}
    mn.measured_interval(other, {"advance": {"s_meas": 0.05, "probes": 16}})
    assert "measured_low" not in other


def test_a_measurement_outside_the_interval_agrees_once_its_own_noise_is_added():
    value, s = 10.0, 0.01
    w = math.exp(z_of(0.9) * s)
    low, high = value / w, value * w
    meas = value * math.exp(3 * s)  # outside the interval
    assert agrees(value, low, high, meas) is False
    assert agrees(value, low, high, meas, s_meas=0.03) is True  # sqrt(0.01^2 + 0.03^2) z > 3 * 0.01
    assert agrees(value, low, high, value * 1.001) is True
    assert agrees(value, math.nan, high, meas) is None
