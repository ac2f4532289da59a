"""The doctor's predicted manoeuvre metrics with their intervals, how far each prediction
extrapolates and which coefficients carry it (the method: ``study.doctor.predictions.METHOD``).

For the baseline and the final model, every ``maneuver_metrics`` row of a validation record gets
``<model>_low`` and ``<model>_high`` (the 90 % interval) and ``<model>_uncertainty`` (its parts);
the final model's rows get ``carriers`` (all but the lengths in metres, whose twins in ship lengths
have them), the record's ``extrapolation`` and the measured value's own interval
(``measured_low``, ``measured_high``, ``measured_noise``: the record's noise replayed,
``study.doctor.measurement_noise``), with which the prediction and the measurement are compared
(``measurement_noise.agrees``). The models the doctor cannot tell apart from one of
them are the other models it fitted whose training and (scored) validation errors are within ``tie``
of that model's or lower -- its candidates, ladder steps and their equation-error twins, minus the
physically implausible ones and those whose effect parameters sit on a bound of their search box
(``model_error.at_bounds``: not identified) -- plus, with validation records given, the model's
anchor halved and doubled and the anchor set itself when it fits the training records as well. With
each record held out in turn (no validation records) each record is predicted by its fold's fits,
and the extrapolation error is calibrated once on all training records (an approximation: the folds'
own calibrations would each leave one record out). ``predicted_turns`` adds what the final model
predicts for a standard 35 deg turning circle to either side from a steady approach at the service
speed, a manoeuvre nobody measured
(``study.doctor.predictions.predict_turn``). When the verdict is a tie, ``tie`` gives those turns as
each tied reading predicts them and their equal mixture: the records favour neither reading, so the
prediction is not conditioned on one.
"""
from __future__ import annotations

import math

import numpy as np

from . import measurement_noise as mn
from . import model_error as me
from . import prediction_interval as pi
from .predictions import METHOD, TURNS, carriers, extrapolation_text, metric_interval

#: posterior draws per model and record
DRAWS = 32
#: metrics an open-loop replay reproduces by construction (it reverses its rudder when the ship did): no prediction,
#: so no interval and no count
BY_CONSTRUCTION = {"period": "an open-loop replay reverses its rudder when the ship did: its period is the "
                             "record's by construction, not a prediction"}


def _mean_on(ev, records: list) -> float:
    """An evaluation's mean validation error over ``records`` (inf with none)."""
    return float(np.mean(ev.per_record(records))) if records else math.inf


def _label(effects) -> str:
    return "+".join(effects) if effects else "no effect"


def calibration(doctor, fit) -> dict:
    """``model_error.calibrate(doctor.problem, fit)``, computed once per fit."""
    cache = doctor.__dict__.setdefault("_calibrations", {})
    if id(fit) not in cache:
        cache[id(fit)] = (fit, me.calibrate(doctor.problem, fit))
    return cache[id(fit)][1]


def alternative_evaluations(doctor, ev, tie: float) -> tuple:
    """([(label, Evaluation)], [excluded sentences]): the doctor's other fits that the records
    cannot tell from ``ev`` (see the module docstring)."""
    scored = doctor.result["scored"]
    implausible = {r["effect"] for r in doctor.result["ranking"] if r.get("implausible")}
    own_v, own_t = _mean_on(ev, scored), ev.training_error
    out, excluded = [], []
    for (effects, _, refine), e in doctor.evaluations.items():
        if e is ev:
            continue
        label = _label(effects) + (" (refined on the replays)" if refine else "")
        v, t = _mean_on(e, scored), e.training_error
        bounds = me.at_bounds(doctor.problem, e.fit)
        if set(effects) & implausible:
            excluded.append(f"{label}: physically implausible here")
        elif bounds:
            excluded.append(f"{label}: {', '.join(bounds)} on a bound of its search box (not identified)")
        elif not (math.isfinite(v) and v <= (1.0 + tie) * own_v):
            excluded.append(f"{label}: validation error {v:.3g} against {own_v:.3g}")
        elif not (math.isfinite(t) and t <= (1.0 + tie) * own_t):
            excluded.append(f"{label}: training error {t:.3g} against {own_t:.3g}")
        else:
            out.append((label, e))
    return out, excluded


