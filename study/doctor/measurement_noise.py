"""The measured value's own uncertainty: how far a validation record's noise alone moves the
comparison of a replayed model with it.

A manoeuvre metric read off a noisy record is itself noisy (a heading noise of 2 deg moves the
instant a turn passes 90 deg, and with it the advance), and the replay it is compared with starts
from the record's noisy first state and follows its noisy rudder and propeller rpm. The model's 90 %
interval is an interval for the metric of the ship; to compare it with a measurement, the measurement's error is
added. It is measured on the record itself by a parametric bootstrap (Efron & Tibshirani 1993,
ch. 6): each channel's white-noise sd is estimated by the difference method
(``study.records.state_estimation.noise_std``), fresh noise at that level is added to the record
``PROBES`` times, and each copy is measured and replayed again; the spread of log(replayed /
measured) over the copies is the comparison's noise, ``s_meas`` (on the log scale, as the model's
interval). Assumptions, labelled: the noise is white and additive (filtered or drifting sensors --
a GNSS's slow wander -- are not seen by the difference method, and their error is not covered), and
noise added to an already noisy record moves a metric as much as the record's own noise did (the
metric is locally linear in the noise).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

#: copies of a record with fresh noise (a setting: the robust sd of 16 normal draws is within about 20 % of the true
#: one, see ``prediction_interval.draws_log_sd``)
PROBES = 16
#: the channels a replay or a metric reads from the record (the rudder and the propeller's rpm drive the replay)
CHANNELS = ("u", "v", "r", "x0", "y0", "psi", "delta", "n")
#: a noise estimate below this share of the channel's size is the arithmetic's rounding on a clean record, not noise
ROUNDING = 1e-9


def record_noise(df: pd.DataFrame) -> dict:
    """{channel: white-noise sd} of the record's :data:`CHANNELS` (difference method); channels
    without noise (a clean simulation) are left out."""
    from study.records.state_estimation import noise_std

    out = {}
    for c in CHANNELS:
        if c in df.columns:
            a = df[c].to_numpy(float)
            s = float(noise_std(a))
            if math.isfinite(s) and s > ROUNDING * max(1.0, float(np.nanmax(np.abs(a)))):
                out[c] = s
    return out


def noisy_copies(df: pd.DataFrame, sd: dict, probes: int = PROBES, seed: int = 0) -> list:
    """``probes`` copies of ``df`` with fresh white noise of ``sd`` (per channel) added;
    deterministic in ``seed``."""
    rng = np.random.default_rng([int(seed), 0x4D45])
    return [df.assign(**{c: df[c].to_numpy(float) + s * rng.standard_normal(len(df)) for c, s in sd.items()})
            for _ in range(probes)]


def comparison_spread(copies: list, measure, replay) -> dict:
    """{metric: {'s_meas', 'probes'}}: the robust sd over the ``copies`` of log(replayed /
    measured) (``prediction_interval.draws_log_sd`` of its exponential). ``measure(copy)`` gives
    ``{metric: value}`` of a copy, ``replay(copy)`` the replay's ``{metric: value}`` (empty when
    it diverged). A metric that fewer than half the copies give is left out."""
    from . import prediction_interval as pi

    ratios = {}
    for c in copies:
        meas, pred = measure(c), replay(c)
        for m, x in meas.items():
            y = pred.get(m, math.nan)
            ratios.setdefault(m, []).append(y / x if x and math.isfinite(x) and math.isfinite(y) else math.nan)
    out = {}
    for m, r in ratios.items():
        s, n = pi.draws_log_sd(r)
        if math.isfinite(s):
            out[m] = {"s_meas": s, "probes": n}
    return out


def measured_interval(row: dict, spread: dict, level: float = 0.9) -> None:
    """Set ``measured_low``, ``measured_high`` and ``measured_noise`` of a ``maneuver_metrics``
    row from its metric's comparison spread (nothing when the metric has none)."""
    from . import prediction_interval as pi

    got = spread.get(row["metric"])
    x = row.get("measured", math.nan)
    if got is None or not (isinstance(x, float) and math.isfinite(x) and x > 0):
        return
    w = pi.z_of(level) * got["s_meas"]
    row["measured_low"], row["measured_high"] = float(x * math.exp(-w)), float(x * math.exp(w))
    row["measured_noise"] = {"s_meas": float(got["s_meas"]), "probes": int(got["probes"])}


def agrees(row: dict, level: float = 0.9) -> bool | None:
    """Whether a ``maneuver_metrics`` row's final prediction and its measurement agree, the
    measured value's own noise included (``prediction_interval.agrees``); None without both."""
    from .prediction_interval import agrees as within

    return within(row.get("final", math.nan), row.get("final_low", math.nan), row.get("final_high", math.nan),
                  row.get("measured", math.nan), (row.get("measured_noise") or {}).get("s_meas", 0.0), level)
