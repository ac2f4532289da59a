"""The estimate of a record's states: :func:`estimate_states` (the record's scales, measurement
noise, initial state, process noise, then the filter and the smoother) and :func:`apply_to_frame`
(a record's table with them)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from study.records.state_estimation.kernels import _ekf, _NZ_I, _NZ_K, _rts
from study.records.state_estimation.noise import measurement_noise
from study.records.state_estimation.options import CHANNELS, GAP_FACTOR, STATES, resolve_options
from study.records.state_estimation.process import process_noise


@dataclass
class StateEstimate:
    """The smoothed states at the record's times: ``frame`` (columns ``time`` and
    :data:`STATES`), ``std`` (their smoothed standard deviations, same columns), and ``settings``
    (what the filter used: the noise standard deviations and whether each was estimated, the
    process noise and how it was chosen, the log-likelihood, the seconds taken);
    JSON-serialisable, as stored in a record's metadata."""

    frame: pd.DataFrame
    std: pd.DataFrame
    settings: dict = field(default_factory=dict)

    def __getitem__(self, key):
        return self.frame[key].to_numpy()


def _column(data, name, n):
    if name in data:
        return np.asarray(data[name], float).reshape(-1)
    return np.full(n, np.nan)


def _lagged(t, a, lag_s):
    """Finite differences over about ``lag_s`` seconds (robust scales and the initial state)."""
    ok = np.isfinite(a)
    tt, aa = t[ok], a[ok]
    if len(tt) < 2:
        return np.zeros(0), np.zeros(0)
    h = float(np.median(np.diff(tt)))
    lag = int(max(1, min(len(tt) - 1, round(lag_s / h))))
    return (aa[lag:] - aa[:-lag]), (tt[lag:] - tt[:-lag])