def setting_alternatives(doctor, fit, tie: float) -> tuple:
    """([(label, problem, fit)], notes): the anchor halved and doubled, and the anchor set when
    it fits the training records within ``tie`` (``study.doctor.model_error``); computed once per
    fit."""
    cache = doctor.__dict__.setdefault("_settings", {})
    if id(fit) not in cache:
        alts = me.anchor_variants(doctor.problem, fit)
        pub, why = me.published_set(doctor.problem, fit, tie)
        cache[id(fit)] = (fit, alts + ([pub] if pub else []), [why] if why else [])
    return cache[id(fit)][1], cache[id(fit)][2]


def _items(doctor, ev) -> list:
    """(index, record name, problem, fit, fold) per validation record (held out: its fold's)."""
    if doctor.mode == "given":
        return [(k, n, doctor.problem, ev.fit, None) for k, n in enumerate(doctor.val_names)]
    return [(k, n, doctor.folds[k], ev.fold_fits[k] if ev.fold_fits else None, k)
            for k, n in enumerate(doctor.train_names)]


def _reduced(doctor, problem, fit, name, fold):
    drop, _ = doctor.setup_left_out(fit, name, fold)
    return me.without_effects(problem, fit, drop) if drop else fit


def _record_values(doctor, name, df, frames) -> list:
    L, U0 = doctor.problem.L, doctor.problem.U0
    return [me.metric_values(name, df, f, L, U0) for f in frames]


