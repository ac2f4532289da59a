"""Sample structures: how a record's samples become (state, acceleration) pairs for regression.

- ``euler``: forward difference a_k = (x_{k+1} - x_k)/h paired with the state at k (seed 000, eq. 14).
- ``central``: central difference a_k = (x_{k+1} - x_{k-1})/(2h), state at k (seed 004, eqs. 14-17).

Pairs that span a gap (a dropout: time step above 1.5 times the median) are left out, so records with
missing samples stay usable. The next issue adds the differenced/centred, integral, smoothed and
output-error structures to this registry.
"""
from __future__ import annotations

import numpy as np

STATE_COLS = ("u", "v", "r", "delta", "n")
RATE_COLS = ("u", "v", "r")


def _gap_mask(dt: np.ndarray) -> np.ndarray:
    h = np.median(dt)
    return dt <= 1.5 * h


def euler(df):
    t = df["time"].to_numpy()
    dt = np.diff(t)
    ok = _gap_mask(dt)
    states = {c: df[c].to_numpy()[:-1][ok] for c in STATE_COLS}
    rates = np.column_stack([np.diff(df[c].to_numpy())[ok] / dt[ok] for c in RATE_COLS])
    return states, rates


def central(df):
    t = df["time"].to_numpy()
    dt = np.diff(t)
    ok = _gap_mask(dt[:-1]) & _gap_mask(dt[1:])
    span = t[2:] - t[:-2]
    states = {c: df[c].to_numpy()[1:-1][ok] for c in STATE_COLS}
    rates = np.column_stack([(df[c].to_numpy()[2:] - df[c].to_numpy()[:-2])[ok] / span[ok] for c in RATE_COLS])
    return states, rates


STRUCTURES = {"euler": euler, "central": central}


def get_structure(name: str):
    if name not in STRUCTURES:
        raise ValueError(f"unknown sample structure '{name}'; known: {sorted(STRUCTURES)}")
    return STRUCTURES[name]
