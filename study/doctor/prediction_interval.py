"""How far a predicted manoeuvre metric can be trusted: the arithmetic of its interval and of the
state envelope.

A predicted metric (a tactical diameter, an overshoot) is uncertain for three reasons, each measured
separately (``study.doctor.model_error`` computes them from a fit and its records) and combined
here:

(a) **identification spread**: the metric over draws from the fit's posterior
(``EffectsProblem.posterior``); (b) **structural spread**: the metric over other models that the
doctor cannot tell from the chosen one (their
    training and validation errors within ``tie`` of its own, or lower);
(c) **extrapolation error**: the relative error of predictions of the training records' harsher
manoeuvres by a
    model identified on their gentler ones, as it grows with the distance outside the training
    envelope.

Each component is a standard deviation of the metric's logarithm (a relative error: a tactical
diameter 10 % too wide is log 1.1 off). How they combine (:func:`combine`) follows from what each
measures. Write a prediction's log error as eps = eps_id + eps_form: the identification error (the
coefficients the records leave uncertain) and the error of the model's form (terms it lacks, and how
they show beyond the records). *Assumptions, labelled*: the two are independent and normal on the
log scale, so var(eps) = s_id^2 + s_form^2, and the interval at ``level`` is ``value * exp(+-z s)``
with s^2 that variance and z the normal quantile (1.645 at 90 %). Then:

- (a) estimates s_id directly.
- (c) measures a held-out prediction's whole error, e = eps_id,ho + eps_form,ho (+ the noise of the
  measured metric), so E[e^2] = s_id,ho^2 + s_form^2(d) + s_noise^2: it holds an identification
  spread of its own, which the prediction's (a) already counts. That spread is measured on the
  held-out fit itself -- its posterior draws replayed through the record it predicts
  (``model_error.own_spread``) -- and taken out of each pair's squared error before the growth is
  fitted (:func:`fit_growth`), so s_extrap estimates s_form at the distance d (the measured metric's
  noise stays in: the measured value a prediction is compared with carries it too). Measured rather
  than approximated by the main fit's s_id: the held-out fits have fewer records (their spread is
  the larger), and the held-out metric is often another one (the RMS yaw rate standing in for a
  turn's diameter).
- (b) and (c) are two estimates of the same s_form, not two errors: (b) from how far the models the
  records cannot tell apart disagree at the prediction itself (it sees where the prediction goes,
  e.g. beyond the farthest held-out record), (c) from how far the model's form actually missed on
  held-out records (it sees a term all the alternatives lack). Adding them would count the form's
  error twice; the larger is taken (assumption: neither overstates it), s_form = max(s_struct,
  s_extrap).

So s^2 = s_id^2 + max(s_struct, s_extrap)^2. Not corrected for: (b)'s alternatives are themselves
identified, so s_struct holds a little of their identification spread (the wide side); and the
held-out pairs are the training records' own manoeuvres, so an error the training records share with
the prediction is seen by neither.

The **envelope** of a set of records (:func:`state_envelope`) is, per state, the 99th percentile of
|v'|, |r'|, the drift angle |beta| and the rudder angle |delta| (v' = v/U, r' = r L/U, beta =
atan2(-v, u), U the speed through the water), each sample weighted by (U/U0)^4 -- the information it
carries about a hull coefficient: the hull force scales with the dynamic pressure, U^2, and the
information with the force's square -- over samples faster than a tenth of U0 (slower ones make v'
and r' meaningless), while the propeller runs (at half its median running speed or more: a record's
end, where the propeller stops and the ship drifts to rest, is no part of its manoeuvre). A record
at low speed thus hardly widens the envelope of a model identified at speed. The 99th percentile
rather than the maximum: one noisy sample does not stretch the envelope (assumption). The
**distance** of a prediction outside an envelope (:func:`envelope_distance`) is the largest relative
excess over the states, max_s max(0, x_s / X_s - 1): 0 inside, 0.5 when one state goes 50 % beyond
the records.
"""
from __future__ import annotations

import math
import re