def model_uncertainty(doctor, ev, rows: list, frames: dict, role: str, tie: float, level: float = 0.9,
                      sensitivity: bool = False) -> dict:
    """Fill ``<role>_low``, ``<role>_high`` and ``<role>_uncertainty`` of the
    ``maneuver_metrics`` rows of the model ``ev`` (``frames``: its replays, by record), and with
    ``sensitivity`` the rows' ``carriers``, the records' extrapolation and the measured values'
    own intervals (``study.doctor.measurement_noise``, replayed by this model). Returns the
    section's part for this model."""
    from study.records.maneuver_metrics import manoeuvre_start

    pb0 = doctor.problem
    L, U0 = pb0.L, pb0.U0
    cal = calibration(doctor, ev.fit)
    alts, excluded = alternative_evaluations(doctor, ev, tie)
    settings, notes = setting_alternatives(doctor, ev.fit, tie) if doctor.mode == "given" else ([], [
        "with each record held out in turn, the anchor's settings are not varied (each fold would need its own fits)"])
    meas = dict(zip(doctor.val_names, doctor.val_df)) if doctor.mode == "given" else \
        dict(zip(doctor.train_names, doctor.train_df))
    infos = doctor.val_infos if doctor.mode == "given" else pb0.infos
    by_record = {}
    for r in rows:
        by_record.setdefault(r["record"], []).append(r)
    records = {}
    for k, name, problem, fit, fold in _items(doctor, ev):
        if name not in by_record or fit is None:
            continue
        df, info = meas[name], infos[k]
        c = me.cut(df, manoeuvre_start(df))
        if c is None:
            continue
        small = _reduced(doctor, problem, fit, name, fold)
        post, sets = me.posterior_draws(problem, fit, DRAWS, seed=k)
        table = me.coefficient_table(problem, small, post) if (sensitivity and post is not None) else []
        sens = me.sensitivity_sets(post, table) if table else []
        vals = _record_values(doctor, name, df, me.replay_members(problem, small, c, info, sets + sens))
        usable = [(lab, e) for lab, e in alts if fold is None or e.fold_fits]
        labels = [lab for lab, _ in usable] + [lab for lab, _, _ in settings]
        alt_frames = [doctor.predict(problem, e.fit if fold is None else e.fold_fits[fold], c, info, fold)
                      for _, e in usable]
        alt_frames += [pb.predict(_reduced(doctor, pb, ft, name, fold), c, info) for _, pb, ft in settings]
        alt_vals = _record_values(doctor, name, df, alt_frames)
        if sensitivity:
            spread = _measurement_spread(doctor, problem, fit, name, df, info, fold, k)
            for row in by_record[name]:
                mn.measured_interval(row, spread, level)
        env_tr = cal["envelope"] if fold is None else pi.state_envelope(problem.records, L, U0)
        env_pr = pi.state_envelope(pi.running(frames[name], c), L, U0) if frames.get(name) is not None else {}
        dist = pi.envelope_distance(env_pr, env_tr) if env_pr else {"distance": math.nan, "excess": {},
                                                                    "state": None}
        for row in by_record[name]:
            m = row["metric"]
            if m in BY_CONSTRUCTION:
                row[f"{role}_uncertainty"] = {"why": BY_CONSTRUCTION[m]}
                continue
            iv = metric_interval(row[role], [v.get(m, math.nan) for v in vals[:len(sets)]],
                                 [v.get(m, math.nan) for v in alt_vals], dist["distance"], me.growth_for(cal, m),
                                 level)
            row[f"{role}_low"], row[f"{role}_high"] = iv["low"], iv["high"]
            row[f"{role}_uncertainty"] = {**{k2: v for k2, v in iv.items() if k2 not in ("low", "high")},
                                          "failed_alternatives": len(alt_frames) - iv["alternatives"],
                                          "alternative_values": dict(zip(labels, [v.get(m, math.nan)
                                                                                  for v in alt_vals]))}
            if table and row.get("unit") != "m":  # a length in metres: its twin in ship lengths carries them
                srows = me.sensitivities(table, row[role], [v.get(m, math.nan) for v in vals[len(sets):]])
                hw = row[role] * iv["half_width"] if np.isfinite(iv["half_width"]) else math.inf
                row["carriers"] = carriers(srows, frames.get(name), problem.records, L, U0, row.get("unit", ""), hw)
        if sensitivity:
            caveats = [r[f"{role}_uncertainty"]["caveat"] for r in by_record[name]
                       if r.get(f"{role}_uncertainty", {}).get("caveat")]
            records[name] = {**dist, "prediction": env_pr, "training": env_tr,
                             "text": extrapolation_text(dist, env_pr, env_tr) if env_pr else
                             "the replay diverged: no states to compare", "caveat": caveats[0] if caveats else None}
    return {"alternatives": [a[0] for a in alts] + [s[0] for s in settings], "excluded": excluded,
            "notes": notes + cal["notes"], "records": records, "calibration": calibration_summary(cal)}


def _measurement_spread(doctor, problem, fit, name: str, df, info, fold, seed: int) -> dict:
    """{metric: {'s_meas', 'probes'}} of a validation record: its noise's spread of the
    comparison with ``fit``'s replay (``measurement_noise.comparison_spread``); {} for a record
    without noise."""
    from study.records.maneuver_metrics import manoeuvre_start

    sd = mn.record_noise(df)
    if not sd:
        return {}
    L, U0 = doctor.problem.L, doctor.problem.U0
    t0 = manoeuvre_start(df)

    def replayed(x):
        c = me.cut(x, t0)
        f = doctor.predict(problem, fit, c, info, fold) if c is not None else None
        return me.metric_values(name, x, f, L, U0)

    return mn.comparison_spread(mn.noisy_copies(df, sd, seed=seed),
                                lambda x: me.metric_values(name, x, x, L, U0), replayed)