def _scales(t, Z, h):
    """The record's robust scales (the initial state, the noise floors): the lag [s] of up to ten
    samples, and the 90th percentiles of the speed [m/s] and of the turn rate [rad/s] over it."""
    n = len(t)
    lag_s = h * max(1, min(10, n // 20))
    dx, dtx = _lagged(t, Z[:, 0], lag_s)
    dy, _ = _lagged(t, Z[:, 1], lag_s)
    dpsi, dtp = _lagged(t, Z[:, 2], lag_s)
    speeds = np.hypot(dx, dy) / dtx if len(dx) and len(dx) == len(dy) else np.zeros(1)
    U_typ = float(np.percentile(speeds, 90)) if len(speeds) else 0.0
    rates = np.abs(dpsi) / dtp if len(dpsi) else np.zeros(1)
    r_typ = float(np.percentile(rates, 90)) if len(rates) else 0.0
    return lag_s, U_typ, r_typ


def _initial_state(t, Z, std_used, lag_s, h, U_typ, r_typ):
    """The diffuse initial state [A4] and its covariance: positions and heading from the first
    samples, velocities from a line through the first samples (rotated into body axes),
    accelerations zero."""
    n = len(t)

    def first(j):
        ok = np.nonzero(np.isfinite(Z[:, j]))[0]
        return ok[0] if len(ok) else 0

    k0 = max(first(0), first(1), first(2))
    x_init = np.zeros(9)
    x_init[0], x_init[1], x_init[2] = Z[first(0), 0], Z[first(1), 1], Z[first(2), 2]
    m = int(min(n - 1, max(2, round(lag_s / h))))
    win = slice(k0, min(n, k0 + m + 1))
    tw = t[win]
    if len(tw) >= 3:
        def slope(a):
            ok = np.isfinite(a)
            return float(np.polyfit(tw[ok], a[ok], 1)[0]) if ok.sum() >= 2 else 0.0

        vx, vy, rr = slope(Z[win, 0]), slope(Z[win, 1]), slope(Z[win, 2])
        c0, s0 = math.cos(x_init[2]), math.sin(x_init[2])
        x_init[3], x_init[4], x_init[5] = vx * c0 + vy * s0, -vx * s0 + vy * c0, rr
    T0 = max(lag_s, h)
    sd_uv = max(U_typ, 10.0 * std_used["x0"] / T0, 1e-6)
    sd_r = max(r_typ, 10.0 * std_used["psi"] / T0, 1e-8)
    P_init = np.diag(np.array([
        (3 * std_used["x0"]) ** 2 + (U_typ * (t[k0] - t[0])) ** 2,
        (3 * std_used["y0"]) ** 2 + (U_typ * (t[k0] - t[0])) ** 2,
        (3 * std_used["psi"]) ** 2 + (r_typ * (t[k0] - t[0])) ** 2,
        sd_uv ** 2, sd_uv ** 2, sd_r ** 2, (sd_uv / T0) ** 2, (sd_uv / T0) ** 2, (sd_r / T0) ** 2]))
    return x_init, P_init


def estimate_states(data, options: dict | None = None, **kw) -> StateEstimate:
    """Estimate ``u, v, r, u_dot, v_dot, r_dot`` (and smoothed ``x0, y0, psi``) from a record's
    positions and heading, refining measured ``u, v, r`` when present. The model, the assumptions
    [A1]-[A5] and the sources are in ``docs/concepts/state-estimation.md``.

    Parameters
    ----------
    data : DataFrame or dict of arrays
        ``time`` (s, increasing, any spacing), ``x0``, ``y0`` (m), ``psi`` (rad); optionally ``u``,
        ``v`` (m/s), ``r`` (rad/s). NaN marks a missing sample of a channel (its update is skipped).
    options : dict, optional (or keywords)
        :data:`DEFAULTS`: ``position_std``, ``heading_std``, ``u_std``, ``v_std``, ``r_std``
        (absolute standard deviations or ``"auto"``), ``use_velocities`` (fuse measured u, v, r;
        default true), ``process`` (``"ml"`` or ``{q_uv, q_r}``).

    Returns
    -------
    StateEstimate
    """
    t_start = time.perf_counter()
    opts = resolve_options({**(options or {}), **kw})
    # writable, C-contiguous float64 copies: one compiled signature of each kernel (a read-only or strided
    # array would make numba compile another)
    t = np.array(data["time"], dtype=np.float64, order="C").reshape(-1)
    n = len(t)
    if n < 5:
        raise ValueError(f"state estimation needs at least 5 samples, got {n}")
    dts = np.diff(t)
    if not np.all(dts > 0):
        raise ValueError("state estimation: time must be strictly increasing")
    Z = np.ascontiguousarray(np.column_stack([_column(data, c, n) for c in CHANNELS]), dtype=np.float64)
    for j, c in enumerate(("x0", "y0", "psi")):
        if np.sum(np.isfinite(Z[:, j])) < 5:
            raise ValueError(f"state estimation: column '{c}' has fewer than 5 values; positions x0, y0 and the "
                             "heading psi are needed")
    if not opts["use_velocities"]:
        Z[:, 3:] = np.nan
    has = {c: bool(np.isfinite(Z[:, j]).any()) for j, c in enumerate(CHANNELS)}
    h = float(np.median(dts))
    duration = float(t[-1] - t[0])

    lag_s, U_typ, r_typ = _scales(t, Z, h)
    std_used, auto, R = measurement_noise(Z, opts, has, h, U_typ, r_typ)
    x_init, P_init = _initial_state(t, Z, std_used, lag_s, h, U_typ, r_typ)
    h_max = GAP_FACTOR * h
    q_uv, q_r, info = process_noise(opts["process"], t, Z, R, std_used, x_init, P_init, h, h_max, duration)
    ll, x_f, P_f, x_p, P_p, Fs = _ekf(t, Z, R, q_uv, q_uv, q_r, x_init, P_init, h_max, True, _NZ_I, _NZ_K)
    xs, sd = _rts(x_f, P_f, x_p, P_p, Fs)
    frame = pd.DataFrame({"time": t, **{s: xs[:, i] for i, s in enumerate(STATES)}})
    std = pd.DataFrame({"time": t, **{s: sd[:, i] for i, s in enumerate(STATES)}})
    settings = {
        "method": "ekf_rts",
        "measured": [c for c in CHANNELS if has[c]],
        "noise_std": {c: std_used[c] for c in CHANNELS if has[c]},
        "noise_std_estimated": {c: auto[c] for c in CHANNELS if has[c]},
        "process": {"q_uv": float(q_uv), "q_r": float(q_r)},
        **info,
        "log_likelihood": float(ll),
        "samples": int(n),
        "seconds": round(time.perf_counter() - t_start, 4),
        "options": {k: v for k, v in opts.items()},
    }
    return StateEstimate(frame, std, settings)


#: the columns a record gets from the estimate (u, v, r replaced or added; the derivatives added)
RECORD_COLUMNS = ("u", "v", "r", "u_dot", "v_dot", "r_dot")


def apply_to_frame(df: pd.DataFrame, options: dict | None = None) -> tuple[pd.DataFrame, dict]:
    """A copy of a record's table with ``u, v, r`` estimated (replaced, or added after ``time``
    when missing) and ``u_dot, v_dot, r_dot`` added; positions and heading stay as measured.
    Returns (frame, settings)."""
    est = estimate_states(df, options)
    out = df.copy()
    for c in RECORD_COLUMNS:
        out[c] = est.frame[c].to_numpy()
    lead = ["time"] + [c for c in ("u", "v", "r") if c not in df.columns]
    rest = [c for c in out.columns if c not in lead]
    return out[lead + rest], est.settings
