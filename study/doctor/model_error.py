"""The three parts of a predicted metric's uncertainty, measured on a fitted model and its training
records (the arithmetic that combines them: ``study.doctor.prediction_interval``).

- :func:`posterior_draws` and :func:`replay_members`: the fit's posterior draws (or any other
  coefficient sets) replayed through a record in one compiled batch, as ``EffectsProblem.predict``
  replays one fit;
- :func:`anchor_variants` and :func:`published_set`: models as defensible as the fit -- the anchor's
  relative sd halved and doubled (a setting: 30 % is a choice), and the anchor set itself when it
  fits the training records about as well (training error within ``tie`` of the fit's);
- :func:`calibrate`: the extrapolation error, measured on the training records themselves. They are
  ranked by how far they reach (their envelope, ``prediction_interval.state_envelope``, relative to
  all of them); the gentler half is trained and the harsher half predicted, and each record is left
  out in turn and predicted from the others (pairs mostly inside the envelope, for the floor) --
  each split's model identified with the fit's effects, their nonlinear parameters held at the fit's
  values (assumption: they do not depend on the split). Each held-out record is replayed (from its
  manoeuvre's start; a record that starts at rest from where it first reaches half the service
  speed) and gives its distance outside the split's envelope and the relative error of every
  manoeuvre metric it carries, and of its RMS yaw rate, and the split's posterior draws replayed
  through it give that prediction's own identification spread (:func:`own_spread`), which
  :func:`growth_for` takes out of the error;
- :func:`sensitivities`: per coefficient, the metric's change for one posterior sd either way
  (central difference over +-1 sd: the secant, robust to the simulation's nonlinearity) and when the
  coefficient is reset to its anchor value; its share of the metric's variance, g_j^2 var_j / sum_k
  g_k^2 var_k (each coefficient alone: correlations between coefficients are left out of the shares,
  an assumption).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pandas as pd

from ..identify.with_effects import Fit, identify_effects
from . import prediction_interval as pi

#: the metric whose error stands in for a metric no held-out record carries: the RMS yaw rate, which a turning
#: circle's size scales with (a steady turn's diameter is 2 U / r)
SURROGATE = "rms_yaw_rate"
#: a turn's advance (the distance run until the heading has changed by 90 deg) depends on how soon the ship starts
#: turning as well as on the yaw rate it settles at, and the RMS yaw rate does not see an onset that comes late: the
#: onset's stand-in is the zigzags' initial turning time (rudder execution to the switch heading), and the larger
#: of the two errors counts (``growth_for``; assumption, labelled)
ONSET_SURROGATE = "initial_turning_time"
SURROGATES = {"advance_L": ONSET_SURROGATE, "advance": ONSET_SURROGATE}
#: a record that starts slower than this share of U0 is replayed from where it first reaches it
START_SPEED_U0 = 0.5
#: held-out records that reach less than this share of the farthest record's reach do not calibrate (see
#: :func:`growth_for`)
MIN_REACH = 0.5
#: posterior draws of a split's fit replayed through each record it predicts: the held-out prediction's own
#: identification spread, which :func:`growth_for` takes out of its error (a setting. Measured on lognormal draws,
#: 4000 repetitions: from 16 draws ``prediction_interval.draws_log_sd`` is 0.85 of the true sd on average, with a
#: spread of 0.17 -- low, the conservative side for a component that is subtracted)
CAL_DRAWS = 16


def model_cfg_of(problem) -> dict:
    """The model config an ``EffectsProblem`` was built from (free coefficients per equation,
    omitted terms)."""
    eqs = {}
    for c, eq in problem.model_eq.items():
        eqs.setdefault(eq, []).append(c)
    omit = list(problem.omit)
    if problem.omit_eq:
        omit = {}
        for c in problem.omit:
            omit.setdefault(problem.omit_eq[c], []).append(c)
    return {"name": problem.model_name, "type": "kind", "equations": eqs, "omit": omit}


def posterior_draws(problem, fit, draws: int, seed: int = 0) -> tuple:
    """(posterior, list of parameter dicts): ``draws`` draws from the fit's Gaussian posterior,
    its linear unknowns together with its effects' nonlinear parameters
    (``EffectsProblem.posterior(fit, nonlinear=True)``, computed once per fit; the covariance made
    positive semidefinite by clipping its eigenvalues); (None, []) when nothing is free."""
    if not draws:
        return None, []
    cache = problem.__dict__.setdefault("_joint_posteriors", {})
    if id(fit) not in cache or cache[id(fit)][0] is not fit:
        cache[id(fit)] = (fit, problem.posterior(fit, nonlinear=True))
    post = cache[id(fit)][1]
    if post is None:
        return None, []
    w, V = np.linalg.eigh(post["cov"])
    # an eigenvector's sign is arbitrary (LAPACK's kernels may choose differently on another CPU): each is turned
    # so that its largest component is positive, so that a seed gives the same draws on every machine
    V = V * np.sign(V[np.argmax(np.abs(V), axis=0), np.arange(V.shape[1])])
    z = np.random.default_rng(seed).standard_normal((draws, len(w)))
    thetas = post["mean"] + (z * np.sqrt(np.clip(w, 0.0, None))) @ V.T
    return post, [dict(zip(post["names"], th)) for th in thetas]


def params_of(problem, fit, coefs: dict, info=None, replay: bool = True) -> np.ndarray:
    """The packed vessel parameters of ``fit`` with its coefficients and nonlinear parameters
    replaced by those in ``coefs`` (those the fit lacks -- a set-up effect left out -- are
    dropped)."""
    c = {k: float(v) for k, v in coefs.items() if k in fit.coefs}
    o = {k: float(v) for k, v in coefs.items() if k in fit.outer}
    return problem.vessel(fit.effects, {**fit.outer, **o, **c}, info, coefs={**fit.coefs, **c}, replay=replay).params


def replay_members(problem, fit, df: pd.DataFrame, info, coef_sets: list) -> list:
    """``fit`` replayed through the record ``df`` once per coefficient set, in one compiled
    batch, exactly as ``EffectsProblem.predict`` replays it (first segment, the record's rudder
    and propeller, the effects' initial state); a member that overflows or leaves ``ENVELOPE`` is
    None."""
    from ..identify.output_error import initial_value
    from ..identify.structures import segments
    from ..identify.with_effects import ENVELOPE
    from ..sim import replay

    seg = segments(df, 0, min_len=10)
    if not seg or not coef_sets:
        return [None] * len(coef_sets)
    t = seg[0].t
    h = float(np.median(np.diff(t)))
    tu = t[0] + h * np.arange(int(round((t[-1] - t[0]) / h)) + 1)
    data = {c: np.interp(tu, t, a) for c, a in seg[0].data.items()}
    v = problem.vessel(fit.effects, fit.values, info, coefs=fit.coefs)
    x0 = {c: initial_value(tu, data[c]) for c in ("u", "v", "r", "x0", "y0", "psi")}
    for e in fit.effects:  # one initial state for the batch: the fit's own (a current's draw moves it by its spread)
        problem.effect(e).initial_state(problem, fit.values, x0)
    state0 = [x0["u"], x0["v"], x0["r"], x0["x0"], x0["y0"], x0["psi"]]
    P = np.column_stack([params_of(problem, fit, c, info) for c in coef_sets])
    with np.errstate(all="ignore"):
        out = replay(v, tu, data["delta"], data["n"], state0, P=P)
    frames = []
    for b in range(P.shape[1]):
        o = out[:, :, b]
        bad = (not np.all(np.isfinite(o[:, :6])) or np.max(np.hypot(o[:, 0], o[:, 1])) > ENVELOPE["speed_U0"] *
               problem.U0 or np.max(np.abs(o[:, 2])) > ENVELOPE["r_U0_L"] * problem.U0 / problem.L)
        frames.append(None if bad else pd.DataFrame(
            {"time": tu, "u": o[:, 0], "v": o[:, 1], "r": o[:, 2], "x0": o[:, 3], "y0": o[:, 4], "psi": o[:, 5],
             "delta": o[:, 6]}))
    return frames


def replay_start(df: pd.DataFrame, U0: float) -> float | None:
    """Where a record's prediction starts: its manoeuvre's start
    (``maneuver_metrics.manoeuvre_start``); for a record with none that starts below half the
    service speed, the first time it reaches it; else None (the whole record). NaN when it never
    reaches it (no prediction at speed to compare)."""
    from study.records.maneuver_metrics import manoeuvre_start

    t0 = manoeuvre_start(df)
    if t0 is not None:
        return t0
    U = np.hypot(df["u"].to_numpy(float), df["v"].to_numpy(float))
    if U[0] >= START_SPEED_U0 * U0:
        return None
    fast = np.flatnonzero(U >= START_SPEED_U0 * U0)
    return float(df["time"].iloc[fast[0]]) if len(fast) else math.nan


def cut(df: pd.DataFrame, t0) -> pd.DataFrame | None:
    """The record from ``t0`` on (None: whole; NaN or fewer than 10 samples left: None)."""
    if t0 is None:
        return df
    if not math.isfinite(t0):
        return None
    c = df[df["time"] >= t0 - 1e-9].reset_index(drop=True)
    return c if len(c) >= 10 else None


def rms_yaw_rate(frame, measured, U0: float) -> float:
    """The surrogate metric: the RMS yaw rate of ``frame`` over the samples where the
    ``measured`` record moves at speed (at least half the service speed); NaN when fewer than
    half its samples do (a record at low speed is another regime than the manoeuvres at speed the
    metrics describe)."""
    if frame is None:
        return math.nan
    t = np.asarray(frame["time"], float)
    tm = measured["time"].to_numpy(float)
    U = np.interp(t, tm, np.hypot(measured["u"].to_numpy(float), measured["v"].to_numpy(float)))
    r = np.asarray(frame["r"], float)
    ok = np.isfinite(r) & (U >= START_SPEED_U0 * U0)
    return float(np.sqrt(np.mean(r[ok] ** 2))) if ok.sum() >= max(10, 0.5 * len(t)) else math.nan


def metric_values(name: str, measured: pd.DataFrame, frame, L: float, U0: float) -> dict:
    """{metric: value} of ``frame`` (a replay of the record ``measured``, or the record itself),
    the manoeuvre metrics of ``study.records.maneuver_metrics`` (from the measured record's
    switch heading) and the RMS yaw rate at speed (:func:`rms_yaw_rate`)."""
    from study.records.maneuver_metrics import maneuver_metrics

    if frame is None:
        return {}
    out = {m["metric"]: m["final"] for m in maneuver_metrics(name, measured, None, frame, L)}
    out[SURROGATE] = rms_yaw_rate(frame, measured, U0)
    return out


def log_error(pred, meas) -> float:
    """|log(pred / meas)|, NaN unless both are positive and finite."""
    ok = all(isinstance(x, (int, float)) and math.isfinite(x) and x > 0 for x in (pred, meas))
    return abs(math.log(pred / meas)) if ok else math.nan


# ---------------------------------------------------------------------------------------------- alternatives
def without_effects(problem, fit, drop):
    """``fit`` with the effects ``drop`` left out: their nonlinear parameters, linear unknowns
    and the coefficients they alone freed removed (those return to the vessel config's values);
    everything else as identified."""
    drop = [e for e in fit.effects if e in set(drop)]
    if not drop:
        return fit
    own = problem.by_effect(fit)
    keep = tuple(e for e in fit.effects if e not in drop)
    kept_names = set(problem.model_free) | {k for e in keep for k in own.get(e, {})}
    gone = {k for e in drop for k in own.get(e, {}) if k not in kept_names}
    return Fit(keep, {k: v for k, v in fit.outer.items() if k not in gone},
               {k: v for k, v in fit.coefs.items() if k not in gone}, fit.training_error, fit.rss, fit.evaluations)


def _records_of(problem, idx) -> list:
    return [SimpleNamespace(data=problem.records[i], meta=problem.infos[i].meta) for i in idx]


def refit(problem, fit, records_idx=None, anchor: float | None = None):
    """(problem, fit): ``fit``'s effects identified again on the training records ``records_idx``
    (default all) with the anchor ``anchor`` (default the problem's), the effects' nonlinear
    parameters held at ``fit``'s."""
    from ..identify.with_effects import EffectsProblem

    idx = list(range(len(problem.records))) if records_idx is None else list(records_idx)
    pb = EffectsProblem(problem.vessel_cfg, model_cfg_of(problem), _records_of(problem, idx), problem.structure,
                        problem.effects, [problem.infos[i].name for i in idx],
                        problem.anchor if anchor is None else anchor)
    f = identify_effects(pb, fit.effects, start=dict(fit.outer), grid=False, fixed=tuple(fit.outer))
    return pb, f


def anchor_variants(problem, fit, factors=(0.5, 2.0)) -> list:
    """[(label, problem, fit)]: ``fit`` identified again with the anchor's relative sd times each
    factor (the 30 % default is a choice; half and double it are as defensible). None for an
    unanchored fit."""
    if not problem.anchor or not problem.model_free:
        return []
    out = []
    for f in factors:
        a = problem.anchor * f
        pb, ft = refit(problem, fit, anchor=a)
        out.append((f"anchored {100 * a:.0f} % instead of {100 * problem.anchor:.0f} %", pb, ft))
    return out


def at_bounds(problem, fit, rel: float = 1e-3) -> list:
    """The effects' nonlinear parameters of ``fit`` that lie on a bound of their search box
    (within ``rel`` of its width): their optimum lies outside the range the catalogue holds
    physical -- an identification that failed, not a model the records support (a wake fraction
    of 0.7, a depth of 1.1 drafts in a pond). A bound at zero is not counted: there the effect
    vanishes (no delay, no lag), a physical limit, not a failure."""
    out = []
    for name, lo, hi, _ in problem.outer_params(fit.effects):
        x = fit.outer.get(name)
        if not isinstance(x, (int, float)):
            continue
        if any(b != 0.0 and abs(x - b) <= rel * (hi - lo) for b in (lo, hi)):
            out.append(f"{name} = {x:.3g} (bounds {lo:.3g}, {hi:.3g})")
    return out


def data_error(problem, fit) -> float:
    """The fit's misfit of the training rows alone (its training error without the anchor's
    penalty)."""
    ref = problem.reference()
    return float(np.mean([fit.rss[eq] / ref[k] for k, eq in enumerate(("X", "Y", "N"))])) if fit.rss else math.nan


def published_set(problem, fit, tie: float = 0.1) -> tuple:
    """((label, problem, fit) or None, why): the anchor set itself (the vessel config's
    coefficients, the effects' own unknowns solved) as an alternative when its training misfit is
    within ``tie`` of the fit's."""
    if not problem.model_free:
        return None, "the model has no free coefficients: the fit is the vessel config's set"
    coefs, J, rss = problem.solve(fit.effects, dict(fit.outer), model=False)
    own = data_error(problem, fit)
    pub = Fit(fit.effects, dict(fit.outer), {**{c: problem.base_param(c) for c in problem.model_free}, **coefs},
              J, rss)
    if not (math.isfinite(J) and math.isfinite(own)) or J > (1.0 + tie) * own:
        return None, (f"the vessel config's set fits the training records worse (training error {J:.3g} against "
                      f"{own:.3g}, beyond {100 * tie:.0f} %)")
    return ("the vessel config's coefficients (the anchor set)", problem, pub), None


# ---------------------------------------------------------------------------------------------- calibration
def reaches(envelopes: list) -> list:
    """Each record's reach: the mean over the states of its envelope over all records' (a state
    it has no sample of counts 0; the mean, not the largest, so that records which all reach the
    same rudder angle still rank). :func:`calibrate` ranks by the records' envelopes at speed
    (``START_SPEED_U0``): a weighted quantile does not see that a whole record was run slowly,
    and a record run slowly is no harsh manoeuvre at speed."""
    keys = list(pi.STATES)
    total = {k: max([e[k] for e in envelopes if np.isfinite(e[k])] or [math.nan]) for k in keys}
    return [float(np.mean([e[k] / total[k] if np.isfinite(e[k]) and total[k] > 0 else 0.0 for k in keys]))
            for e in envelopes]


def splits(envelopes: list) -> list:
    """[(label, trained indices, predicted indices)]: the gentler half -> the harsher half (by
    :func:`reaches`), then each record left out in turn (with nearly all the data: the error of a
    model like the full one, mostly inside the envelope -- the floor -- and outside it for the
    records that reach furthest)."""
    order = [int(i) for i in np.argsort(reaches(envelopes), kind="stable")]
    n = len(order)
    if n < 2:
        return []
    half = (n + 1) // 2
    return [("gentler half -> harsher half", order[:half], order[half:])] + [
        ("each record left out", [j for j in order if j != i], [i]) for i in order]


def calibrate(problem, fit) -> dict:
    """The held-out pairs of :func:`splits` (see the module docstring): ``{'pairs': [{record,
    split, distance, state, errors: {metric: |log error|}, own_sd: {metric: the prediction's
    identification spread}}], 'envelope': the training envelope, 'splits', 'notes'}``."""
    L, U0 = problem.L, problem.U0
    envs = [pi.state_envelope(df, L, U0, min_speed=START_SPEED_U0) for df in problem.records]
    reach = reaches(envs)
    rmax = max(reach) or 1.0
    pairs, notes, done = [], [], []
    for label, tr, te in splits(envs):
        if not tr or not te:
            continue
        try:
            pb, f = refit(problem, fit, tr)
        except (ValueError, np.linalg.LinAlgError) as e:
            notes.append(f"split '{label}' not identified: {e}")
            continue
        env_tr = pi.state_envelope([problem.records[i] for i in tr], L, U0)
        if label not in done:
            done.append(label)
        for i in te:
            df, info = problem.records[i], problem.infos[i]
            c = cut(df, replay_start(df, U0))
            if c is None:
                continue
            pred = pb.predict(f, c, pb.info_for(c, info.meta, info.name))
            if pred is None:
                pairs.append({"record": info.name, "split": label, "distance": math.nan, "state": None,
                              "errors": {}, "diverged": True, "reach": reach[i] / rmax})
                continue
            dist = pi.envelope_distance(pi.state_envelope(pi.running(pred, c), L, U0), env_tr)
            meas, got = metric_values(info.name, c, c, L, U0), metric_values(info.name, c, pred, L, U0)
            errs = {m: log_error(got.get(m), v) for m, v in meas.items()}
            errs = {m: e for m, e in errs.items() if math.isfinite(e)}
            pairs.append({"record": info.name, "split": label, "distance": dist["distance"], "state": dist["state"],
                          "errors": errs, "own_sd": own_spread(pb, f, c, pb.info_for(c, info.meta, info.name),
                                                               info.name, list(errs), seed=i),
                          "diverged": False, "reach": reach[i] / rmax})
    if not done:
        notes.append("fewer than two training records: the extrapolation error cannot be calibrated")
    return {"pairs": pairs, "envelope": pi.state_envelope(problem.records, L, U0), "splits": done, "notes": notes}


def own_spread(problem, fit, df: pd.DataFrame, info, name: str, metrics: list, draws: int = CAL_DRAWS,
               seed: int = 0) -> dict:
    """{metric: the identification spread of a held-out prediction} -- ``draws`` posterior draws
    of the split's ``fit`` replayed through the held-out record ``df`` (:func:`replay_members`),
    the sd of each metric's log over them (``prediction_interval.draws_log_sd``; NaN when fewer
    than half the draws reach it)."""
    _, sets = posterior_draws(problem, fit, draws, seed)
    if not sets or not metrics:
        return {m: math.nan for m in metrics}
    vals = [metric_values(name, df, f, problem.L, problem.U0) for f in replay_members(problem, fit, df, info, sets)]
    return {m: pi.draws_log_sd([v.get(m, math.nan) for v in vals])[0] for m in metrics}


def growth_for(cal: dict, metric: str) -> dict:
    """The extrapolation error's growth for ``metric`` from the held-out pairs of records that reach
    at least ``MIN_REACH`` of the farthest record's reach (assumption: a much smaller manoeuvre's
    relative errors are dominated by what a large one hardly feels -- a rudder offset, an asymmetry,
    the noise -- and say nothing about a prediction at the envelope's edge or beyond): the metric's
    own errors where two or more such records carry it, else those of the surrogate (the RMS yaw
    rate) or, for a metric with a stand-in of its own (:data:`SURROGATES`: the initial turning time
    for a turn's advance) that two or more records carry, whichever of the two gives the larger
    error at the farthest held-out distance -- ``source`` says which. A held-out replay that
    diverged counts as an error of log 2 at the farthest distance seen, so that divergence is not
    left out (assumption).

    Each pair's own identification spread (``own_sd``, :func:`own_spread`: the split's posterior
    draws replayed through the held-out record) is taken out of its squared error
    (``prediction_interval.fit_growth``), so that the growth is the error of the model's form
    alone (see ``prediction_interval``); a pair without a measured spread (its draws failed)
    keeps its whole error (the conservative side), and so does a divergence. ``net_of_own``
    counts the pairs whose spread was taken out."""
    big = [p for p in cal["pairs"] if p.get("reach", 1.0) >= MIN_REACH]
    if len([p for p in big if metric in p["errors"]]) >= 2:
        return _growth(cal, big, metric)
    # a metric no two held-out records carry: the RMS yaw rate stands in, and where the metric has a stand-in of
    # its own (the advance: the onset) that two records carry, the larger error of the two at the farthest held-out
    # distance (the advance depends on both how soon the turn starts and the rate it settles at: assumption)
    out = _growth(cal, big, SURROGATE)
    other = SURROGATES.get(metric)
    if other is not None and len([p for p in big if other in p["errors"]]) >= 2:
        alt = _growth(cal, big, other)
        d = max(out["d_max"], alt["d_max"]) if math.isfinite(out["d_max"]) else alt["d_max"]
        if pi.extrapolation_log_sd(d, alt) > pi.extrapolation_log_sd(d, out) or not math.isfinite(out["sigma0"]):
            out = alt
    return out


def _growth(cal: dict, big: list, source: str) -> dict:
    """The growth fitted on the held-out pairs of ``big`` that carry ``source`` (and the divergences)."""
    use = [p for p in big if source in p["errors"]]
    dmax = max([p["distance"] for p in cal["pairs"] if math.isfinite(p["distance"])] or [0.0])
    div = [p for p in big if p.get("diverged")]
    d = [p["distance"] for p in use] + [dmax] * len(div)
    e = [p["errors"][source] for p in use] + [math.log(2.0)] * len(div)
    s = [float(p.get("own_sd", {}).get(source, math.nan)) for p in use] + [math.nan] * len(div)
    s = [x if math.isfinite(x) else 0.0 for x in s]
    return {**pi.fit_growth(d, e, s), "source": source, "left_out_small": len(cal["pairs"]) - len(big),
            "net_of_own": int(sum(x > 0 for x in s))}


# ---------------------------------------------------------------------------------------------- sensitivity
def coefficient_table(problem, fit, post: dict) -> list:
    """Per linear unknown of ``post``: name, estimate, posterior sd, anchor value (None: not
    anchored) and posterior sd over prior sd (None: no prior)."""
    out = []
    lam = post["prior"][1] if post.get("prior") is not None else None
    for j, n in enumerate(post["names"]):
        sd = float(np.sqrt(max(post["cov"][j, j], 0.0)))
        anchored = lam is not None and lam[j] > 0
        base = problem.base_param(n) if n in problem.base.param_names and n not in problem.omit else None
        out.append({"coefficient": n, "estimate": float(post["mean"][j]), "sd": sd,
                    "anchor": float(post["prior"][0][j]) if anchored else base,
                    "ratio": sd / float(np.sqrt(post["tau"] / lam[j])) if anchored else None})
    return out


def sensitivity_sets(post: dict, table: list) -> list:
    """The coefficient sets of :func:`sensitivities`: per coefficient +1 sd, -1 sd and (when it
    has one) its anchor value, the others at the posterior mean."""
    mean = dict(zip(post["names"], post["mean"]))
    sets = []
    for row in table:
        n = row["coefficient"]
        for x in (row["estimate"] + row["sd"], row["estimate"] - row["sd"],
                  row["anchor"] if row["anchor"] is not None else row["estimate"]):
            sets.append({**mean, n: float(x)})
    return sets


def sensitivities(table: list, value: float, member_values) -> list:
    """Rank the coefficients by their share of a metric's variance (see the module docstring),
    from the metric's values on the :func:`sensitivity_sets` members (three per coefficient, in
    order). Rows: the table's, with ``per_sd`` (the metric's change for +1 sd), ``share`` and
    ``reset`` (the change when reset to the anchor value); NaN where a member failed. Sorted by
    share, largest first."""
    v = np.asarray(member_values, float)
    if v.shape != (3 * len(table),):
        raise ValueError(f"expected {3 * len(table)} member values (three per coefficient), got {v.shape}")
    rows = []
    for j, row in enumerate(table):
        up, down, reset = v[3 * j: 3 * j + 3]
        per_sd = (up - down) / 2.0
        rows.append({**row, "per_sd": float(per_sd), "reset": float(reset - value) if row["anchor"] is not None
                     else math.nan})
    var = np.array([r["per_sd"] ** 2 for r in rows])
    tot = float(np.nansum(var))
    for r, x in zip(rows, var):
        r["share"] = float(x / tot) if tot > 0 and np.isfinite(x) else math.nan
    return sorted(rows, key=lambda r: -(r["share"] if np.isfinite(r["share"]) else -1.0))


def turn_members(problem, fit, v, maneuver, coef_sets: list):
    """(t, out) of a closed-loop manoeuvre (``study.sim.simulate_batch``) of ``fit``'s vessel
    ``v`` (its rpm and approach speed set) once per coefficient set."""
    from ..sim import simulate_batch

    if not coef_sets:
        return None, None
    P = np.column_stack([params_of(problem, fit, c, None, replay=False) for c in coef_sets])
    return simulate_batch(v, maneuver, P)
