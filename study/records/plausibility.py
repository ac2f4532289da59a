"""Plausibility checks of a record against itself: do its channels agree with each other in the
schema's units?

``study.records.schema.validate`` runs these after the structural checks (columns, NaN, time order,
limits). Each finding names the column, the row where it applies, what was found and the likely fix;
``validate`` adds the file.

The channels of a record are redundant: the heading is the integral of the yaw rate, the track the
integral of the body velocities turned by the heading, the course of the track the heading plus the
drift angle. A unit mistake breaks that redundancy by a known factor (degrees: 57.3, milliseconds:
1000, knots: 1.944...), which the checks recognise:

1. **yaw rate against heading**: over windows of the record, the change of ``psi`` against the
   integral of ``r``; their ratio is 1 in the schema's units, 57.3 with the heading in degrees,
   1/57.3 with the yaw rate in deg/s (which the schema's limit of 2 rad/s misses below 2 deg/s:
   every full-scale ship);
2. **heading against the track's course**: the change of the course over ground (direction of the
   track's displacement over a window, from ``x0, y0``) less the drift angle ``atan2(v, u)`` against
   the change of ``psi``; catches a heading and a yaw rate both in degrees (their ratio is then 1);
3. **body velocities against the track**: the displacement of ``x0, y0`` over each window against
   the integral of ``(u, v)`` turned by ``psi``; 1 in the schema's units, 1/1000 with time in
   milliseconds (then check 1 says 1/1000 too), 1/1.944 with speeds in knots, 1/3.6 in km/h, 1/1000
   with positions in km;
4. **time units from the sample interval**: a median interval above 5 "seconds" (records for
   identification are sampled at 0.01-1 s) is named as probably milliseconds when no check above
   confirms or refutes it;
5. **position jumps**: a step of ``x0, y0`` that the velocities do not explain, by far more than the
   track's own scatter: a single step that stays (two records joined end to end) or a spike that
   returns (a position
   glitch);
6. **constant channels**: a motion or rudder channel with one value throughout (a sensor not
   logged);
7. **mirrored track**: the track's course does not follow the heading, but does with ``x0`` and
   ``y0`` exchanged (check 2 on the mirrored track): the columns swapped, or a heading counted
   anticlockwise; judged from positions and heading (and ``u, v`` where given), so it holds for
   records whose ``u, v, r`` are to be estimated.

A ratio is judged only where the record says it clearly: enough windows, enough change, and a fit
that explains at least :data:`MIN_FIT` of the windows' squared increments. A ratio within
:data:`UNIT_TOLERANCE` of a unit factor is an **error** (the mistake is certain, the fix is named);
any other ratio outside :data:`AGREE` is a **warning** (a suspicion: a calibration, a current,
water-relative velocities, a different reference point). The thresholds were set on every real
record of ``../shared/data/real`` (HSVA's KVLCC2 and Osaka University's Esso Osaka: all pass without
a finding) and on simulated records of every vessel at every noise definition
(``tests/records/test_plausibility.py``); their reasons are in ``docs/schema.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

# ------------------------------------------------------------------------------------------------ thresholds
# Windows over which increments are compared: long enough that the noise of one end point is small against the
# change over the window, many enough for a fit; about WINDOW_SAMPLES samples each, between MIN_WINDOWS and
# MAX_WINDOWS of them.
WINDOW_SAMPLES = 40
MIN_WINDOWS = 8
MAX_WINDOWS = 60
# A ratio is judged only when the fit through the origin explains this fraction of the windows' squared
# increments (1 - sum (D - k I)^2 / sum D^2): noise or an unmodelled drift below it, the record says nothing
# clear, and nothing is reported.
MIN_FIT = 0.9
# The ratio agrees with the schema's units within this factor (a current, a calibration, a reference point off
# midship move it by a few per cent; a unit mistake by 1.9 and more).
AGREE = 1.5
# A ratio within this factor of a unit factor names that unit mistake (an error).
UNIT_TOLERANCE = 1.15
# A track is judged mirrored (x0, y0 swapped) when its course changes against the heading while the exchanged
# track's course follows it with at least this ratio and fit (loose: see check()).
MIRROR_RATIO = 0.5
MIRROR_FIT = 0.5
# The median sample interval above which the time is suspected to be in milliseconds.
MAX_SAMPLE_INTERVAL = 5.0
# Position jumps: the step's residual (displacement minus the integral of the velocities) against the median
# residual of all steps (a robust scale of the track's scatter: noise and integration error), and against the
# distance the velocities cover in that step.
JUMP_SCATTER = 50.0
JUMP_STEP = 5.0
# ... and against the track's extent (the diagonal of its bounding box): two records joined end to end jump by a
# good part of it; the real records' GNSS steps reach 1.7 % of it (Esso Osaka, 0.7 m in 42 m), HSVA's none.
JUMP_EXTENT = 0.1
# A spike returns: the next step's residual undoes at least this fraction of the jump.
SPIKE_RETURN = 0.5
# Channels that must vary in a manoeuvre (n, depth, wind may well be constant).
VARYING = ("u", "v", "r", "psi", "x0", "y0", "delta")
# A constant u (v) is confirmed by the track when the velocities miss the track's displacement along (across) the
# heading by at most CONSTANT_MISS times what they miss across (along) it (both then noise), or by at most
# TINY_MISS of the displacement itself (noise-free).
CONSTANT_MISS = 3.0
TINY_MISS = 1e-3

DEG = 180.0 / math.pi
# (factor, what it means, fix): ratio = change seen in the reference / integral of the rate.
R_FACTORS = (
    (DEG, "psi looks like degrees (its change is 57.3 times the integral of r)", "convert psi with numpy.deg2rad"),
    (1 / DEG, "r looks like deg/s (its integral is 57.3 times the change of psi)", "convert r with numpy.deg2rad"),
)
TIME_FACTORS = (
    (1e-3, "time looks like milliseconds", "divide time by 1000"),
    (60.0, "time looks like minutes", "multiply time by 60"),
)
UV_FACTORS = (
    (1 / 1.943844, "u, v look like knots", "multiply u and v by 0.514444 (1 kn = 1852/3600 m/s)"),
    (1 / 3.6, "u, v look like km/h", "divide u and v by 3.6"),
    (1e-3, "x0, y0 look like km (or u, v like mm/s)", "multiply x0 and y0 by 1000"),
    (1e3, "x0, y0 look like mm (or u, v like km/s)", "divide x0 and y0 by 1000"),
)
COURSE_FACTORS = (
    (1 / DEG, "psi looks like degrees (its change is 57.3 times the change of the track's course)",
     "convert psi with numpy.deg2rad"),
)


@dataclass(frozen=True)
class Finding:
    level: str  # "error" | "warning"
    column: str
    row: int | None
    message: str  # without the file; study.records.schema.validate puts it in front


@dataclass(frozen=True)
class Ratio:
    """A fitted ratio reference increment / rate integral over windows, with its fit and support,
    and the rows of the window that departs most from ratio 1 (where to look)."""

    k: float
    fit: float
    windows: int
    rows: tuple = (0, 0)

    @property
    def judged(self) -> bool:
        return self.windows >= MIN_WINDOWS // 2 and self.fit >= MIN_FIT and math.isfinite(self.k) and self.k > 0


def _g(x: float) -> str:
    return f"{x:.4g}"


def windows(n: int) -> np.ndarray:
    """Window boundaries (indices) splitting ``n`` samples into about WINDOW_SAMPLES-sample
    windows."""
    m = int(np.clip(n // WINDOW_SAMPLES, MIN_WINDOWS, MAX_WINDOWS))
    m = max(1, min(m, n - 1))
    return np.unique(np.round(np.linspace(0, n - 1, m + 1)).astype(int))


def _cumtrapz(y: np.ndarray, t: np.ndarray) -> np.ndarray:
    from scipy.integrate import cumulative_trapezoid

    return cumulative_trapezoid(y, t, initial=0.0)


def fit_ratio(D: np.ndarray, I: np.ndarray, starts=None, ends=None) -> Ratio:
    """k of D = k I through the origin (D, I: increments per window; rows may be 2-vectors), with
    the fraction of sum |D|^2 it explains; ``starts``, ``ends``: the windows' first and last
    rows."""
    D = np.asarray(D, float).reshape(len(D), -1)
    I = np.asarray(I, float).reshape(len(I), -1)
    ii, dd = float(np.sum(I * I)), float(np.sum(D * D))
    if not (ii > 0 and dd > 0):
        return Ratio(float("nan"), 0.0, len(D))
    k = float(np.sum(D * I)) / ii
    fit = 1.0 - float(np.sum((D - k * I) ** 2)) / dd
    rows = (0, 0)
    if starts is not None and len(D):
        j = int(np.argmax(np.sum((D - I) ** 2, axis=1)))
        rows = (int(starts[j]), int(ends[j]))
    return Ratio(k, fit, len(D), rows)


def _match(k: float, factors) -> tuple | None:
    for f, what, fix in factors:
        if abs(math.log(k / f)) < math.log(UNIT_TOLERANCE):
            return f, what, fix
    return None


def _agrees(k: float) -> bool:
    return abs(math.log(k)) < math.log(AGREE)


def ratios(df: pd.DataFrame) -> dict:
    """The record's three ratios (``r``: heading change / integral of r; ``uv``: track
    displacement / integral of the turned velocities; ``course``: change of the track's course
    less the drift angle / change of psi), what the velocities miss of the track along and across
    the heading (``missed``), and the window boundaries."""
    t = df["time"].to_numpy(float)
    psi = df["psi"].to_numpy(float)
    u, v, r = (df[c].to_numpy(float) for c in ("u", "v", "r"))
    x, y = df["x0"].to_numpy(float), df["y0"].to_numpy(float)
    b = windows(len(t))
    s, e = b[:-1], b[1:]
    R = _cumtrapz(r, t)
    out = {"bounds": b, "r": fit_ratio(psi[e] - psi[s], R[e] - R[s], s, e)}
    cx = _cumtrapz(u * np.cos(psi) - v * np.sin(psi), t)
    cy = _cumtrapz(u * np.sin(psi) + v * np.cos(psi), t)
    D = np.column_stack([x[e] - x[s], y[e] - y[s]])
    I = np.column_stack([cx[e] - cx[s], cy[e] - cy[s]])
    out["uv"] = fit_ratio(D, I, s, e)
    # what the velocities miss of the track, along the heading and across it (RMS over the windows): a constant
    # u or v is confirmed when its own direction misses no more than the other
    E, h = D - I, np.array([np.mean(psi[a:z + 1]) for a, z in zip(s, e)])
    along = E[:, 0] * np.cos(h) + E[:, 1] * np.sin(h)
    across = -E[:, 0] * np.sin(h) + E[:, 1] * np.cos(h)
    out["missed"] = {"u": float(np.sqrt(np.mean(along ** 2))), "v": float(np.sqrt(np.mean(across ** 2))),
                     "track": float(np.sqrt(np.mean(np.sum(D ** 2, axis=1))))}
    # course of each window's displacement less the drift angle atan2(v, u) (both in radians whatever psi's unit)
    # against the heading, each averaged over the window; windows at rest have no course
    drift = np.array([np.mean(np.arctan2(v[a:z + 1], u[a:z + 1])) for a, z in zip(s, e)])
    head = np.array([np.mean(psi[a:z + 1]) for a, z in zip(s, e)])
    moving = np.hypot(D[:, 0], D[:, 1]) > 0.5 * np.median(np.hypot(D[:, 0], D[:, 1]))
    mid = ((s + e) // 2)[moving]
    dh = np.diff(head[moving])
    # the same with x0 and y0 exchanged ("course_mirrored"): the hypothesis that the track is mirrored
    for key, (a, b) in (("course", (1, 0)), ("course_mirrored", (0, 1))):
        course = np.unwrap(np.arctan2(D[:, a], D[:, b]))
        dc = np.diff(course[moving] - drift[moving])
        out[key] = (fit_ratio(dc, dh, mid[:-1], mid[1:]) if dc.size >= 2
                    else Ratio(float("nan"), 0.0, int(dc.size)))
    return out


def _at(R: Ratio) -> str:
    return f"rows {R.rows[0]}-{R.rows[1]} disagree most"


def _time_unit(kr: Ratio, kuv: Ratio, h: float):
    """(factor, what, fix) when the track and the yaw rate both say the time is in other units,
    else None. The track alone (ratio 1/1000) could also be positions in km: then the yaw rate
    decides, or without a turn the sample interval (above 1 'second' with 1/1000: milliseconds)."""
    for R in (kuv, kr):
        m = _match(R.k, TIME_FACTORS) if R.judged else None
        if m is None:
            continue
        other = kr if R is kuv else kuv
        if other.judged:
            if _match(other.k, TIME_FACTORS) == m:
                return m
            continue
        if (m[0] == 1e-3 and h > 1.0) or (m[0] == 60.0 and h < 0.02):
            return m
    return None


def check(df: pd.DataFrame) -> list[Finding]:
    """Every plausibility finding of a structurally valid record (see the module docstring)."""
    out: list[Finding] = []
    t = df["time"].to_numpy(float)
    n = len(t)
    q = ratios(df)
    kr, kuv, kc = q["r"], q["uv"], q["course"]
    # a constant channel that its redundant partner confirms is no finding: r or psi when they agree; u (v) when
    # the track along (across) the heading is missed by no more than across (along) it, or by next to nothing (a
    # Nomoto vessel's simulated v = 0 and constant u)
    miss = q["missed"]
    confirmed = {"r": kr.judged and _agrees(kr.k), "psi": kr.judged and _agrees(kr.k)}
    for c, o in (("u", "v"), ("v", "u")):
        confirmed[c] = miss[c] <= CONSTANT_MISS * miss[o] or miss[c] <= TINY_MISS * miss["track"]
    for c in VARYING:
        a = df[c].to_numpy(float)
        if n and np.all(a == a[0]) and not confirmed.get(c, False):
            out.append(Finding("warning", c, 0, f"column '{c}' is {_g(a[0])} in all {n} rows: a sensor that was "
                                                f"not logged? fill it from the real signal or drop the record"))
    h = float(np.median(np.diff(t)))
    m = _time_unit(kr, kuv, h)
    if m is not None:
        out.append(Finding("error", "time", None, f"column 'time': {m[1]} (median sample interval {_g(h)}; the "
                                                  f"track x0, y0 moves {_g(kuv.k)} times the distance u, v give in "
                                                  f"that time, psi changes {_g(kr.k)} times the integral of r); "
                                                  f"{m[2]}"))
        return out
    if h > MAX_SAMPLE_INTERVAL and not (kuv.judged and _agrees(kuv.k)):
        out.append(Finding("warning", "time", None, f"column 'time': median sample interval {_g(h)} s, coarser than "
                                                    f"the 0.01-1 s of manoeuvring records: milliseconds? then "
                                                    f"divide time by 1000"))
    psi_deg = False
    if kr.judged and not _agrees(kr.k):
        m = _match(kr.k, R_FACTORS)
        if m:
            psi_deg = m[0] == DEG
            col = "psi" if psi_deg else "r"
            out.append(Finding("error", col, kr.rows[0], f"column '{col}': {m[1]}: ratio {_g(kr.k)} over {kr.windows} "
                                                         f"windows, expected 1 ({_at(kr)}); {m[2]}"))
        else:
            out.append(Finding("warning", "r", kr.rows[0], f"columns 'r' and 'psi' disagree: psi changes {_g(kr.k)} "
                                                           f"times the integral of r, expected 1 ({_at(kr)}): are "
                                                           f"they in rad/s and rad, with the same sign?"))
    if not psi_deg and kc.judged and not _agrees(kc.k):
        m = _match(kc.k, COURSE_FACTORS)
        if m:
            psi_deg = True
            both = kr.judged and _agrees(kr.k)
            out.append(Finding("error", "psi", kc.rows[0],
                               f"column 'psi': {m[1]}: ratio {1 / kc.k:.4g}, expected 1 ({_at(kc)})"
                               + ("; so is r (deg/s), which agrees with psi" if both else "")
                               + f"; {m[2]}" + (" and r too" if both else "")))
    m = _mirrored(kc, q["course_mirrored"]) if not psi_deg else None
    if m is not None:
        return out + [m]
    if not psi_deg and kuv.judged and not _agrees(kuv.k):
        m = _match(kuv.k, UV_FACTORS)
        if m:
            out.append(Finding("error", "u", kuv.rows[0], f"columns 'u', 'v' against x0, y0: {m[1]}: the track moves "
                                                          f"{_g(kuv.k)} times the distance u, v give, expected 1 "
                                                          f"({_at(kuv)}); {m[2]}"))
        else:
            out.append(Finding("warning", "u", kuv.rows[0], f"columns 'u', 'v' disagree with the track x0, y0: it "
                                                            f"moves {_g(kuv.k)} times the distance that u, v turned "
                                                            f"by psi give, expected 1 ({_at(kuv)}): u, v over "
                                                            f"ground, in body axes, in m/s?"))
    if not psi_deg:
        out += _jumps(df)
    return out


def _mirrored(kc: Ratio, km: Ratio) -> Finding | None:
    """The finding of a mirrored track (check 7) from the course ratios of the track and of the
    exchanged track. Only the sign is judged: without u, v (states to be estimated) the drift's
    changes are left in the course, which lowers the fit and the ratio (0.84, fit 0.86 on a
    KVLCC2 20/20 zigzag) but never turns its sign."""
    if km.windows >= MIN_WINDOWS // 2 and km.fit >= MIRROR_FIT and km.k > MIRROR_RATIO and kc.k < 0:
        return Finding("error", "x0", km.rows[0],
                       f"columns 'x0', 'y0': the track's course turns against psi (its change is {_g(kc.k)} "
                       f"times psi's, fit {kc.fit:.2f}; with x0 and y0 exchanged {_g(km.k)}, fit {km.fit:.2f}, "
                       f"over {km.windows} windows): x0 and y0 swapped, or psi counted anticlockwise? the "
                       f"schema's x0 points north, y0 east and psi turns clockwise from north; swap x0 and y0")
    return None


def mirrored_track(df: pd.DataFrame) -> Finding | None:
    """Check 7 alone, from positions and heading (``u, v`` taken as zero where absent): for a
    record whose ``u, v, r`` are still to be estimated from its track, which a mirrored track
    would corrupt."""
    cols = {c: 0.0 for c in ("u", "v", "r") if c not in df.columns}
    q = ratios(df.assign(**cols) if cols else df)
    return _mirrored(q["course"], q["course_mirrored"])


def _jumps(df: pd.DataFrame) -> list[Finding]:
    t = df["time"].to_numpy(float)
    psi = df["psi"].to_numpy(float)
    u, v = df["u"].to_numpy(float), df["v"].to_numpy(float)
    x, y = df["x0"].to_numpy(float), df["y0"].to_numpy(float)
    dt = np.diff(t)
    vx, vy = u * np.cos(psi) - v * np.sin(psi), u * np.sin(psi) + v * np.cos(psi)
    ix, iy = 0.5 * (vx[1:] + vx[:-1]) * dt, 0.5 * (vy[1:] + vy[:-1]) * dt
    ex, ey = np.diff(x) - ix, np.diff(y) - iy
    res = np.hypot(ex, ey)
    if res.size < 3:
        return []
    scatter = float(np.median(res))
    step = np.hypot(ix, iy)
    extent = float(np.hypot(np.ptp(x), np.ptp(y)))
    big = ((res > JUMP_SCATTER * scatter) & (res > JUMP_STEP * np.maximum(step, np.median(step)))
           & (res > JUMP_EXTENT * extent))
    out = []
    for i in np.flatnonzero(big):
        nxt = i + 1
        spike = nxt < res.size and (ex[i] * ex[nxt] + ey[i] * ey[nxt]) < -SPIKE_RETURN * res[i] ** 2
        if i > 0 and big[i - 1] and (ex[i - 1] * ex[i] + ey[i - 1] * ey[i]) < 0:
            continue  # the return of a spike already reported
        row = i + 1
        head = (f"columns 'x0', 'y0' jump by {_g(res[i])} m at row {row} (time {_g(t[row])}) where u, v cover "
                f"{_g(step[i])} m (median scatter per step {_g(scatter)} m, track extent {_g(extent)} m)")
        if spike:
            out.append(Finding("warning", "x0", row, f"{head} and back at the next row: a position glitch; remove "
                                                     f"row {row} or replace it by interpolation"))
        else:
            out.append(Finding("error", "x0", row, f"{head} and stay there: two records joined end to end? split "
                                                   f"the file at row {row}"))
        if len(out) >= 3:
            break
    return out
