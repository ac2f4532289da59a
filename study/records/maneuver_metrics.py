"""A replayed model compared in the ship's own terms: standard manoeuvre metrics of each validation
record, measured against the replays of two models (the doctor's baseline and final model; a run on
files' identified
model).

:func:`maneuver_metrics` gives one row per record and metric, ``{'record', 'metric', 'unit',
'measured', 'baseline', 'final'}``; ``study.doctor.html.metrics_table_html`` renders such rows as a
small HTML table (the doctor's report). The metrics are those of :mod:`study.records.metrics` (IMO
MSC.137(76), MSC/Circ.1053, ITTC 7.5-04-02-01), computed with the same functions on the measured
record and on both replays:

- **turning circle**: ``advance``, ``transfer``, ``tactical_diameter`` [m] and the same in ship
  lengths (``advance_L``, ``transfer_L``, ``tactical_diameter_L`` [L]), ``steady_turning_rate``
  [deg/s];
- **zigzag**: ``first_overshoot``, ``second_overshoot`` [deg], ``period``, ``initial_turning_time``
  and ``time_to_check_yaw`` [s];
- **anything else** (random rudder, straight runs): no rows -- the per-channel errors of the report
  cover them.

Choices made here:

- *The kind* is found on the **measured** record and used for all three columns (a replay uses the
  measured rudder, so it is the same manoeuvre). A record that
  :func:`study.records.metrics.detect_maneuver` calls a zigzag is taken whole. Otherwise a rudder
  test of this module (:func:`_own_kind`) looks for the manoeuvre at the end of the record: a real
  record often starts with the helmsman's course keeping (the Esso Osaka pond runs), where the
  execution of :mod:`study.records.metrics` (the first rudder movement) would fall, so that
  ``detect_maneuver`` calls it "other", or a turning circle with its origin in the approach. When
  the test finds a turning circle or a zigzag, the three records are cut at the start of the rudder
  movement into it (keeping the quiet rudder just before it) before the metrics, and the doctor's
  two replays for them start there, from the measured state (:func:`manoeuvre_start`): replayed from
  the start of the record, a model arrives at the execution with the approach's accumulated errors
  (an Esso Osaka run starts at rest, where an MMG model is not meant to work), and the metrics would
  compare the approach, not the manoeuvre. A clean simulated record is not cut. A record the test
  rejects and ``detect_maneuver`` calls a turning circle is taken whole; anything else gives no
  rows.
- *Overshoots of a replay* are measured from the **measured** record's switch heading (the heading
  change at its first rudder reversal; their own when the measured record has none): the replay
  reverses its rudder when the ship did, not at its own heading, and the same reference compares the
  heading extremes themselves.
- *Period* is the standard one (IMO/ITTC; ``period`` of
  :func:`study.records.metrics.zigzag_metrics`, between rudder movements). In an open-loop replay
  the rudder moves when it did in the measurement, so the replays' period equals the measured one by
  construction (it is shown because it characterises the record); the model's own timing shows in
  ``initial_turning_time`` (rudder execution to the switch heading) and ``time_to_check_yaw`` (first
  rudder reversal to the heading's extreme), both from the same function.
- *Steady turning rate* is ``steady_turning_rate_deg`` of
  :func:`study.records.metrics.turning_metrics` (mean |r| on the steady part of the turn). Its band
  of a steady yaw rate is 2 %; when that finds no steady stretch on the measured record (wind and
  noise make a real turn's r wander), the first of 5, 10 and 20 % that does, the same band then for
  the measured record and both replays.
- A metric that a record cannot carry (the turn never reaches 180 deg, the record ends before the
  second overshoot, a function of :mod:`study.records.metrics` raising on a short or odd record) or
  a replay that diverged (``None``) is NaN, never an exception.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from study.records import metrics as M

__all__ = ["maneuver_metrics", "TURNING_METRICS", "ZIGZAG_METRICS"]

_NAN = float("nan")

#: (metric, unit, description) in the order of the rows
TURNING_METRICS = (
    ("tactical_diameter", "m", "distance across the initial course at 180 deg heading change"),
    ("advance", "m", "distance along the initial course at 90 deg heading change"),
    ("transfer", "m", "distance across the initial course at 90 deg heading change"),
    ("tactical_diameter_L", "L", "tactical diameter in ship lengths"),
    ("advance_L", "L", "advance in ship lengths"),
    ("transfer_L", "L", "transfer in ship lengths"),
    ("steady_turning_rate", "deg/s", "mean |r| on the steady part of the turn"),
)
ZIGZAG_METRICS = (
    ("first_overshoot", "deg", "heading change beyond the switch heading after the first rudder reversal"),
    ("second_overshoot", "deg", "heading change beyond the switch heading after the second rudder reversal"),
    ("period", "s", "mean time between rudder movements to the same side (set by the measured rudder in a replay)"),
    ("initial_turning_time", "s", "time from the rudder execution to the switch heading"),
    ("time_to_check_yaw", "s", "time from the first rudder reversal to the heading's extreme"),
)
COLUMNS = ("measured", "baseline", "final")

STEADY_TOLS = (0.02, 0.05, 0.1, 0.2)  # bands tried for the steady turn (see _steady_tol)
_BIG = 0.8  # the rudder "holds" the manoeuvre's angle P when |delta| >= 0.8 P (see _own_kind)
_NEED = ("time", "u", "v", "r", "x0", "y0", "psi", "delta")


# ---------------------------------------------------------------------------------------------- the kind
def _usable(df) -> bool:
    return isinstance(df, pd.DataFrame) and len(df) >= 3 and all(c in df.columns for c in ("time", "delta", "psi"))


def _noise_sigma(delta: np.ndarray) -> float:
    """Robust noise sigma of the rudder from its first differences (as
    :mod:`study.records.metrics` estimates it)."""
    dd = np.diff(delta)
    if dd.size == 0:
        return 0.0
    return 1.4826 * float(np.median(np.abs(dd - np.median(dd)))) / math.sqrt(2)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs ``[a, b)`` of True in ``mask``."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))


def _own_kind(df: pd.DataFrame) -> tuple[str, float | None]:
    """Rudder test for records whose first rudder movement is not the manoeuvre's (manual
    course-keeping before a turning circle or zigzag, as in the Esso Osaka pond runs): ``(kind,
    t0)``, ``t0`` the time from which the records are to be cut (None: from their start).

    The manoeuvre's rudder angle ``P`` is the 90th percentile of |delta| over the second half of the
    record (where the manoeuvre is); *holds* are the runs of |delta| >= 0.8 P. From the last hold
    backwards, holds are chained while the rudder goes straight from one to the next (a monotone
    movement to the other side: a zigzag's reversal; or a dip on the same side that stays above
    P/2); the approach's steering breaks the chain. One hold (or a last hold three times as long as
    the rest of the chain: a short counter-steer before the turn) with 90 deg of heading change and
    no excursion to the other side after it is a turning circle; three or more covering 30 % of the
    record, each reversed with the heading on the side of its rudder (at a heading change within a
    factor 3 of the first), a zigzag. The records are cut at the start of the movement into the
    chain's first hold, keeping the quiet rudder just before it.
    """
    t = df["time"].to_numpy(float)
    delta = df["delta"].to_numpy(float)
    psi = df["psi"].to_numpy(float)
    ok = np.isfinite(t) & np.isfinite(delta) & np.isfinite(psi)
    t, delta, psi = t[ok], delta[ok], psi[ok]
    n = len(t)
    if n < 10 or np.any(np.diff(t) <= 0):
        return "other", None
    P = float(np.percentile(np.abs(delta[n // 2:]), 90))
    if P < math.radians(1.0):
        return "other", None
    tol = max(math.radians(M.EXEC_THRESHOLD_DEG), 6.0 * _noise_sigma(delta))
    holds = sorted([(a, b, 1.0) for a, b in _runs(delta >= _BIG * P)]
                   + [(a, b, -1.0) for a, b in _runs(delta <= -_BIG * P)])
    if not holds:
        return "other", None
    chain = [holds[-1]]
    for a, b, s in reversed(holds[:-1]):
        a1, b1, s1 = chain[0]
        gap = s1 * delta[b - 1:a1 + 1]  # from the last sample of this hold to the first of the next
        if s == s1 and float(np.min(gap)) >= 0.5 * P:
            chain[0] = (a, b1, s1)  # a dip on the same side: one hold
        elif s != s1 and np.all(gap >= np.maximum.accumulate(gap) - tol):
            chain.insert(0, (a, b, s))  # a reversal
        else:
            break
    a, b, s = chain[-1]
    if (b - a >= 0.75 * (b - chain[0][0]) and abs(psi[b - 1] - psi[a]) >= math.pi / 2
            and not np.any(-s * delta[b:] > 0.25 * P)):
        chain = [chain[-1]]  # a turn after a short counter-steer of the approach: the turn alone
    a0, _, s0 = chain[0]
    j = a0  # start of the movement into the first hold: back along its monotone ramp ...
    while j > 0 and s0 * delta[j - 1] < s0 * delta[j]:
        j -= 1
    j0 = j  # ... and back over the quiet rudder before it
    while j0 > 0 and abs(delta[j0 - 1] - delta[j]) <= tol:
        j0 -= 1
    t0 = float(t[j0]) if j0 > 0 else None
    if len(chain) == 1:
        a, b, s = chain[0]
        if abs(psi[b - 1] - psi[j]) >= math.pi / 2 and not np.any(-s * delta[b:] > 0.25 * P):
            return "turning", t0
        return "other", None
    if len(chain) < 3 or t[chain[-1][1] - 1] - t[j] < 0.3 * (t[-1] - t[0]):
        return "other", None
    head = [s * (psi[b - 1] - psi[j]) for a, b, s in chain[:-1]]  # heading change at each reversal
    if head[0] <= math.radians(0.5) or any(h < head[0] / 3 or h > 3 * head[0] for h in head):
        return "other", None
    return "zigzag", t0


def _kind(measured) -> tuple[str, float | None]:
    """The manoeuvre of the measured record and the time to cut the records from (None: not cut)."""
    if not _usable(measured):
        return "other", None
    try:
        k0 = M.detect_maneuver(measured)
    except Exception:  # noqa: BLE001 -- an odd record is "other", not an error of the report
        k0 = "other"
    if k0 == "zigzag":  # its checks are strict (and it keeps multi-stage zigzags whole)
        return k0, None
    try:
        kind, t0 = _own_kind(measured)
    except Exception:  # noqa: BLE001
        kind, t0 = "other", None
    if kind in ("turning", "zigzag"):
        return kind, t0
    return ("turning", None) if k0 == "turning" else ("other", None)


def manoeuvre_start(measured) -> float | None:
    """The time a measured record's manoeuvre starts (where :func:`maneuver_metrics` cuts the
    records), None when it is taken whole. The doctor replays a cut record from its measured state
    there (see
    ``study.doctor.report.manoeuvre_predictions``)."""
    return _kind(measured)[1]


# ---------------------------------------------------------------------------------------------- the metrics
def _clean(df, t0: float | None):
    """The record as the metrics need it (time-sorted, finite), cut from ``t0``; None when it
    cannot be used."""
    if not isinstance(df, pd.DataFrame) or any(c not in df.columns for c in _NEED):
        return None
    d = df.loc[:, list(_NEED)].apply(pd.to_numeric, errors="coerce")
    d = d[np.all(np.isfinite(d.to_numpy(float)), axis=1)]
    if t0 is not None:
        d = d[d["time"] >= t0 - 1e-9]
    d = d.sort_values("time").drop_duplicates("time")
    return d.reset_index(drop=True) if len(d) >= 3 else None


def _f(x) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return _NAN
    return v if math.isfinite(v) else _NAN


def _turning(df, L: float | None, steady_tol: float = 0.02) -> dict:
    out = {m: _NAN for m, _, _ in TURNING_METRICS}
    if df is None:
        return out
    try:
        tm = M.turning_metrics(df, L=L, steady_tol=steady_tol)
    except Exception:  # noqa: BLE001 -- e.g. the heading never changes 90 deg: NaN
        return out
    for m in ("tactical_diameter", "advance", "transfer"):
        out[m] = _f(tm.get(m))
        out[m + "_L"] = _f(tm.get(m + "_L"))
    out["steady_turning_rate"] = _f(tm.get("steady_turning_rate_deg"))
    return out


def _steady_tol(df, L: float | None) -> float:
    """The band of :func:`study.records.metrics.turning_metrics`'s steady turn for this measured
    record: its 2 %, else the first of 5, 10, 20 % that finds a steady stretch (wind and noise
    make a real turn's r wander)."""
    for tol in STEADY_TOLS:
        if math.isfinite(_turning(df, L, tol)["steady_turning_rate"]):
            return tol
    return STEADY_TOLS[0]


def _zigzag(df, psi_switch: float | None) -> tuple[dict, float | None]:
    """The zigzag rows of one record and its switch heading [rad] (None when unknown)."""
    out = {m: _NAN for m, _, _ in ZIGZAG_METRICS}
    if df is None:
        return out, None
    try:
        zm = M.zigzag_metrics(df, psi_switch=psi_switch)
    except Exception:  # noqa: BLE001 -- no reversal, heading on the wrong side, short record: NaN
        return out, None
    out["first_overshoot"] = _f(zm.get("overshoot_1"))
    out["second_overshoot"] = _f(zm.get("overshoot_2"))
    for k in ("period", "initial_turning_time", "time_to_check_yaw"):
        out[k] = _f(zm.get(k))
    sw = _f(zm.get("psi_switch_deg"))
    return out, (math.radians(sw) if math.isfinite(sw) and sw > 0 else None)


def maneuver_metrics(name: str, measured: pd.DataFrame, baseline: pd.DataFrame | None,
                     final: pd.DataFrame | None, L: float) -> list[dict]:
    """Standard manoeuvre metrics of one validation record, measured against the two replays.

    Parameters
    ----------
    name : str
        The record's name (the ``record`` of every row).
    measured : DataFrame
        The measured record (``time, u, v, r, x0, y0, psi, delta``; SI units, radians).
    baseline, final : DataFrame or None
        The baseline and the final model replayed through the record (same columns), or None when
        the replay diverged: that column is NaN.
    L : float
        Ship length [m] for the ``*_L`` rows (NaN there when it is not a positive number).

    Returns
    -------
    list of dict
        Rows ``{'record', 'metric', 'unit', 'measured', 'baseline', 'final'}`` (values floats, NaN
        where the metric cannot be measured): for a turning circle :data:`TURNING_METRICS`, for a
        zigzag :data:`ZIGZAG_METRICS`, for anything else none. Never raises on odd records (see the
        module docstring).
    """
    kind, t0 = _kind(measured)
    if kind not in ("turning", "zigzag"):
        return []
    Lf = _f(L)
    Lf = Lf if Lf > 0 else None
    frames = [_clean(d, t0) for d in (measured, baseline, final)]
    if kind == "turning":
        tol = _steady_tol(frames[0], Lf)
        vals = [_turning(d, Lf, tol) for d in frames]
        spec = TURNING_METRICS
    else:
        first, sw = _zigzag(frames[0], None)
        vals = [first] + [_zigzag(d, sw)[0] for d in frames[1:]]
        spec = ZIGZAG_METRICS
    return [{"record": str(name), "metric": m, "unit": u, **{c: v[m] for c, v in zip(COLUMNS, vals)}}
            for m, u, _ in spec]
