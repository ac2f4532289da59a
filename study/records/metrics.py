"""Standard manoeuvring metrics and prediction-accuracy metrics.

Definitions follow IMO Resolution MSC.137(76) "Standards for ship manoeuvrability" (2002), its
explanatory notes MSC/Circ.1053 (2002), and ITTC Recommended Procedure 7.5-04-02-01 "Full Scale
Manoeuvring Trials" (2017). Signs and frames follow ``docs/conventions.md``: ``delta > 0`` turns the
ship to starboard (r > 0), ``psi`` is clockwise from north in radians and unwrapped, ``x0`` north,
``y0`` east.

Conventions chosen here (the standards leave them to the analyst):

- **Rudder execution** is the first sample at which ``|delta - delta[0]|`` exceeds 0.5 deg, moved
  back to the start of that rudder movement (the last sample before the rudder began to move
  monotonically), then to the sub-sample instant where the line through the first two moving samples
  leaves the initial angle (a rate-limited rudder moves linearly; on a coarse record this removes up
  to one sample of error). The heading and position at that instant (linearly interpolated) are the
  origin of every heading change and distance.
- **Rudder reversal** (zigzag "second, third, ... execute"): the start of the rudder movement
  towards the other side, found in the same way (departure by more than 0.5 deg from the plateau,
  moved back to the start of the monotone movement, refined between samples). A reversal counts only
  once the rudder has actually crossed to the other side by ``max(0.5 deg, a quarter of the largest
  rudder angle)``, so noise around midship is never a reversal.
- **Noisy rudder records**: the rudder noise sigma is estimated robustly from the first differences
  (zero on the plateaus of a clean record, so clean records are unaffected); if it is not zero the
  threshold becomes ``max(0.5 deg, 6 sigma)``, the initial angle the median of the samples before
  the rudder clearly moved, and the start of each movement is where a least-squares line through its
  ramp meets the plateau it leaves (sample-by-sample tests cannot see a start buried in noise).
  Heading and position noise is not filtered: the overshoots of a noisy record are biased upwards by
  the heading noise extremes.
- All angles returned by the zigzag metrics are in degrees (as tabulated by IMO and ITTC); times in
  seconds; lengths in metres (and in ship lengths under ``*_L`` when ``L`` is given).
- Quantities that a record is too short to determine are ``NaN``; a record that cannot carry the
  metric at all (no rudder execution, no reversal in a "zigzag", heading never reaching 90 deg in a
  "turning circle") raises :class:`ValueError` naming the problem.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

EXEC_THRESHOLD_DEG = 0.5  # rudder departure that counts as a movement (IMO/ITTC trials practice)
_NAN = float("nan")


# --------------------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------------------
def _columns(df: pd.DataFrame, cols, what: str) -> dict:
    if not isinstance(df, pd.DataFrame):
        raise ValueError(f"{what}: expected a pandas DataFrame, got {type(df).__name__}")
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise ValueError(f"{what}: the record lacks column(s) {missing}")
    if len(df) < 3:
        raise ValueError(f"{what}: the record has {len(df)} samples; at least 3 are needed")
    out = {c: df[c].to_numpy(dtype=float) for c in cols}
    if "time" in out:
        t = out["time"]
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise ValueError(f"{what}: 'time' must be finite and strictly increasing")
    return out


def _walk_back(y: np.ndarray, j: int, lo: int) -> int:
    """Move index j back to the start of the monotone *decrease* of y that contains it (not
    before lo)."""
    while j > lo and y[j - 1] > y[j]:
        j -= 1
    return j


def _refine(t: np.ndarray, y: np.ndarray, j: int) -> float:
    """Sub-sample start of a movement that leaves level y[j] at sample j (y decreasing after j).

    The line through the first two moving samples is extended back to the level y[j] (a rate-limited
    rudder moves linearly), clamped to [t[j], t[j+1]]: on a coarsely sampled record the reversal
    then falls where the rudder actually started, not up to one sample earlier.
    """
    if j + 2 >= len(t) or not y[j + 1] > y[j + 2] or not y[j] > y[j + 1]:
        return float(t[j])
    tq = t[j + 1] - (y[j] - y[j + 1]) * (t[j + 2] - t[j + 1]) / (y[j + 1] - y[j + 2])
    return float(min(max(tq, t[j]), t[j + 1]))


def _fit_ramp_start(t: np.ndarray, y: np.ndarray, lo: int, hi: int, top: float, bottom: float, h: float):
    """Noisy record: y falls from plateau ``top`` towards ``bottom`` within [lo, hi]; return the
    time at which the least-squares line through the ramp samples (clear of both plateaus by ``h``)
    is at ``top``, or None.

    Sample-by-sample tests cannot find the start of a movement buried in noise; the ramp of a
    rate-limited rudder is a straight line, and its fit locates the start to a fraction of a sample.
    """
    seg = y[lo:hi + 1]
    on_top = np.nonzero(seg >= top - h)[0]
    start = int(on_top[-1]) + 1 if on_top.size else 0
    on_bot = np.nonzero(seg[start:] <= bottom + h)[0]
    stop = start + int(on_bot[0]) if on_bot.size else len(seg)
    if stop - start < 3:
        return None
    tt = t[lo + start:lo + stop]
    slope, icpt = np.polyfit(tt - tt[0], seg[start:stop], 1)
    if not slope < 0:
        return None
    return float(min(max(tt[0] + (top - icpt) / slope, t[lo]), t[hi]))


def _index_at(t: np.ndarray, tq: float) -> int:
    return int(np.clip(np.searchsorted(t, tq, side="right") - 1, 0, len(t) - 1))


class _RudderEvents:
    """Execution and reversals of the rudder signal (see the module docstring for the
    definitions)."""

    def __init__(self, t: np.ndarray, delta: np.ndarray, threshold_deg: float = EXEC_THRESHOLD_DEG):
        # Measured rudder angles carry noise: raise the threshold to 6 noise sigmas (robust estimate from the
        # first differences, which are zero on the rudder's plateaus) so noise is never taken for a movement.
        # For a clean record the estimate is 0 and the threshold is the 0.5 deg of trials practice.
        dd = np.diff(delta)
        sig = 1.4826 * float(np.median(np.abs(dd - np.median(dd)))) / math.sqrt(2) if dd.size else 0.0
        thr = max(math.radians(threshold_deg), 6.0 * sig)
        d0 = float(delta[0])
        if sig > 0:  # neutral angle: median of the samples before the rudder clearly moved, not one noisy sample
            moved = np.nonzero(np.abs(delta - d0) > 2 * thr)[0]
            d0 = float(np.median(delta[:max(1, int(moved[0]) if moved.size else len(delta))]))
        d = delta - d0
        dev = np.abs(d) > thr
        if not dev.any():
            raise ValueError(f"no rudder execution found: |delta - delta[0]| never exceeds "
                             f"{math.degrees(thr):.2f} deg")
        j = int(np.argmax(dev))
        side = float(np.sign(d[j]))
        # start of the movement: walk back while the rudder was still moving (monotonically) away from neutral
        self.i_exec = _walk_back(-side * d, j, 0)
        self.t_exec = _refine(t, -side * d, self.i_exec)
        self.side = side
        self.d = d
        self.thr = thr
        self.noise_sigma = sig
        # plateau band below a segment's maximum: the noise extremes of a plateau stay inside it
        self.band = thr + 6.0 * sig
        self.amax = float(np.max(np.abs(d)))
        self.cross_thr = max(thr, 0.25 * self.amax)
        # reversals: segment k runs from seg_start[k] (the rudder is on side sides[k]) to the next reversal
        self.reversals: list[int] = []
        self.t_rev: list[float] = []
        self.seg_start: list[int] = [self.i_exec]
        self.sides: list[float] = [side]
        a, s = self.i_exec, side
        n = len(d)
        while True:
            other = np.nonzero(s * d[a:] < -self.cross_thr)[0]
            if other.size == 0:
                break
            b = a + int(other[0])  # first sample well on the other side
            seg = s * d[a:b]
            m = float(seg.max())
            last_plateau = a + int(np.nonzero(seg >= m - self.band)[0][-1])
            j = min(last_plateau + 1, n - 1)
            jr = _walk_back(s * d, j, a)
            tr = _refine(t, s * d, jr)
            if sig > 0:
                plateau = float(np.median(seg[seg >= m - self.band]))
                tf = _fit_ramp_start(t, s * d, a, b, plateau, -self.cross_thr, 4 * sig)
                if tf is not None:
                    tr, jr = tf, _index_at(t, tf)
            self.reversals.append(jr)
            self.t_rev.append(tr)
            s = -s
            a = b
            self.seg_start.append(b)
            self.sides.append(s)
        if sig > 0:  # execution of a noisy record: fit the first ramp too (y falls from 0 to -plateau)
            end = self.reversals[0] if self.reversals else n - 1
            y1 = side * d[self.i_exec:end + 1]
            m1 = float(y1.max())
            p1 = float(np.median(y1[y1 >= m1 - self.band]))
            reach = self.i_exec + int(np.argmax(y1 >= p1 - 4 * sig))
            tf = _fit_ramp_start(t, -side * d, 0, reach, 0.0, -p1, 4 * sig)
            if tf is not None:
                self.t_exec, self.i_exec = tf, _index_at(t, tf)
                self.seg_start[0] = self.i_exec

    def segment_shape_ok(self, k: int, end: int, tol: float) -> bool:
        """True if the rudder on segment k rises monotonically (within tol) to a plateau and
        stays on it."""
        y = self.sides[k] * self.d[self.seg_start[k]:end + 1]
        if y.size < 2:
            return True
        runmax = np.maximum.accumulate(y)
        if np.any(y < runmax - tol):  # a drop before the end: a second level, not a zigzag plateau
            return False
        return True


def _interp_crossing(t: np.ndarray, y: np.ndarray, level: float, start: int) -> float:
    """Time at which y first reaches ``level`` (from below) at or after index start; NaN if
    never."""
    idx = np.nonzero(y[start:] >= level)[0]
    if idx.size == 0:
        return _NAN
    i = start + int(idx[0])
    if i == start or y[i] == level:
        return float(t[i])
    f = (level - y[i - 1]) / (y[i] - y[i - 1])
    return float(t[i - 1] + f * (t[i] - t[i - 1]))


def _interp_at(t: np.ndarray, y: np.ndarray, tq: float) -> float:
    return float(np.interp(tq, t, y)) if np.isfinite(tq) else _NAN


# --------------------------------------------------------------------------------------------------------------
# zigzag
# --------------------------------------------------------------------------------------------------------------
def zigzag_metrics(df: pd.DataFrame, psi_switch: float | None = None, L: float | None = None) -> dict:
    """Zigzag (Kempf) manoeuvre characteristics.

    Definitions after IMO MSC.137(76) section 4.2 and MSC/Circ.1053 (annex, zig-zag test), and ITTC
    Recommended Procedure 7.5-04-02-01 (2017), section on the zig-zag manoeuvre:

    - *overshoot angle* k: the largest heading change beyond the switch heading after the k-th
      rudder reversal, on the side the ship was turning to, ``max(s_k (psi - psi_exec)) -
      psi_switch`` between reversal k and reversal k+1 (or the end of the record); positive degrees;
    - *initial turning time*: from the first execute to the instant the heading change first reaches
      ``psi_switch`` (linear interpolation between samples);
    - *time to check yaw*: from a rudder reversal to the following heading extremum (the overshoot);
    - *reach*: here the time from the first execute to the first heading extremum (= initial turning
      time + time to check yaw when the rudder is reversed exactly at the switch heading), and
      ``reach_distance``, the distance run along the initial course over that time;
    - *period*: time between successive rudder movements in the same direction; the first is from
      the first execute to the second reversal (a full cycle), the following ones from reversal k to
      reversal k+2.

    One function: these standard definitions are computed in turn from the same rudder events and
    heading change.

    Parameters
    ----------
    df : DataFrame
        Record with ``time`` [s], ``delta`` [rad], ``psi`` [rad, unwrapped]; ``x0``, ``y0`` [m] for
        the reach
        distance.
    psi_switch : float, optional
        Switch heading change in **radians** (magnitude, e.g. ``math.radians(10)`` for a 20/10
        zigzag). When omitted it is inferred as the heading change at the first rudder reversal
        (exact for a simulated controller; for manual steering it includes the helmsman's delay).
    L : float, optional
        Ship length [m]; adds ``reach_distance_L``.

    Returns
    -------
    dict
        Scalars: ``side`` (+1 starboard first, -1 port first), ``execution_time`` [s],
        ``psi_switch_deg``, ``psi_switch_inferred`` (1.0/0.0), ``delta_amplitude_deg``,
        ``n_reversals``, ``overshoot_1``, ``overshoot_2``, ``overshoot_3`` [deg],
        ``initial_turning_time``, ``time_to_check_yaw``, ``reach``, ``period`` (mean of ``periods``)
        [s], ``reach_distance`` [m]. Lists: ``switch_times`` [s, record time], ``overshoots`` [deg],
        ``overshoot_times`` [s, record time], ``check_yaw_times`` [s], ``periods`` [s]. NaN where
        the record is too short.

    Raises
    ------
    ValueError
        Missing columns, no rudder execution, no rudder reversal, or a reversal with the heading on
        the wrong side of the initial course.
    """
    c = _columns(df, ("time", "delta", "psi"), "zigzag_metrics")
    t, psi = c["time"], c["psi"]
    ev = _RudderEvents(t, c["delta"])
    if not ev.reversals:
        raise ValueError("zigzag_metrics: no rudder reversal found (the rudder never crosses to the other side); "
                         "not a zigzag, or the record ends before the first switch")
    ie, s1 = ev.i_exec, ev.side
    t_exec = ev.t_exec
    psi_e = float(np.interp(t_exec, t, psi))
    dpsi = psi - psi_e
    J, TR = ev.reversals, ev.t_rev
    if psi_switch is None:
        sw = float(s1 * (np.interp(TR[0], t, psi) - psi_e))
        inferred = 1.0
        if sw <= 0:
            raise ValueError("zigzag_metrics: the heading at the first rudder reversal is not on the side of the "
                             "first rudder; cannot infer psi_switch (pass it explicitly)")
    else:
        sw = abs(float(psi_switch))
        inferred = 0.0

    overshoots, os_times, check = [], [], []
    for k, jk in enumerate(J):
        sk = ev.sides[k]  # the side the ship was turning to before reversal k
        end = J[k + 1] if k + 1 < len(J) else len(t) - 1
        e = sk * dpsi[jk:end + 1]
        p = int(np.argmax(e))
        if k + 1 >= len(J) and p == len(e) - 1:
            break  # the heading is still moving at the end of the record: no extremum yet
        overshoots.append(math.degrees(float(e[p]) - sw))
        os_times.append(float(t[jk + p]))
        check.append(float(t[jk + p] - TR[k]))

    events = [t_exec] + list(TR)
    periods = [events[k + 2] - events[k] for k in range(len(events) - 2)]
    t_a = _interp_crossing(t, s1 * dpsi, sw, ie) - t_exec

    reach = os_times[0] - t_exec if os_times else _NAN
    reach_dist = _NAN
    if os_times and "x0" in df.columns and "y0" in df.columns:
        x, y = df["x0"].to_numpy(float), df["y0"].to_numpy(float)
        i1 = int(np.searchsorted(t, os_times[0]))
        xe, ye = np.interp(t_exec, t, x), np.interp(t_exec, t, y)
        reach_dist = float((x[i1] - xe) * math.cos(psi_e) + (y[i1] - ye) * math.sin(psi_e))

    amp_first = float(np.max(s1 * ev.d[ie:J[0] + 1]))
    out = {
        "side": s1,
        "execution_time": t_exec,
        "psi_switch_deg": math.degrees(sw),
        "psi_switch_inferred": inferred,
        "delta_amplitude_deg": math.degrees(amp_first),
        "n_reversals": float(len(J)),
        "overshoot_1": overshoots[0] if len(overshoots) > 0 else _NAN,
        "overshoot_2": overshoots[1] if len(overshoots) > 1 else _NAN,
        "overshoot_3": overshoots[2] if len(overshoots) > 2 else _NAN,
        "initial_turning_time": float(t_a),
        "time_to_check_yaw": check[0] if check else _NAN,
        "reach": float(reach),
        "reach_distance": reach_dist,
        "period": float(np.mean(periods)) if periods else _NAN,
        "switch_times": list(TR),
        "overshoots": overshoots,
        "overshoot_times": os_times,
        "check_yaw_times": check,
        "periods": periods,
    }
    if L is not None:
        out["reach_distance_L"] = reach_dist / float(L)
    return out


# --------------------------------------------------------------------------------------------------------------
# turning circle
# --------------------------------------------------------------------------------------------------------------
def _fit_circle(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Algebraic least-squares circle (Kasa 1976): returns (xc, yc, R). Exact for points on a
    circle."""
    xm, ym = x.mean(), y.mean()
    X, Y = x - xm, y - ym  # centred for conditioning (positions can be kilometres from the origin)
    A = np.column_stack([X, Y, np.ones_like(X)])
    b = -(X ** 2 + Y ** 2)
    (a1, a2, a3), *_ = np.linalg.lstsq(A, b, rcond=None)
    xc, yc = -a1 / 2, -a2 / 2
    R2 = xc ** 2 + yc ** 2 - a3
    return float(xc + xm), float(yc + ym), float(math.sqrt(R2)) if R2 > 0 else _NAN


def turning_metrics(df: pd.DataFrame, L: float | None = None, steady_tol: float = 0.02) -> dict:
    """Turning-circle characteristics.

    Definitions after IMO MSC.137(76) sections 2.3.2-2.3.4 and 4.1 (advance, tactical diameter),
    MSC/Circ.1053 (transfer, steady turning diameter, speed loss) and ITTC Recommended Procedure
    7.5-04-02-01 (turning circle test). Origin: position and heading at rudder execution (see the
    module docstring); distances are those of the record's reference point (midship for MMG
    records).

    - *advance*: distance along the initial course from the execution to the point where the heading
      has changed by 90 deg; *transfer*: the distance perpendicular to the initial course (towards
      the turn) at that point; *tactical diameter*: the perpendicular distance at 180 deg heading
      change. Crossing instants are linearly interpolated between samples.
    - *steady turn*: the last contiguous stretch before the pull-out (the rudder leaving its turning
      angle) or the end of the record on which the smoothed yaw rate stays within ``steady_tol``
      (relative) of its mean over the last 30 % of the turn. *Steady turning rate* = mean |r| there;
      *speed loss ratio* = mean U there over the mean U before execution; *drift angle* ``beta =
      atan2(-v, u)`` (MMG sign, positive when the bow points into the turn) times the side, mean
      over the steady part.
    - *steady turning diameter*: a least-squares circle through the steady positions when the steady
      stretch covers at least 90 deg of heading (well-conditioned fit), else ``2 U / |r|``; ``2 U /
      |r|`` is always given as ``steady_turning_diameter_Ur``.

    One function: these standard definitions are computed in turn from the same execution instant,
    turn side and track in the initial course's axes.

    Parameters
    ----------
    df : DataFrame
        Record with ``time, u, v, r, x0, y0, psi, delta``.
    L : float, optional
        Ship length [m]; adds ``advance_L``, ``transfer_L``, ``tactical_diameter_L``,
        ``steady_turning_diameter_L``.
    steady_tol : float
        Relative band on the yaw rate that defines the steady turn.

    Returns
    -------
    dict of floats
        ``side`` (+1 starboard, -1 port), ``execution_time``, ``approach_speed`` [m/s], ``advance``,
        ``transfer``, ``tactical_diameter`` [m], ``time_90``, ``time_180`` [s from execution],
        ``steady_turning_diameter``, ``steady_turning_diameter_Ur`` [m], ``steady_turning_rate``
        [rad/s], ``steady_turning_rate_deg`` [deg/s], ``steady_speed`` [m/s], ``speed_loss_ratio``,
        ``drift_angle`` [rad], ``drift_angle_deg``, ``steady_start_time``, ``steady_end_time`` [s].
        Turn-dependent quantities are positive for both port and starboard turns. NaN where the
        record is too short (e.g. heading never reaches 180 deg, or no steady stretch).

    Raises
    ------
    ValueError
        Missing columns, no rudder execution, or a heading change of less than 90 deg.
    """
    c = _columns(df, ("time", "u", "v", "r", "x0", "y0", "psi", "delta"), "turning_metrics")
    t, u, v, r, x, y, psi = (c[k] for k in ("time", "u", "v", "r", "x0", "y0", "psi"))
    ev = _RudderEvents(t, c["delta"])
    ie, te = ev.i_exec, ev.t_exec
    psi_e, x_e, y_e = (float(np.interp(te, t, a)) for a in (psi, x, y))
    dpsi = psi[ie:] - psi_e
    # turn side from the heading (what the geometry follows), not the rudder sign
    s = float(np.sign(dpsi[int(np.argmax(np.abs(dpsi)))])) or 1.0
    h = s * dpsi
    if h.max() < math.pi / 2:
        raise ValueError(f"turning_metrics: the heading changes only {math.degrees(h.max()):.1f} deg after the "
                         "rudder execution; advance and transfer need 90 deg")
    tt = t[ie:]
    c0, s0 = math.cos(psi_e), math.sin(psi_e)
    X = (x[ie:] - x_e) * c0 + (y[ie:] - y_e) * s0  # along the initial course
    Y = s * (-(x[ie:] - x_e) * s0 + (y[ie:] - y_e) * c0)  # across it, positive towards the turn

    def at(level):
        tq = _interp_crossing(tt, h, level, 0)
        return tq, _interp_at(tt, X, tq), _interp_at(tt, Y, tq)

    t90, adv, trans = at(math.pi / 2)
    t180, _, tact = at(math.pi)
    U = np.hypot(u, v)
    U_app = float(np.mean(U[:ie + 1]))

    # end of the turn: the rudder leaving its turning angle (pull-out), found like a reversal
    sd = ev.side
    seg = sd * ev.d[ie:]
    i_plat = int(np.argmax(seg))  # on the plateau, past the rudder's approach to it
    left = np.nonzero(seg[i_plat:] < seg[i_plat] - ev.band)[0]
    i_end = len(seg) if left.size == 0 else _walk_back(seg, i_plat + int(left[0]), i_plat)  # exclusive
    steady = dict(steady_turning_diameter=_NAN, steady_turning_diameter_Ur=_NAN, steady_turning_rate=_NAN,
                  steady_turning_rate_deg=_NAN, steady_speed=_NAN, speed_loss_ratio=_NAN, drift_angle=_NAN,
                  drift_angle_deg=_NAN, steady_start_time=_NAN, steady_end_time=_NAN)
    rr = s * r[ie:ie + i_end]
    if rr.size >= 10:
        from scipy.ndimage import uniform_filter1d

        w = max(1, int(round(0.02 * rr.size)))  # light smoothing so that measurement noise is not "unsteady"
        rs = uniform_filter1d(rr, w, mode="nearest")
        r_ref = float(np.mean(rs[int(0.7 * rs.size):]))
        ok = np.abs(rs - r_ref) <= steady_tol * abs(r_ref)
        if r_ref > 0 and ok[-1]:
            bad = np.nonzero(~ok)[0]
            i0 = 0 if bad.size == 0 else int(bad[-1]) + 1
            sl = slice(ie + i0, ie + i_end)
            if sl.stop - sl.start >= 3:
                r_ss = float(np.mean(s * r[sl]))
                U_ss = float(np.mean(U[sl]))
                beta = float(np.mean(s * np.arctan2(-v[sl], u[sl])))
                D_Ur = 2 * U_ss / r_ss
                arc = abs(psi[sl.stop - 1] - psi[sl.start])
                D = 2 * _fit_circle(x[sl], y[sl])[2] if arc >= math.pi / 2 else D_Ur
                steady.update(steady_turning_diameter=D, steady_turning_diameter_Ur=D_Ur, steady_turning_rate=r_ss,
                              steady_turning_rate_deg=math.degrees(r_ss), steady_speed=U_ss,
                              speed_loss_ratio=U_ss / U_app if U_app > 0 else _NAN, drift_angle=beta,
                              drift_angle_deg=math.degrees(beta), steady_start_time=float(t[sl.start]),
                              steady_end_time=float(t[sl.stop - 1]))
    out = {
        "side": s,
        "execution_time": te,
        "approach_speed": U_app,
        "advance": adv,
        "transfer": trans,
        "tactical_diameter": tact,
        "time_90": t90 - te,
        "time_180": t180 - te,
        **steady,
    }
    if L is not None:
        L = float(L)
        for k in ("advance", "transfer", "tactical_diameter", "steady_turning_diameter"):
            out[f"{k}_L"] = out[k] / L
    return out


# --------------------------------------------------------------------------------------------------------------
# prediction accuracy
# --------------------------------------------------------------------------------------------------------------
def prediction_metrics(measured_df: pd.DataFrame, predicted_df: pd.DataFrame,
                       channels=("u", "v", "r", "psi")) -> dict:
    """Accuracy of a predicted trajectory against a measured one.

    The predicted record is linearly interpolated onto the measured time stamps that lie within its
    time span (so records with dropouts or a different step compare sample by sample). Per channel
    ``c``: ``rmse_c``, ``nrmse_c`` (RMSE over the standard deviation of the measured channel; NaN if
    that is 0), ``max_abs_error_c`` and ``cc_c`` (Pearson correlation coefficient; NaN if either
    signal is constant) -- the RMSE and CC of seed paper 000 (Song et al. 2025, Table 4). Track:
    ``track_rmse`` (RMS of the horizontal position error) and ``final_position_error`` (at the last
    common time), in metres, when both records have ``x0`` and ``y0``. Units are those of the
    channels (SI, radians for ``psi``).

    Raises
    ------
    ValueError
        Missing columns, or fewer than 2 common time stamps.
    """
    chans = tuple(channels)
    need = ("time",) + chans
    for name, d in (("measured", measured_df), ("predicted", predicted_df)):
        missing = [k for k in need if k not in d.columns]
        if missing:
            raise ValueError(f"prediction_metrics: the {name} record lacks column(s) {missing}")
    tm = measured_df["time"].to_numpy(float)
    tp = predicted_df["time"].to_numpy(float)
    if np.any(np.diff(tp) <= 0):
        raise ValueError("prediction_metrics: the predicted record's time must be strictly increasing")
    eps = 1e-9 * max(1.0, float(np.max(np.abs(tp))))
    sel = (tm >= tp[0] - eps) & (tm <= tp[-1] + eps)
    if sel.sum() < 2:
        raise ValueError("prediction_metrics: the measured and predicted records share fewer than 2 time stamps")
    tq = tm[sel]

    def pair(k):
        return measured_df[k].to_numpy(float)[sel], np.interp(tq, tp, predicted_df[k].to_numpy(float))

    out = {}
    for k in chans:
        a, b = pair(k)
        e = b - a
        rmse = float(np.sqrt(np.mean(e ** 2)))
        sa, sb = float(np.std(a)), float(np.std(b))
        out[f"rmse_{k}"] = rmse
        out[f"nrmse_{k}"] = rmse / sa if sa > 0 else _NAN
        out[f"max_abs_error_{k}"] = float(np.max(np.abs(e)))
        out[f"cc_{k}"] = float(np.corrcoef(a, b)[0, 1]) if sa > 0 and sb > 0 else _NAN
    if all(k in d.columns for k in ("x0", "y0") for d in (measured_df, predicted_df)):
        xa, xb = pair("x0")
        ya, yb = pair("y0")
        dist = np.hypot(xb - xa, yb - ya)
        out["track_rmse"] = float(np.sqrt(np.mean(dist ** 2)))
        out["final_position_error"] = float(dist[-1])
    return out


# --------------------------------------------------------------------------------------------------------------
# dispatch
# --------------------------------------------------------------------------------------------------------------
def detect_maneuver(df: pd.DataFrame) -> str:
    """Guess the manoeuvre of a record from its rudder signal: ``'zigzag'``, ``'turning'`` or
    ``'other'``.

    - zigzag: at least one rudder reversal; at every reversal the heading change is on the side of
      the rudder being reversed and of a size within a factor 3 of the first one (the switch
      heading); on every leg the rudder goes to one plateau and stays there (IMO MSC.137(76) 4.2).
    - turning: no reversal; the rudder goes to one angle and holds it, optionally back towards
      midship once (pull-out) and stays there (IMO MSC.137(76) 4.1).
    - other: anything else (random rudder, no rudder execution, ...).
    """
    c = _columns(df, ("time", "delta", "psi"), "detect_maneuver")
    try:
        ev = _RudderEvents(c["time"], c["delta"])
    except ValueError:
        return "other"
    tol = max(ev.thr, 0.1 * ev.amax) + 6 * ev.noise_sigma  # + noise: extremes of a noisy plateau differ
    n = len(ev.d)
    if ev.reversals:
        dpsi = c["psi"] - np.interp(ev.t_exec, c["time"], c["psi"])
        head = [ev.sides[k] * np.interp(tr, c["time"], dpsi) for k, tr in enumerate(ev.t_rev)]
        if head[0] <= math.radians(0.5) or any(h < head[0] / 3 or h > 3 * head[0] for h in head):
            return "other"
        ends = ev.reversals + [n - 1]
        if all(ev.segment_shape_ok(k, ends[k], tol) for k in range(len(ends))):
            return "zigzag"
        return "other"
    y = ev.side * ev.d[ev.i_exec:]
    i_plat = int(np.argmax(y))
    left = np.nonzero(y[i_plat:] < y[i_plat] - tol)[0]
    if left.size == 0:
        return "turning"
    rest = y[i_plat + int(left[0]):]
    runmin = np.minimum.accumulate(rest)
    if np.all(rest <= runmin + tol) and np.all(rest >= -tol) and abs(rest[-1]) <= tol:
        return "turning"  # a single pull-out back to (about) the initial rudder angle
    return "other"


def standard_metrics(df: pd.DataFrame, L: float | None = None) -> dict:
    """The standard metrics that apply to a record, chosen by :func:`detect_maneuver`.

    Returns ``{'maneuver': kind, **metrics}``: :func:`zigzag_metrics` (switch heading inferred) for
    a zigzag, :func:`turning_metrics` for a turning circle, nothing else for ``'other'``. Raises
    ValueError (from the metric) when the record looks like a zigzag or turning circle but cannot
    carry the metric.
    """
    kind = detect_maneuver(df)
    if kind == "zigzag":
        return {"maneuver": kind, **zigzag_metrics(df, L=L)}
    if kind == "turning":
        return {"maneuver": kind, **turning_metrics(df, L=L)}
    return {"maneuver": kind}
