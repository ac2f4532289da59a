"""How far a replay is from a record: per channel RMSE and NRMSE, the track error, and the
doctor's single number (the mean NRMSE of the scored channels over records: u, v, r and psi, and
the positions x0, y0 too where u, v, r were estimated from them); a diverged replay is inf, never a
percentage."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

CHANNELS = ("u", "v", "r", "psi")
#: The channels scored on a record whose u, v, r the state estimator made: those estimates and the measured
#: positions and heading they came from. The estimates carry the smoother's own error, which no model removes;
#: the positions are measured, and they keep what a replay's velocities leave in the track (a current's drift).
#: Scored alone, the positions rank by a zigzag's cross-track position, whose spread is small: measured on the
#: 7 m KVLCC2 model at 1 % noise, shallow water and a rudder-inflow change then tie, while with the velocities
#: shallow water removes 93 % of the error and the next candidate 62 %.
ESTIMATED_STATES_SCORED = ("u", "v", "r", "psi", "x0", "y0")
UNITS = {"u": "m/s", "v": "m/s", "r": "rad/s", "psi": "rad", "x0": "m", "y0": "m", "track": "m"}


#: the NRMSE counted for a channel whose replay stayed within the envelope but is off by more: beyond ten times
#: the channel's spread a prediction has no shape left to compare. A DIVERGED replay is not capped: its errors
#: are inf and it is reported as diverged (never as a percentage).
NRMSE_CAP = 10.0


def states_estimated(meta: dict | None) -> bool:
    """True for a record whose u, v, r came from the state estimator (``meta['states'] == 'ekf'``:
    ``study.records.schema``): its replay starts from a fitted state (``initial_state``) and is
    scored on ``ESTIMATED_STATES_SCORED``."""
    return (meta or {}).get("states") == "ekf"


def scored_channels(meta: dict | None) -> tuple:
    """The channels a record's error is the mean NRMSE of: ``ESTIMATED_STATES_SCORED`` when its u,
    v, r were estimated (:func:`states_estimated`), else ``CHANNELS``."""
    return ESTIMATED_STATES_SCORED if states_estimated(meta) else CHANNELS


def record_errors(meas: pd.DataFrame, pred: pd.DataFrame | None, floors: dict | None = None,
                  scored: tuple = CHANNELS) -> dict:
    """Per channel RMSE and NRMSE (RMSE over the measured spread, or over ``floors[c]`` when that
    is larger; at most ``NRMSE_CAP``) of a prediction, for u, v, r, psi, x0 and y0; the track
    error (RMSE of the position over the track's extent); ``scored``: the channels
    :func:`record_error` averages (:func:`scored_channels`); a diverged prediction (None) has inf
    errors and ``diverged`` set."""
    out = {"scored": tuple(scored)}
    if pred is None:
        for c in CHANNELS + ("x0", "y0", "track"):
            out[c] = {"rmse": math.inf, "nrmse": math.inf}
        out["diverged"] = True
        return out
    t = pred["time"].to_numpy()
    m = meas[(meas["time"] >= t[0]) & (meas["time"] <= t[-1])]
    for c in CHANNELS + ("x0", "y0"):
        a = m[c].to_numpy()
        b = np.interp(m["time"].to_numpy(), t, pred[c].to_numpy())
        rmse = float(np.sqrt(np.mean((b - a) ** 2)))
        sd = max(float(np.std(a)), (floors or {}).get(c, 0.0))
        out[c] = {"rmse": rmse, "nrmse": min(rmse / sd, NRMSE_CAP) if sd > 0 else NRMSE_CAP}
    dx = np.interp(m["time"].to_numpy(), t, pred["x0"].to_numpy()) - m["x0"].to_numpy()
    dy = np.interp(m["time"].to_numpy(), t, pred["y0"].to_numpy()) - m["y0"].to_numpy()
    tr = float(np.sqrt(np.mean(dx ** 2 + dy ** 2)))
    span = float(np.hypot(np.ptp(m["x0"].to_numpy()), np.ptp(m["y0"].to_numpy())))
    out["track"] = {"rmse": tr, "nrmse": min(tr / span, NRMSE_CAP) if span > 0 else NRMSE_CAP}
    out["diverged"] = False
    return out


def record_error(errors_of_record: dict) -> float:
    """One record's validation error: the mean NRMSE of its scored channels (u, v, r and psi unless
    :func:`record_errors` was told otherwise; inf when its replay diverged)."""
    return float(np.mean([errors_of_record[c]["nrmse"] for c in errors_of_record.get("scored", CHANNELS)]))


def validation_error(errors: dict) -> float:
    """The doctor's single number: the mean over records of :func:`record_error`; inf when a replay diverged (see ``diverged_records``)."""
    vals = [record_error(errors[r]) for r in errors]
    return float(np.mean(vals)) if vals else math.nan


def diverged_records(errors: dict) -> list:
    return [r for r, e in errors.items() if e.get("diverged")]
