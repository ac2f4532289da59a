"""A predicted manoeuvre metric with its interval and the coefficients that carry it: what the
doctor's report and ``study.doctor.turn_prediction`` give for every predicted metric.

:func:`metric_interval` combines the three parts (``study.doctor.model_error`` measures them,
``study.doctor.prediction_interval`` adds them); :func:`carriers` names the coefficients a metric is
sensitive to, ranked by their share of its variance, and says whether the training records determine
each where the prediction goes (its posterior sd under half its prior's -- the doctor's rule for
"determined" -- and the state product it multiplies within the records' reach);
:func:`predict_metrics` does both for a closed-loop manoeuvre nobody measured (a 35 deg turning
circle from a steady approach).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..identify.with_effects import identify_effects
from . import model_error as me
from . import prediction_interval as pi

#: the standard turns a report predicts (title, manoeuvre config or dict; IMO MSC.137(76))
TURNS = (("35 deg turning circle to starboard", "turning_35"),
         ("35 deg turning circle to port", {"name": "turning_35_port", "type": "turning", "first": "port",
                                            "t_start": 10.0, "amp_deg": 35.0, "pullout_deg": 540.0,
                                            "duration_L": 60.0}))
#: the turning-circle metrics a predicted turn gives (``study.records.metrics.turning_metrics``), in ship lengths
TURN_METRICS = ("tactical_diameter_L", "advance_L", "transfer_L")
#: a coefficient is named as a carrier of a metric when its share of the variance is at least this
MIN_SHARE = 0.05
#: posterior sd over prior sd below which the records determine a coefficient (as ``EffectsProblem.identifiability``)
DETERMINED_RATIO = 0.5
#: a state less than this share beyond the training envelope is at its edge, not outside it (assumption: the
#: envelope's 99th percentile itself moves by a few % between records)
EDGE = 0.05
#: the method, as the report states it
METHOD = (
    "90 % interval = the value times exp(+-1.645 s), s^2 = s_id^2 + max(s_struct, s_extrap)^2 on the log scale "
    "(assumption: independent, normal relative errors of identification and of the model's form; s_struct and "
    "s_extrap are two estimates of the latter, so the larger is taken rather than both added). s_id: the spread of "
    "the metric over draws from the fit's posterior (its linear unknowns and its effects' nonlinear parameters, "
    "the latter by a Laplace approximation of the profile training error); s_struct: its root-mean-square log deviation over the other "
    "models the records cannot tell apart (training and validation errors within the doctor's tie of the model's "
    "own or lower; the anchor's sd halved and doubled; the anchor set itself when it fits the training records as "
    "well); s_extrap = sqrt(s0^2 + (k d)^2): the relative error of the training records predicted from the others "
    "(each left out in turn; the harsher half from the gentler half), each held-out prediction's own "
    "identification spread (its fit's posterior draws replayed through it) taken out in quadrature, s0 the floor "
    "and k its growth with d, the distance outside the training envelope (the largest relative excess of |v'|, "
    "|r'|, the drift angle and the rudder angle over the records' 99th percentiles). The metric's own held-out "
    "errors when two or more training records carry it, else those of the RMS yaw rate at speed (for a turn's "
    "advance, those of the zigzags' initial turning time, the turn's onset, where they are the larger). Not covered: "
    "errors the training records share with the prediction (a sensor bias, the facility), a growth steeper than "
    "linear beyond the farthest held-out record, and conditions no record has (another depth, speed or loading). "
    "The interval is for the ship's metric: a measured value's own noise is its own interval (measured_low, "
    "measured_high), and the two agree when their log difference is within 1.645 sqrt(s^2 + s_meas^2).")


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)


def metric_interval(value: float, draw_values, alt_values, distance: float, growth: dict,
                    level: float = 0.9) -> dict:
    """One metric's interval and its parts: ``{'low', 'high', 'half_width', 's_id', 's_struct',
    's_extrap', 'draws', 'alternatives', 'distance', 'growth_source', 'why', 'caveat'}``
    (``why``: a reason when it has none; ``caveat``: set when the prediction lies farther outside
    the envelope than any held-out record did, so that the growth of its error is assumed, not
    measured)."""
    s_id, n_draws = pi.draws_log_sd(draw_values, level)
    s_struct, n_alt = pi.structural_log_sd(value, alt_values)
    s_ext = pi.extrapolation_log_sd(distance, growth) if _finite(distance) else math.nan
    out = pi.combine(value, 0.0 if len(np.ravel(draw_values)) == 0 else s_id, s_struct, s_ext, level)
    why = None
    if not (_finite(value) and value > 0):
        why = "no positive predicted value"
    elif len(np.ravel(draw_values)) and not math.isfinite(s_id):
        why = f"only {n_draws} of {len(np.ravel(draw_values))} posterior draws reached the metric"
    elif not math.isfinite(s_ext):
        why = growth.get("note") or "the extrapolation error could not be calibrated"
    d_max = growth.get("d_max", math.nan)
    beyond = _finite(distance) and _finite(d_max) and distance > d_max + EDGE
    caveat = (f"the prediction lies {distance:.2g} outside the training envelope; the error's growth was measured "
              f"only up to {d_max:.2g}: beyond that the interval assumes it grows no faster") if beyond else None
    return {"low": out["low"], "high": out["high"], "half_width": out["half_width"], "s_id": s_id,
            "s_struct": s_struct, "s_extrap": s_ext, "draws": n_draws, "alternatives": n_alt,
            "distance": distance, "growth_source": growth.get("source"), "why": why, "caveat": caveat}


def _pow(letters: str) -> str:
    out = []
    for c in dict.fromkeys(letters):
        k = letters.count(c)
        name = {"v": "v'", "r": "r'", "d": "delta", "u": "u'"}[c]
        out.append(name + (f"^{k}" if k > 1 else ""))
    return " ".join(out)


def _identified(ratio) -> str:
    """The doctor's words for a posterior sd over the prior's
    (``EffectsProblem.identifiability``)."""
    if ratio is None:
        return "no prior: set by the records alone"
    if ratio < DETERMINED_RATIO:
        return f"determined by the records (posterior sd {ratio:.2f} of the prior's)"
    if ratio < 0.9:
        return f"partly determined by the records (posterior sd {ratio:.2f} of the prior's)"
    return f"NOT determined by the records (posterior sd {ratio:.2f} of the prior's): the prior sets it"


def carriers(rows: list, prediction, training_frames, L: float, U0: float, unit: str = "",
             half_width: float = math.inf) -> list:
    """The coefficients that carry a metric (rows of ``model_error.sensitivities``): those with a
    share of its variance of at least ``MIN_SHARE``, by share, then those that move it by more
    than ``half_width`` (the interval's, in the metric's unit) when reset to their anchor value,
    by that move -- a coefficient the records determine can carry a prediction far from the
    anchor set's. Each with ``reach_ratio`` (how far the prediction goes in the state product it
    multiplies, over the training records' reach; None for no state product), ``determined`` (by
    the records, and within their reach) and a plain ``sentence``."""
    named = [r for r in rows if _finite(r.get("share")) and r["share"] >= MIN_SHARE]
    moved = sorted([r for r in rows if r not in named and _finite(r.get("reset"))
                    and abs(r["reset"]) > half_width], key=lambda r: -abs(r["reset"]))
    out = []
    for r in named + moved:
        mono = pi.monomial_of(r["coefficient"])
        reach = None
        if mono and prediction is not None:
            got = pi.monomial_reach(prediction, mono, L, U0)
            have = pi.monomial_reach(training_frames, mono, L, U0)
            reach = got / have if (_finite(got) and _finite(have) and have > 0) else None
        ratio = r.get("ratio")
        inside = reach is None or reach <= 1.0
        share = f"{100 * r['share']:.0f} %" if _finite(r.get("share")) else "n/a"
        say = f"{r['coefficient']}: {share} of the variance"
        if _finite(r.get("reset")):
            big = " (more than the interval's half-width)" if abs(r["reset"]) > half_width else ""
            say += f"; reset to its anchor value the metric moves {r['reset']:+.3g}{(' ' + unit) if unit else ''}{big}"
        say += "; " + _identified(ratio)
        if reach is not None and not inside:
            say += (f"; the prediction reaches {reach:.1f} times further in |{_pow(mono)}| than the training "
                    "records do: there it is extrapolated")
        out.append({**{k: r.get(k) for k in ("coefficient", "share", "per_sd", "reset", "ratio", "estimate",
                                              "anchor")},
                    "reach_ratio": reach, "determined": bool(ratio is not None and ratio < DETERMINED_RATIO
                                                             and inside), "sentence": say})
    return out


def extrapolation_text(dist: dict, env_pred: dict, env_train: dict) -> str:
    """A plain sentence: inside the training envelope, at its edge (no state more than ``EDGE``
    beyond it), or which states go how far outside it."""
    names = {"v'": "|v'|", "r'": "|r'|", "drift_deg": "drift angle [deg]", "rudder_deg": "rudder angle [deg]"}
    if not _finite(dist.get("distance")):
        return "the prediction's states could not be compared with the training envelope"
    out = [f"{names[s]} {env_pred[s]:.3g} against {env_train[s]:.3g} (+{100 * e:.0f} %)"
           for s, e in dist["excess"].items() if _finite(e) and e > EDGE]
    if out:
        return "EXTRAPOLATES beyond the training records: " + "; ".join(out)
    return "at the edge of the training envelope" if dist["distance"] > 0 else "inside the training envelope"


# ---------------------------------------------------------------------------------------------- a turn's metrics
def _turn_values(df, L: float) -> dict:
    from study.records import metrics as M

    try:
        m = M.turning_metrics(df, L=L)
        return {k: float(m[k]) for k in TURN_METRICS}
    except (ValueError, KeyError, IndexError):  # never reached 180 deg, or diverged
        return {k: math.nan for k in TURN_METRICS}


def _frames(t, out) -> list:
    from ..sim import to_frame

    return [to_frame(out, t, b) for b in range(out.shape[2])] if out is not None else []


def predict_metrics(problem, fit, v, maneuver, alternatives=(), cal: dict | None = None, draws: int = 64,
                    seed: int = 0, level: float = 0.9) -> dict:
    """A closed-loop manoeuvre of ``fit``'s vessel ``v`` (its rpm and approach speed set) with
    every turning metric's interval and carriers. ``alternatives``: (label, problem, fit, vessel)
    of the models the records cannot tell apart, each turned as it is; ``cal``:
    ``model_error.calibrate(problem, fit)`` (computed when None). Returns ``{'metrics': {name:
    {value, low, high, ..., carriers}}, 'extrapolation': {...}, 'alternatives': [labels],
    'frame': the point prediction, 'calibration', 'draw_values': {name: array}}``."""
    from ..sim import simulate

    L, U0 = problem.L, problem.U0
    cal = me.calibrate(problem, fit) if cal is None else cal
    point = simulate(v, maneuver, u0=v.U0)
    values = _turn_values(point, L)
    post, sets = me.posterior_draws(problem, fit, draws, seed)
    table = me.coefficient_table(problem, fit, post) if post is not None else []
    sens_sets = me.sensitivity_sets(post, table) if post is not None else []
    t, out = me.turn_members(problem, fit, v, maneuver, sets + sens_sets)
    member = [_turn_values(f, L) for f in _frames(t, out)]
    alt_vals = []
    for label, pb, ft, va in alternatives:
        alt_vals.append(_turn_values(simulate(va, maneuver, u0=va.U0), L))
    env_pred = pi.state_envelope(point, L, U0)
    dist = pi.envelope_distance(env_pred, cal["envelope"])
    res, drawn = {}, {}
    for m in TURN_METRICS:
        dv = drawn[m] = np.array([x[m] for x in member[:len(sets)]])
        iv = metric_interval(values[m], dv, [a[m] for a in alt_vals], dist["distance"], me.growth_for(cal, m),
                             level)
        sens = me.sensitivities(table, values[m], [x[m] for x in member[len(sets):]]) if table else []
        hw = values[m] * iv["half_width"] if _finite(iv["half_width"]) else math.inf
        res[m] = {"value": values[m], **iv, "carriers": carriers(sens, point, problem.records, L, U0, "L", hw)}
    return {"metrics": res, "frame": point, "alternatives": [a[0] for a in alternatives],
            "alternative_values": {a[0]: v for a, v in zip(alternatives, alt_vals)},
            "extrapolation": {**dist, "prediction": env_pred, "training": cal["envelope"],
                              "text": extrapolation_text(dist, env_pred, cal["envelope"])},
            "calibration": {"splits": cal["splits"], "notes": cal["notes"]}, "draw_values": drawn}


# ------------------------------------------------------------------------------------ a turn nobody measured
def setup_effects_left_out(problem, fit, facility: str | None = None, scale: str | None = None,
                           keep_setup_effects: bool = False) -> tuple:
    """(``fit`` for a prediction in ``facility`` at ``scale``, the set-up effects left out, why):
    the set-up effects are left out unless kept, or the prediction's facility and scale are the
    training records' own."""
    from study.records.facility import other_setup, setup_of

    drop = [e for e in fit.effects if getattr(problem.effect(e), "setup_effect", False)]
    if not drop or keep_setup_effects:
        return fit, [], None
    training = [setup_of(i.meta, problem.vessel_cfg) for i in problem.infos]
    if facility is None:
        why = "the prediction's facility is not stated (a manoeuvre nobody measured: not the training set-up)"
    else:
        why = other_setup((facility, scale), training)
    if why is None:
        return fit, [], None
    return me.without_effects(problem, fit, drop), drop, why