import numpy as np
from scipy import optimize, stats

#: the states of the envelope, in the order of every envelope dict
STATES = ("v'", "r'", "drift_deg", "rudder_deg")
#: samples slower than this share of U0 are not counted (v', r' undefined at rest)
MIN_SPEED_U0 = 0.1
#: the envelope's quantile per state (weighted by (U/U0)^4)
ENVELOPE_QUANTILE = 0.99
#: a sample counts in an envelope while the propeller runs at this share of its median running speed or more
PROPELLER_RUNNING = 0.5
#: posterior draws needed for an identification spread (a share of those drawn)
MIN_FINITE_DRAWS = 0.5


def z_of(level: float) -> float:
    """The normal quantile of a central interval at ``level`` (1.645 at 0.9)."""
    if not 0.0 < float(level) < 1.0:
        raise ValueError(f"level={level!r}: expected a number between 0 and 1 (0.9 for a 90 % interval)")
    return float(stats.norm.ppf(0.5 + float(level) / 2.0))


def _positive(x) -> np.ndarray:
    a = np.asarray(x, float).ravel()
    return a[np.isfinite(a) & (a > 0)]


def draws_log_sd(draws, level: float = 0.9) -> tuple[float, int]:
    """(sd of log metric over the posterior draws, number of usable draws): the central ``level``
    range of the draws' logarithms over 2 z (a robust sd: one wild draw does not set it). NaN
    when fewer than half the draws gave a positive finite metric (the rest diverged or never
    reached it: the spread is then not measurable)."""
    d = np.asarray(draws, float).ravel()
    ok = _positive(d)
    if len(d) == 0 or len(ok) < max(2, MIN_FINITE_DRAWS * len(d)):
        return math.nan, int(len(ok))
    a = (1.0 - level) / 2.0
    lo, hi = np.quantile(np.log(ok), [a, 1.0 - a])
    return float((hi - lo) / (2.0 * z_of(level))), int(len(ok))


def structural_log_sd(value: float, alternatives) -> tuple[float, int]:
    """(root-mean-square of log(alternative / value) over the alternatives that give a positive
    metric, their number): the spread of the models the records cannot tell apart, about the
    chosen one. 0 with none."""
    alt = _positive(alternatives)
    if not (math.isfinite(value) and value > 0) or len(alt) == 0:
        return 0.0, int(len(alt))
    return float(np.sqrt(np.mean(np.log(alt / value) ** 2))), int(len(alt))


def fit_growth(distance, error, own_sd=None) -> dict:
    """The extrapolation error's growth with the distance outside the training envelope, from
    held-out pairs: ``error`` the |log(predicted / measured)| of a metric on a record,
    ``distance`` that record's distance outside the envelope of the records the model was trained
    on, ``own_sd`` (optional; 0 or NaN where unknown) the held-out prediction's own
    identification spread, taken out of its squared error (see the module docstring): the target
    is e^2 - own_sd^2. Model (assumption): the expected target is sigma0^2 + (k d)^2 -- a floor
    inside the envelope, growing linearly with the distance beyond it; sigma0^2 and k^2 by
    non-negative least squares on the targets (a pair whose own spread exceeds its error pulls
    them down: its error was mostly the identification's). Returns ``{'sigma0', 'k', 'n',
    'd_max', 'note'}``; with no pair, NaNs; with no pair outside the envelope, k is 0 and the
    note says the growth is not measured."""
    d = np.asarray(distance, float).ravel()
    e = np.asarray(error, float).ravel()
    s = np.zeros_like(e) if own_sd is None else np.asarray(own_sd, float).ravel()
    if d.shape != e.shape or s.shape != e.shape:
        raise ValueError(f"distance, error and own_sd differ in length ({d.size}, {e.size} and {s.size})")
    ok = np.isfinite(d) & np.isfinite(e) & (d >= 0)
    d, e, s = d[ok], np.abs(e[ok]), np.where(np.isfinite(s[ok]), s[ok], 0.0)
    if len(d) == 0:
        return {"sigma0": math.nan, "k": math.nan, "n": 0, "d_max": math.nan,
                "note": "no held-out record to calibrate the extrapolation error on"}
    A = np.column_stack([np.ones_like(d), d ** 2])
    (a, b), _ = optimize.nnls(A, e ** 2 - s ** 2)
    note = ""
    if not np.any(d > 0):
        note = "no held-out record lay outside its training envelope: the growth with distance is not measured"
        b = 0.0
    elif len(d) < 3:
        note = f"calibrated on {len(d)} held-out record(s) only"
    return {"sigma0": float(math.sqrt(a)), "k": float(math.sqrt(b)), "n": int(len(d)), "d_max": float(d.max()),
            "note": note}