def calibration_summary(cal: dict) -> dict:
    """The calibration as the report shows it: the splits, the held-out pairs (record, distance, the
    metrics' errors and the held-out predictions' own identification spreads, taken out of them) and
    the surrogate's
    growth."""
    return {"splits": cal["splits"], "growth": me.growth_for(cal, me.SURROGATE),
            "pairs": [{"record": p["record"], "split": p["split"], "distance": p["distance"],
                       "state": p["state"], "diverged": p.get("diverged", False),
                       "errors": p["errors"], "own_sd": p.get("own_sd", {})} for p in cal["pairs"]]}


def predicted_turns(doctor, ev, tie: float, level: float = 0.9) -> list:
    """The final model's 35 deg turns to either side (``TURNS``), each with its metrics'
    intervals and carriers and its extrapolation; the models the doctor cannot tell apart from it
    turn as they are."""
    from .predictions import predict_turn

    alts = [(label, doctor.problem, e.fit) for label, e in alternative_evaluations(doctor, ev, tie)[0]]
    settings, _ = setting_alternatives(doctor, ev.fit, tie)
    cal = calibration(doctor, ev.fit)
    out = []
    for title, man in TURNS:
        try:
            got = predict_turn(doctor.problem, ev.fit, draws=2 * DRAWS, maneuver=man, level=level,
                               keep_setup_effects=doctor.opt.keep_setup_effects, alternatives=alts + settings,
                               tie=tie, cal=cal)
        except ValueError as e:  # a kind without a propeller to solve for, ...
            out.append({"maneuver": title, "why": str(e)})
            continue
        ex = got["extrapolation"]
        out.append({"maneuver": title, "n": got["n"], "u0": got["u0"], "setup_left_out": got["setup_left_out"],
                    "metrics": got["metrics"], "alternatives": got["alternatives"], "notes": got["notes"],
                    "extrapolation": {k: ex[k] for k in ("distance", "state", "excess", "prediction", "training",
                                                         "text")}})
    return out


def tie_turns(doctor, tie: float, level: float = 0.9) -> dict | None:
    """When the verdict is a tie, the 35 deg turns as each tied reading predicts them (its
    equation-error fit, through :func:`predicted_turns`) and their equal mixture
    (``prediction_interval.tie_mixture``): the records favour neither reading, so the turn is not
    conditioned on one. None without a tie. Returns ``{'readings', 'turns': [{'maneuver',
    'metrics': {metric: {'value', 'low', 'high', 'half_width', 'readings': {effect: {'value',
    'low', 'high'}}}}, 'setup_left_out'}]}`` (a turn no reading could predict: ``{'maneuver', 'why'}``)."""
    evs = doctor.result.get("tie_evaluations") or {}
    if len(evs) < 2:
        return None
    each = {effect: predicted_turns(doctor, ev, tie, level) for effect, ev in evs.items()}
    turns = []
    for k, (title, _) in enumerate(TURNS):
        got = {effect: sides[k] for effect, sides in each.items()}
        why = next((g["why"] for g in got.values() if "metrics" not in g), None)
        if why is not None:  # a kind without a propeller to solve for, ...: as predicted_turns says it
            turns.append({"maneuver": title, "why": why})
            continue
        metrics = {}
        for m in got[next(iter(got))]["metrics"]:
            readings = {e: {x: g["metrics"][m][x] for x in ("value", "low", "high")} for e, g in got.items()}
            mix = pi.tie_mixture([(r["value"], r["low"], r["high"]) for r in readings.values()], level)
            metrics[m] = {**{x: mix[x] for x in ("value", "low", "high", "half_width")}, "readings": readings}
        turns.append({"maneuver": title, "metrics": metrics,
                      "setup_left_out": sorted({e for g in got.values() for e in g["setup_left_out"]})})
    return {"readings": list(evs), "turns": turns}