def turn_vessel(problem, fit, u0: float | None = None, n: float | None = None):
    """(vessel, n): ``fit``'s model ready to turn from a steady approach at ``u0`` (default the
    vessel's U0), its propeller at ``n`` (default its own self-propulsion point at ``u0``)."""
    v = problem.vessel(fit.effects, fit.values, coefs=fit.coefs, replay=False)
    u0 = float(problem.U0 if u0 is None else u0)
    if n is None:
        if not hasattr(v.kind, "solve_n"):
            raise ValueError(f"vessel kind '{v.kind_name}' has no propeller to solve for: give n")
        n = float(v.kind.solve_n(v.params[:len(v.kind.PARAM_NAMES)], u0))
    return replace(v, n0=float(n), U0=u0), float(n)


def default_alternatives(problem, fit, tie: float = 0.1) -> tuple:
    """([(label, problem, fit)], notes): the models as defensible as ``fit`` that need no other
    records -- its anchor's sd halved and doubled; the anchor set itself when it fits the
    training records within ``tie``; and, when the problem's catalogue has ``hull_nonlinear`` and
    the model lacks hull terms, the model with them freed (another structure) when it fits within
    ``tie`` or better (``study.doctor.model_error``)."""
    alts = me.anchor_variants(problem, fit)
    pub, why = me.published_set(problem, fit, tie)
    notes = [why] if why else []
    alts += [pub] if pub else []
    hn = problem.effects.get("hull_nonlinear")
    if hn is not None and "hull_nonlinear" not in fit.effects and hn.applies(problem) is None:
        other = identify_effects(problem, tuple(fit.effects) + ("hull_nonlinear",), start=dict(fit.outer),
                                 grid=False, fixed=tuple(fit.outer))
        if me.data_error(problem, other) <= (1.0 + tie) * me.data_error(problem, fit):
            alts.append(("with the hull terms the model lacks freed (hull_nonlinear)", problem, other))
        else:
            notes.append("the model with the hull terms it lacks freed fits the training records worse")
    return alts, notes