def extrapolation_log_sd(distance: float, growth: dict) -> float:
    """sqrt(sigma0^2 + (k d)^2): the extrapolation error at ``distance`` outside the training
    envelope (see :func:`fit_growth`); NaN when the growth is not calibrated."""
    s0, k = float(growth.get("sigma0", math.nan)), float(growth.get("k", math.nan))
    d = max(0.0, float(distance)) if math.isfinite(float(distance)) else math.nan
    return float(math.hypot(s0, k * d))


def combine(value: float, s_id: float, s_struct: float, s_extrap: float, level: float = 0.9) -> dict:
    """The interval of ``value`` from the three log-scale sds: s^2 = s_id^2 + max(s_struct,
    s_extrap)^2 (the identification spread and the error of the model's form, in quadrature; the
    structural spread and the held-out extrapolation error are two estimates of the latter: see
    the module docstring). Returns ``{'low', 'high', 'log_sd', 'half_width'}`` (half_width:
    relative, exp(z s) - 1). A component that is NaN makes the interval NaN (an interval that
    leaves out what could not be measured would look narrower than it is); a value that is not
    positive has none (the log scale)."""
    parts = [float(s_id), float(s_struct), float(s_extrap)]
    if not (math.isfinite(value) and value > 0) or not all(math.isfinite(p) and p >= 0 for p in parts):
        return {"low": math.nan, "high": math.nan, "log_sd": math.nan, "half_width": math.nan}
    s = math.hypot(parts[0], max(parts[1], parts[2]))
    w = z_of(level) * s
    return {"low": float(value * math.exp(-w)), "high": float(value * math.exp(w)), "log_sd": float(s),
            "half_width": float(math.exp(w) - 1.0)}


def agrees(value: float, low: float, high: float, measured: float, s_meas: float = 0.0,
           level: float = 0.9) -> bool | None:
    """Whether a measured value agrees with a prediction whose ``level`` interval is ``low`` ..
    ``high`` once the measurement's own noise (``s_meas``, log scale) is added: |log(measured /
    value)| <= z sqrt(s^2 + s_meas^2), s = log(high / low) / (2 z) the interval's log sd. None
    when either has no positive finite value."""
    vals = (value, low, high, measured)
    if not all(isinstance(x, (int, float)) and math.isfinite(x) and x > 0 for x in vals):
        return None
    z = z_of(level)
    s = math.log(high / low) / (2.0 * z)
    sm = float(s_meas) if isinstance(s_meas, (int, float)) and math.isfinite(s_meas) else 0.0
    return bool(abs(math.log(measured / value)) <= z * math.hypot(s, sm))