def tie_records(doctor, mm: list, meas: dict, frames_of, tie: float, level: float = 0.9) -> dict | None:
    """When the verdict is a tie, every validation metric as each tied reading predicts it (its
    replays ``frames_of(evaluation)``, its own interval from :func:`model_uncertainty`) and their
    equal mixture (``prediction_interval.tie_mixture``), as :func:`tie_turns` does for the turns:
    the final model is then the baseline, which both readings beat, and the records favour
    neither. Sets ``tie``, ``tie_low``, ``tie_high`` and ``tie_readings`` ({effect: {value, low,
    high}}) of the ``mm`` rows; returns ``{'readings', 'rows'}`` (how many rows got a mixture), or
    None without a tie."""
    from study.records.maneuver_metrics import maneuver_metrics

    evs = doctor.result.get("tie_evaluations") or {}
    if len(evs) < 2:
        return None
    L = doctor.problem.L
    each = {}  # effect -> {(record, metric): that reading's row}
    for effect, ev in evs.items():
        frames = frames_of(ev)
        rows = [r for name, df in meas.items() for r in maneuver_metrics(name, df, None, frames.get(name), L)]
        model_uncertainty(doctor, ev, rows, frames, "final", tie, level)
        each[effect] = {(r["record"], r["metric"]): r for r in rows}
    n = 0
    for row in mm:
        key = (row["record"], row["metric"])
        got = {e: by_key[key] for e, by_key in each.items() if key in by_key}
        if len(got) < len(each) or row["metric"] in BY_CONSTRUCTION:
            continue
        readings = {e: {"value": r["final"], "low": r.get("final_low", math.nan), "high": r.get("final_high", math.nan)}
                    for e, r in got.items()}
        mix = pi.tie_mixture([(x["value"], x["low"], x["high"]) for x in readings.values()], level)
        if not np.isfinite(mix["low"]):
            continue
        row.update(tie=mix["value"], tie_low=mix["low"], tie_high=mix["high"], tie_readings=readings)
        n += 1
    return {"readings": list(evs), "rows": n}


def annotate(doctor, mm: list, base, final, mb: dict, mf: dict, level: float = 0.9, meas: dict | None = None,
             frames_of=None) -> dict:
    """Fill the intervals of the ``maneuver_metrics`` rows ``mm`` (baseline and final; the
    final's carriers and extrapolation; under a tie, with ``meas`` (the validation records by
    name) and ``frames_of`` (an evaluation's replays of them), the tied readings' mixture) and
    return the report's ``prediction_uncertainty`` section."""
    tie = doctor.opt.tie
    sec = {"level": level, "method": METHOD, "errors": []}
    parts = (("final", lambda: model_uncertainty(doctor, final, mm, mf, "final", tie, level, sensitivity=True)),
             ("baseline", lambda: model_uncertainty(doctor, base, mm, mb, "baseline", tie, level)),
             ("predicted_turns", lambda: predicted_turns(doctor, final, tie, level)),
             ("tie", lambda: tie_turns(doctor, tie, level)),
             ("tie_records", lambda: tie_records(doctor, mm, meas, frames_of, tie, level) if frames_of else None))
    for key, part in parts:
        try:
            sec[key] = part()
        except Exception as e:  # noqa: BLE001 -- a part that fails is reported, the report is still written
            sec[key] = [] if key == "predicted_turns" else None if key in ("tie", "tie_records") else {
                "records": {}, "alternatives": [], "excluded": [], "notes": [], "calibration": {}}
            sec["errors"].append(f"{key}: could not be computed ({type(e).__name__}: {e})")
    sec["training_envelope"] = pi.state_envelope(doctor.problem.records, doctor.problem.L, doctor.problem.U0)
    sec["summary"] = summary(mm, sec) + sec["errors"]
    return sec