def predict_turn(problem, fit, u0: float | None = None, n: float | None = None, draws: int = 64, seed: int = 0,
                 maneuver="turning_35", level: float = 0.9, facility: str | None = None,
                 scale: str | None = None, keep_setup_effects: bool = False, alternatives=None,
                 model_error: bool = True, tie: float = 0.1, cal: dict | None = None) -> dict:
    """Tactical diameter, advance and transfer [L] of ``fit``'s model in ``maneuver`` from a steady
    approach at ``u0`` (default: the vessel's U0), each with its ``level`` interval; set-up effects
    left out for another ``facility`` or ``scale`` unless ``keep_setup_effects`` (see the module's
    docstring).

    ``alternatives``: (label, problem, fit) of other models the records cannot tell apart (the
    caller's choice, e.g. other effects); None: :func:`default_alternatives`. Each turns at its own
    self-propulsion point unless ``n`` is given. ``cal``:
    ``study.doctor.model_error.calibrate(problem, fit)`` when already computed.
    ``model_error=False``: the identification spread alone (``td_low``, ``td_high``).

    Returns ``{'tactical_diameter_L', 'advance_L', 'transfer_L', 'td_low', 'td_high',
    'td_draws_median', 'n', 'u0', 'draws', 'finite_draws', 'setup_left_out', 'setup_why',
    'metrics', 'extrapolation', 'alternatives', 'notes'}``: ``td_low``/``td_high`` the central
    ``level`` share of the posterior draws' tactical diameters (identification spread only);
    ``metrics[name]`` the combined interval (``low``, ``high`` and its parts,
    ``study.doctor.predictions.metric_interval``) and the coefficients that carry it
    (``carriers``)."""

    fit, left_out, why = setup_effects_left_out(problem, fit, facility, scale, keep_setup_effects)
    v, n_used = turn_vessel(problem, fit, u0, n)
    out = {"n": n_used, "u0": v.U0, "draws": int(draws), "td_low": float("nan"), "td_high": float("nan"),
           "td_draws_median": float("nan"), "finite_draws": 0, "setup_left_out": list(left_out),
           "setup_why": why, "metrics": {}, "extrapolation": None, "alternatives": [], "notes": []}
    if not model_error:
        from ..sim import simulate

        out.update(_turn_values(simulate(v, maneuver, u0=v.U0), problem.L))
        _, sets = me.posterior_draws(problem, fit, draws, seed)
        t, sims = me.turn_members(problem, fit, v, maneuver, sets)
        tds = np.array([_turn_values(f, problem.L)["tactical_diameter_L"] for f in _frames(t, sims)])
    else:
        notes = []
        if alternatives is None:
            alternatives, notes = default_alternatives(problem, fit, tie)
        alts = []
        for label, pb, ft in alternatives:
            ft = setup_effects_left_out(pb, ft, facility, scale, keep_setup_effects)[0]
            alts.append((label, pb, ft, turn_vessel(pb, ft, v.U0, n)[0]))
        res = predict_metrics(problem, fit, v, maneuver, alts, cal or me.calibrate(problem, fit), draws, seed,
                              level)
        out.update({m: res["metrics"][m]["value"] for m in TURN_METRICS})
        out.update(metrics=res["metrics"], extrapolation=res["extrapolation"], alternatives=res["alternatives"],
                   alternative_values=res["alternative_values"], notes=notes + res["calibration"]["notes"])
        tds = res["draw_values"]["tactical_diameter_L"]
    ok = np.isfinite(tds)
    out["finite_draws"] = int(ok.sum())
    if ok.sum() >= 2:
        a = (1.0 - level) / 2.0
        out.update(td_low=float(np.quantile(tds[ok], a)), td_high=float(np.quantile(tds[ok], 1.0 - a)),
                   td_draws_median=float(np.median(tds[ok])))
    return out