def tie_mixture(readings, level: float = 0.9) -> dict:
    """The interval of a metric when the records cannot tell two or more readings of them apart
    (the doctor's verdict is a tie): ``readings`` holds each reading's ``(value, low, high)``,
    its own ``level`` interval from :func:`combine` (value * exp(+-z s): a normal of sd s on the
    log scale). The readings are weighted equally -- a tie says the records favour none
    (assumption) -- and the result is the central ``level`` share of that mixture, its median as
    the value. Choosing one reading would give an interval that holds only its own world; the
    mixture holds each in proportion. Returns ``{'value', 'low', 'high', 'half_width', 'n'}``
    (half_width: (high - low) / (2 value)); NaNs when a reading has no interval."""
    if len(readings) == 0:
        raise ValueError("tie_mixture: no reading given")
    z = z_of(level)
    mus, sds = [], []
    for value, low, high in readings:
        vals = (float(value), float(low), float(high))
        if not all(math.isfinite(x) and x > 0 for x in vals) or not vals[1] <= vals[0] <= vals[2]:
            return {"value": math.nan, "low": math.nan, "high": math.nan, "half_width": math.nan,
                    "n": len(readings)}
        mus.append(math.log(vals[0]))
        sds.append(max((math.log(vals[2]) - math.log(vals[1])) / (2.0 * z), 1e-12))
    mus, sds = np.array(mus), np.array(sds)

    def quantile(p: float) -> float:
        lo, hi = float(np.min(mus - 10 * sds)), float(np.max(mus + 10 * sds))
        return optimize.brentq(lambda x: float(np.mean(stats.norm.cdf((x - mus) / sds))) - p, lo, hi)

    a = (1.0 - level) / 2.0
    med, low, high = (math.exp(quantile(p)) for p in (0.5, a, 1.0 - a))
    return {"value": med, "low": low, "high": high, "half_width": (high - low) / (2.0 * med), "n": int(len(mus))}


# ---------------------------------------------------------------------------------------------- envelope
def running(frame, measured=None, share: float = PROPELLER_RUNNING):
    """``frame`` restricted to the samples where the propeller runs at ``share`` of its median
    running speed or more -- the record's ``n`` (or ``measured``'s, interpolated at the frame's
    times, for a replay); unchanged without one. The end of a record where the propeller stops
    and the ship drifts to rest is no part of the manoeuvre its metrics describe, and there v'
    and r' (over a vanishing speed) run away."""
    src = measured if measured is not None else frame
    if frame is None or src is None or "n" not in getattr(src, "columns", ()):
        return frame
    n = np.abs(np.asarray(src["n"], float))
    if measured is not None:
        n = np.interp(np.asarray(frame["time"], float), np.asarray(src["time"], float), n)
    on = n[np.isfinite(n) & (n > 0)]
    if not len(on):
        return frame
    keep = np.isfinite(n) & (n >= share * float(np.median(on)))
    return frame[keep]


def nondimensional_states(df, L: float, U0: float, min_speed: float = MIN_SPEED_U0) -> tuple[dict, np.ndarray]:
    """({state: |value| per kept sample}, weights (U/U0)^4) of a frame with ``u, v, r`` (and
    ``delta`` when present) over its samples faster than ``min_speed`` U0."""
    u, v, r = (np.asarray(df[c], float) for c in ("u", "v", "r"))
    U = np.hypot(u, v)
    ok = np.isfinite(U) & np.isfinite(r) & (U > min_speed * U0)
    u, v, r, U = u[ok], v[ok], r[ok], U[ok]
    out = {"v'": np.abs(v / U), "r'": np.abs(r * L / U), "drift_deg": np.abs(np.degrees(np.arctan2(-v, u)))}
    if "delta" in getattr(df, "columns", ()):
        out["rudder_deg"] = np.abs(np.degrees(np.asarray(df["delta"], float)[ok]))
    return out, (U / U0) ** 4


def weighted_quantile(x, w, q: float) -> float:
    """The ``q`` quantile of ``x`` with weights ``w`` (the smallest x whose cumulative weight
    reaches q); NaN for no finite sample."""
    x, w = np.asarray(x, float), np.asarray(w, float)
    ok = np.isfinite(x) & np.isfinite(w) & (w > 0)
    if not ok.any():
        return math.nan
    o = np.argsort(x[ok])
    xs, cw = x[ok][o], np.cumsum(w[ok][o])
    return float(xs[min(np.searchsorted(cw, q * cw[-1]), len(xs) - 1)])