def summary(mm: list, sec: dict) -> list:
    """Plain sentences: which predictions extrapolate (how far, in which states) and which
    coefficients carry them; how often the intervals hold the measured value."""
    out = []
    names = {"v'": "|v'|", "r'": "|r'|", "drift_deg": "drift", "rudder_deg": "rudder"}
    far = {n: r for n, r in sec["final"]["records"].items() if r.get("text", "").startswith("EXTRAPOLATES")}
    if far:
        items = [f"{n} ({r['distance']:.2g}; {names.get(r['state'], r['state'])} "
                 f"+{100 * r['excess'][r['state']]:.0f} %)" for n, r in far.items()]
        out.append(f"{len(far)} of {len(sec['final']['records'])} validation replays of the final model "
                   f"EXTRAPOLATE beyond the training records (distance outside their envelope; the state that sets "
                   f"it): {', '.join(items)}")
        caveats = [r["caveat"] for r in far.values() if r.get("caveat")]
        if caveats:
            g = sec["final"]["calibration"].get("growth", {})
            out.append(f"{len(caveats)} of them lie farther out than the calibration reached (its farthest held-out "
                       f"record: {g.get('d_max', math.nan):.2g}): their intervals assume the error grows no faster "
                       "beyond it")
    for t in sec.get("predicted_turns", []):
        if "metrics" not in t:
            continue
        td = t["metrics"].get("tactical_diameter_L", {})
        cs = td.get("carriers", [])
        share = [c["coefficient"] for c in cs if np.isfinite(c.get("share") or np.nan) and c["share"] >= 0.05]
        reset = [f"{c['coefficient']} ({c['reset']:+.2g} L)" for c in cs if c["coefficient"] not in share]
        out.append(f"{t['maneuver']}: tactical diameter {td.get('value', math.nan):.3g} L "
                   f"(90 %: {td.get('low', math.nan):.3g}-{td.get('high', math.nan):.3g} L); "
                   f"{t['extrapolation']['text']}" + (f" ({td['caveat']})" if td.get("caveat") else "")
                   + (f"; carried by {', '.join(share)} (its variance)" if share else "")
                   + (f"; reset to their anchor values {', '.join(reset)} move it beyond its interval" if reset
                      else ""))
    for t in (sec.get("tie") or {}).get("turns", []):
        if "metrics" not in t:
            continue
        td = t["metrics"]["tactical_diameter_L"]
        each = "; ".join(f"{e} {x['value']:.3g} L ({x['low']:.3g}-{x['high']:.3g})" for e, x in td["readings"].items())
        out.append(f"the verdict is a tie, so the {t['maneuver']} is predicted by both readings: {each}; weighted "
                   f"equally, tactical diameter {td['value']:.3g} L (90 %: {td['low']:.3g}-{td['high']:.3g} L)")
    held = [r for r in mm if np.isfinite(r.get("measured", np.nan)) and np.isfinite(r.get("final_low", np.nan))]
    if held:
        k = sum(r["final_low"] <= r["measured"] <= r["final_high"] for r in held)
        noisy = [r for r in held if "measured_noise" in r]
        text = (f"the final model's 90 % intervals hold the measured value for {k} of {len(held)} validation "
                "metrics")
        if noisy:
            k2 = sum(bool(mn.agrees(r)) for r in held)
            text += (f"; with the measured values' own noise (each record's, added again {mn.PROBES} times) the "
                     f"prediction and the measurement agree on {k2} of {len(held)}")
        out.append(text)
    tied = [r for r in mm if np.isfinite(r.get("measured", np.nan)) and np.isfinite(r.get("tie_low", np.nan))]
    if tied:
        k = sum(r["tie_low"] <= r["measured"] <= r["tie_high"] for r in tied)
        k0 = sum(r.get("final_low", np.inf) <= r["measured"] <= r.get("final_high", -np.inf) for r in tied)
        out.append(f"the verdict is a tie, so each validation metric is also predicted by both readings, weighted "
                   f"equally: their mixture's 90 % intervals hold the measured value for {k} of {len(tied)} (the "
                   f"final model, the baseline, for {k0})")
    return out