def state_envelope(frames, L: float, U0: float, q: float = ENVELOPE_QUANTILE,
                   min_speed: float = MIN_SPEED_U0) -> dict:
    """The envelope of records (one frame or several, pooled): per state of :data:`STATES` the
    weighted ``q`` quantile of its magnitude over the samples faster than ``min_speed`` U0 (see
    the module docstring); NaN for a state no frame has."""
    frames = [frames] if hasattr(frames, "columns") else [f for f in frames if f is not None]
    if not (L > 0 and U0 > 0):
        raise ValueError(f"state_envelope: L={L!r} and U0={U0!r} must be positive")
    xs = {s: [] for s in STATES}
    ws = {s: [] for s in STATES}
    for f in frames:
        vals, w = nondimensional_states(running(f), L, U0, min_speed)
        for s, a in vals.items():
            xs[s].append(a)
            ws[s].append(w)
    return {s: (weighted_quantile(np.concatenate(xs[s]), np.concatenate(ws[s]), q) if xs[s] else math.nan)
            for s in STATES}


def envelope_distance(prediction: dict, training: dict) -> dict:
    """How far ``prediction``'s envelope lies outside ``training``'s: per state the relative
    excess max(0, x / X - 1) (NaN when either is unknown or the training one is 0), and
    ``distance`` their largest (NaN when no state could be compared), ``state`` the state that
    sets it."""
    ex = {}
    for s in STATES:
        x, X = float(prediction.get(s, math.nan)), float(training.get(s, math.nan))
        ex[s] = max(0.0, x / X - 1.0) if (math.isfinite(x) and math.isfinite(X) and X > 0) else math.nan
    known = {s: e for s, e in ex.items() if math.isfinite(e)}
    if not known:
        return {"excess": ex, "distance": math.nan, "state": None}
    s = max(known, key=known.get)
    return {"excess": ex, "distance": float(known[s]), "state": s if known[s] > 0 else None}


# ---------------------------------------------------------------------------------------------- coefficients
_MONOMIAL = re.compile(r"^[XYN]([uvrda]+)$")


def monomial_of(name: str) -> str | None:
    """The state product a hull coefficient multiplies, from the kinds' naming (``Yvvr``
    multiplies v'^2 r', ``Nrar`` r'|r'|, ``Xdd`` delta^2): its letters v, r, d (rudder), u
    (surge, as u/U0 - 1); ``a`` (absolute value) adds nothing. None for a coefficient that is no
    state product (R0, t_R, a wind factor...)."""
    m = _MONOMIAL.match(str(name))
    if not m or not any(c in m.group(1) for c in "vrd"):
        return None
    return m.group(1).replace("a", "")


def monomial_values(df, letters: str, L: float, U0: float) -> tuple[np.ndarray, np.ndarray]:
    """(|product of the states ``letters`` names| per sample, weights (U/U0)^4) of a frame (see
    :func:`monomial_of`), over its samples faster than ``MIN_SPEED_U0`` U0."""
    u, v, r = (np.asarray(df[c], float) for c in ("u", "v", "r"))
    U = np.hypot(u, v)
    ok = np.isfinite(U) & (U > MIN_SPEED_U0 * U0)
    d = np.asarray(df["delta"], float) if "delta" in getattr(df, "columns", ()) else np.zeros_like(u)
    each = {"v": np.abs(v[ok] / U[ok]), "r": np.abs(r[ok] * L / U[ok]), "d": np.abs(d[ok]),
            "u": np.abs(u[ok] / U0 - 1.0)}
    out = np.ones(int(ok.sum()))
    for c in letters:
        out = out * each[c]
    return out, (U[ok] / U0) ** 4


def monomial_reach(frames, letters: str, L: float, U0: float, q: float = ENVELOPE_QUANTILE) -> float:
    """The weighted ``q`` quantile of |the state product ``letters``| over the frames: how far
    the records reach in the direction a coefficient acts."""
    frames = [frames] if hasattr(frames, "columns") else [f for f in frames if f is not None]
    xs, ws = zip(*[monomial_values(f, letters, L, U0) for f in frames]) if frames else ((), ())
    return weighted_quantile(np.concatenate(xs), np.concatenate(ws), q) if xs else math.nan
