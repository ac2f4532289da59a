"""The report page's view data: the dict of ``report.json`` turned once into plain lists and dicts of strings and
numbers, in the order and with the words the page shows them; the templates of ``templates/`` lay them out and
:mod:`.html` renders them.

:func:`view` normalises the report at the entry (:func:`.html_format.normalise`); each section's function returns
its data, or None when the report has nothing for it: the page and its table of contents then leave it out.
"""
from __future__ import annotations

import base64
import math
import re
from collections.abc import Mapping
from typing import Any

from .html_format import (DIVERGED, MODES, NA, REJECTED_DEF, SECTIONS, STABILITY_DEF, TITLES, as_float, as_text,
                          base_diverged, definition, divergences, err, final_diverged, finite, fmt_p, fmt_pct,
                          footnote, interval, known, metric_num, named_in, names, no_final_model, normalise, num,
                          param_items, param_value, pct, records_of, stability_by_step, step_diverged, unit,
                          unit_notes, verdict_diverged)


def _section(sid: str, **body) -> dict:
    return {"id": sid, "title": TITLES[sid], **body}


# --------------------------------------------------------------------------------------------- the top


def summary(r: dict) -> list:
    rows = [(label, r[k]) for k, label in (("vessel", "Vessel"), ("model", "Model"), ("structure", "Structure"))
            if r.get(k)]
    if r.get("mode"):
        rows.append(("Validation", MODES.get(r["mode"], r["mode"])))
    return [{"label": a, "value": b} for a, b in rows]


def _with_units(text: str, units: Mapping) -> list:
    """``text`` in pieces, a piece ending at each ``name = number`` of a parameter with a unit (``unit``)."""
    pieces, at = [], 0
    for m in re.finditer(r"\b([A-Za-z_][A-Za-z0-9_]*) = (-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)", text):
        u = unit(m.group(1), units)
        if u:
            pieces.append({"text": text[at:m.end()], "unit": u})
            at = m.end()
    return pieces + [{"text": text[at:], "unit": None}]


def verdict(r: dict) -> dict:
    """The verdict box: its kind (``diverged``, ``found``, ``ambiguous``, ``none`` or ``unknown``), what its
    headline names, the report's verdict sentence (with units) and what follows it."""
    missing = r.get("missing_effect") if (r.get("missing_effect") or "").strip() else None
    ambiguous = r.get("ambiguous", [])
    ranking = r.get("ranking", [])
    stab = stability_by_step(r).get(1)
    v: dict = {"named": named_in(stab, long=True), "role": "status", "others": [], "defs": []}
    text = r.get("verdict") or ""
    show_text = True
    if verdict_diverged(r):
        recs = base_diverged(r)
        n_val = len(r.get("baseline", {}).get("errors") or {}) or len(r.get("validate", []))
        v.update(kind="diverged", cls="verdict diverged", role="alert", on=known(recs),
                 of=f" {len(recs)} of {n_val}" if recs and n_val >= len(recs) and recs != ["?"] else "")
        if text.strip().lower().startswith("diverged"):
            v["rest"] = re.sub(r"^\s*diverged\s*:?\s*", "", text, flags=re.I)
            show_text = False
        v["others"] = [d for d in divergences(r) if d["what"] != "the baseline model"]
        v["defs"] = [definition(r, "diverged")]
    elif missing is not None:
        cand = next((c for c in ranking if str(c.get("effect")) == missing), None)
        bits = []
        if cand is not None:
            if finite(cand.get("improvement")) is not None and cand.get("diverged") is not True:
                bits.append(f"validation error down by {fmt_pct(cand.get('improvement'))}")
            p = as_float(cand.get("p_value"))
            if p is not None and not math.isnan(p):
                bits.append(f"p {fmt_p(p)}" if p < 1e-3 else f"p = {fmt_p(p)}")
        v.update(kind="found", cls="verdict found", missing=missing, bits=bits,
                 inseparable=[a for a in ambiguous if a != missing])
    elif ambiguous:
        v.update(kind="ambiguous", cls="verdict ambiguous", ambiguous=ambiguous)
    elif "missing_effect" in r or ranking:
        same = named_in(stab)
        v.update(kind="none", cls="verdict none", same=same.replace("named in ", ""))
    else:
        v.update(kind="unknown", cls="verdict unknown")
    v["text"] = _with_units(text, r.get("units", {})) if text and show_text else None
    if v["kind"] != "diverged" and "validation error" in text:
        v["defs"] = [definition(r, "validation error")]
    v["defs"] = [d for d in v["defs"] if d]
    return v


def divergence(r: dict) -> dict | None:
    """The warning box listing every diverged replay (when the verdict is not already the divergence)."""
    items = [] if verdict_diverged(r) else divergences(r)
    return {"entries": items, "defs": [d for d in [definition(r, "diverged")] if d]} if items else None


# --------------------------------------------------------------------------------------------- the tables


def _baseline_val(r: dict) -> float | None:
    if base_diverged(r):
        return None
    b = finite(r.get("baseline", {}).get("validation_error"))
    if b:
        return b
    steps = r.get("ladder", [])
    v = finite(steps[0].get("validation_error")) if steps else None
    return v or None


def ladder(r: dict) -> dict | None:
    steps = r.get("ladder", [])
    if not steps:
        return None
    base, base_div, stab = _baseline_val(r), bool(base_diverged(r)), stability_by_step(r)
    rows, any_div, any_rej, any_stab = [], False, False, False
    for i, s in enumerate(steps):
        div, rejected = step_diverged(s, i, r), s.get("rejected") is True
        any_div |= div
        any_rej |= rejected
        v = finite(s.get("validation_error"))
        if div:
            fall = {"kind": "diverged"}
        elif base is not None and v is not None:
            f = (base - v) / base
            fall = {"kind": "bar", "width": f"{max(0.0, min(1.0, f)) * 100.0:.1f}", "text": fmt_pct(f)}
        else:
            fall = {"kind": "na_base" if base_div else "na"}
        named = named_in(stab.get(i) if i > 0 and not rejected else None)
        any_stab |= bool(named)
        if rejected:
            status = {"kind": "rejected", "why": as_text(s.get("reason"))}
        elif div:
            status = {"kind": "diverged", "on": ", ".join(known(records_of(s.get("diverged")))) or "a record"}
        else:
            status = {"kind": "given" if i == 0 else "accepted"}
        rows.append({"cls": " ".join(c for c in ("rejected" if rejected else "", "diverged-row" if div else "") if c),
                     "step": as_text(s.get("step")), "effects": names(s.get("effects")),
                     "validation": err(s.get("validation_error"), div), "training": err(s.get("training_error")),
                     "fall": fall, "named": named, "status": status})
    extra = [("fall of validation error vs baseline", "(baseline - step) / baseline of the validation error")]
    extra += ([("stability (named in k of n)", STABILITY_DEF)] if any_stab else []) + \
        ([("rejected", REJECTED_DEF)] if any_rej else [])
    defs = footnote(r, ["validation error", "training error"] + (["diverged"] if any_div else []), extra)
    return _section("ladder", rows=rows, defs=defs)


def ranking(r: dict) -> dict | None:
    cands, b, units, missing = r.get("ranking", []), r.get("baseline", {}), r.get("units", {}), r.get("missing_effect")
    rows, any_div, notes = [], False, {}
    for c in cands:
        div_recs = records_of(c.get("diverged_records"))
        v = as_float(c.get("validation_error"))
        div = c.get("diverged") is True or bool(div_recs) or (v is not None and math.isinf(v))
        any_div |= div
        sig = not div and (c.get("significant") is True or (
            not isinstance(c.get("significant"), (str, type(None))) and bool(c.get("significant"))))
        cls = "candidate significant" if sig else "candidate"
        cls += " diverged-row" if div else ""
        cls += " chosen" if missing is not None and str(c.get("effect")) == str(missing) else ""
        mt = c.get("metrics") or {}
        e0, e1 = finite(mt.get("baseline_error")), finite(mt.get("error"))
        rows.append({"cls": cls, "effect": as_text(c.get("effect")), "validation": err(c.get("validation_error"), div),
                     "on": known(div_recs) if div else [], "improvement": pct(c.get("improvement"), div),
                     "metrics": [fmt_pct(e1), fmt_pct(e0)] if e0 is not None and e1 is not None else None,
                     "significant": sig, "p": fmt_p(c.get("p_value")),
                     "params": param_items(c.get("parameters"), units, notes), "note": as_text(c.get("note"))})
    na = [{"effect": k, "why": as_text(x)} for k, x in r.get("not_applicable", {}).items()]
    if not rows and not b:
        return _section("candidates", baseline=None, rows=[], na=na, tried=False) if na else None
    base = None
    if b:
        bdiv = base_diverged(r)
        base = {"diverged": bool(bdiv), "validation": err(b.get("validation_error")), "on": known(bdiv),
                "training": err(b.get("training_error"))}
    extra = [("p-value", "of the paired t-test of the per-record validation errors against the baseline's "
                         "(n/a when there are too few validation records to run it)"),
             ("manoeuvre metrics error", "the mean over the validation turning circles' and zigzags' metrics "
                                         "(tactical diameter, advance, transfer, overshoots...) of |predicted - "
                                         "measured| / |measured|, with the candidate (and, below, the baseline); "
                                         "n/a without such records")]
    return _section("candidates", baseline=base, rows=rows, na=na, tried=bool(rows), unit_notes=unit_notes(notes),
                    defs=footnote(r, ["validation error", "improvement"] + (["diverged"] if any_div else []), extra))


def errors(r: dict) -> dict | None:
    rows, any_div, channels = [], False, set()
    bdiv, fdiv = set(base_diverged(r)), set(final_diverged(r))
    inf = lambda e, keys: any((v := as_float(e.get(k))) is not None and math.isinf(v) for k in keys)  # noqa: E731
    for e in r.get("errors_table", []):
        rec = str(e.get("record"))
        db = e.get("baseline_diverged") is True or rec in bdiv or inf(e, ("baseline_rmse", "baseline_nrmse"))
        df = e.get("final_diverged") is True or rec in fdiv or inf(e, ("final_rmse", "final_nrmse"))
        any_div |= db or df
        channels.add(str(e.get("channel")))
        b, f = finite(e.get("baseline_nrmse")), finite(e.get("final_nrmse"))
        if db or df:
            change = DIVERGED
        elif b is not None and f is not None and b != 0.0:
            change = fmt_pct((f - b) / b)
            change = change if change.startswith("-") else "+" + change
        else:
            change = NA
        cells = [err(e.get("baseline_rmse"), db), err(e.get("final_rmse"), df), err(e.get("baseline_nrmse"), db),
                 err(e.get("final_nrmse"), df)]
        rows.append({"record": as_text(e.get("record")), "channel": as_text(e.get("channel")),
                     "unit": as_text(e.get("unit")), "cells": cells, "change": change})
    if not rows:
        return None
    extra = [("RMSE", "root-mean-square error of the replayed channel, in the channel's unit"),
             ("NRMSE change", "(final - baseline) / baseline of the NRMSE; negative is better")]
    terms = ["NRMSE"] + (["track error"] if "track" in channels else []) + (["diverged"] if any_div else [])
    return _section("errors", rows=rows, defs=footnote(r, terms, extra))


def metric_rows(rows: list, bdiv: set = frozenset(), fdiv: set = frozenset()) -> list:
    """The manoeuvre metrics' rows (``study.maneuver_metrics.maneuver_metrics``): record, metric with its
    definition, unit, and measured, baseline and final (each with its 90 % interval when it has one); a replay
    that diverged has no metric, and says so."""
    from ..maneuver_metrics import COLUMNS, TURNING_METRICS, ZIGZAG_METRICS

    units = {m: u for m, u, _ in TURNING_METRICS + ZIGZAG_METRICS}
    descriptions = {m: d for m, _, d in TURNING_METRICS + ZIGZAG_METRICS}
    out = []
    for x in rows:
        m, rec = x.get("metric"), str(x.get("record"))
        cells = []
        for c in COLUMNS:
            dv = (c == "baseline" and rec in bdiv) or (c == "final" and rec in fdiv)
            cells.append({"value": DIVERGED, "interval": None} if dv and finite(x.get(c)) is None else
                         {"value": metric_num(x.get(c)), "interval": interval(x.get(f"{c}_low"), x.get(f"{c}_high"))})
        out.append({"record": as_text(x.get("record")), "metric": as_text(m), "tip": descriptions.get(str(m)),
                    "unit": as_text(x.get("unit", units.get(str(m), ""))), "cells": cells})
    return out


def maneuvers(r: dict) -> dict | None:
    if "maneuver_metrics" not in r:
        return None
    from ..maneuver_metrics import TURNING_METRICS, ZIGZAG_METRICS

    rows = [x for x in r["maneuver_metrics"] if x.get("metric") is not None]
    bdiv, fdiv = set(base_diverged(r)), set(final_diverged(r))
    shown = {str(x.get("metric")) for x in rows}
    fin, base = r.get("final", {}).get("effects"), r.get("baseline", {}).get("effects")
    same = isinstance(fin, list) and isinstance(base, list) and sorted(map(str, fin)) == sorted(map(str, base))
    return _section("maneuvers", rows=metric_rows(rows, bdiv, fdiv), same=same,
                    metrics=[{"metric": m, "unit": u, "text": d} for m, u, d in TURNING_METRICS + ZIGZAG_METRICS
                             if m in shown], defs=footnote(r, ["diverged"] if (bdiv or fdiv) else []))


def identifiability(r: dict) -> dict | None:
    """Per anchored coefficient of the baseline fit: prior, estimate, prior and posterior sd, their ratio and the
    doctor's sentence; the coefficients the records do not determine, and prior-data conflicts, marked."""
    rows, n_not, n_conf = [], 0, 0
    for it in r.get("identifiability", []):
        ratio, moved = as_float(it.get("ratio")), as_float(it.get("moved_prior_sd"))
        undetermined, conflict = ratio is not None and ratio >= 0.9, moved is not None and abs(moved) > 2.0
        n_not += undetermined
        n_conf += conflict
        rows.append({"marked": undetermined or conflict, "coefficient": as_text(it.get("coefficient")),
                     "cells": [num(it.get("prior")), num(it.get("estimate")), num(it.get("prior_sd"), 3),
                               num(it.get("posterior_sd"), 3), num(ratio, 2), num(moved, 2)],
                     "sentence": as_text(it.get("sentence"))})
    if not rows:
        return None
    defs = footnote(r, [], [("ratio", "posterior sd / prior sd: near 0 the records determine the coefficient, near 1 "
                                   "the prior does"), ("moved", "(estimate - prior) / prior sd")])
    return _section("identifiability", rows=rows, undetermined=n_not, conflicts=n_conf, defs=defs)


# --------------------------------------------------------------------------------------------- the figures


def _mime(data: bytes) -> str:
    if data.startswith(b"\xff\xd8\xff"):
        return "image/jpeg"
    if data.startswith((b"GIF87a", b"GIF89a")):
        return "image/gif"
    head = data[:256].lstrip()
    if head.startswith(b"<svg") or (head.startswith(b"<?xml") and b"<svg" in data[:2048]):
        return "image/svg+xml"
    return "image/png"


def _caption(meta: Mapping, r: dict) -> Any:
    """The figure's caption, less what the figure cannot show in this report."""
    cap = meta.get("caption")
    if not isinstance(cap, str):
        return cap
    sec = str(meta.get("section") or "")
    if sec == "compare" and no_final_model(r):
        cap = re.sub(r"Measured \(dots\), the baseline model \(red\) and the model with the effects found \(blue\)",
                     "Measured (dots) and the baseline model (red)", cap)
        cap = re.sub(r",? *(and )?the model with the effects found \(blue\)", "", cap)
    if sec == "ladder" and ("hatched" in cap or "marked" in cap):
        steps = r.get("ladder", [])
        rej = any(s.get("rejected") is True for s in steps)
        div = any(step_diverged(s, i, r) for i, s in enumerate(steps))
        head = cap.split(";")[0].rstrip(". ")
        if len(steps) <= 1:
            head = re.sub(r" and of each step with an effect added$", " (no effect was added)", head)
        bits = (["a rejected step (its error not lower) is hatched"] if rej else []) + \
               (["a diverged step is marked DIVERGED, with no bar"] if div else [])
        cap = head + ("; " + "; ".join(bits) if bits else "") + "."
    return cap


def _figure(meta: Mapping, data: Any, r: dict) -> dict:
    file, title, caption = meta.get("file"), meta.get("title"), _caption(meta, r)
    src = None
    if isinstance(data, (bytes, bytearray, memoryview)) and len(data) > 0:
        data = bytes(data)
        src = f"data:{_mime(data)};base64,{base64.b64encode(data).decode('ascii')}"
    return {"file": as_text(file), "title": as_text(title), "caption": as_text(caption), "src": src,
            "alt": next((str(x) for x in (title, caption) if x not in (None, "")), f"Figure {file}")}


def figures(r: dict, figs: Mapping) -> dict | None:
    metas = list(r.get("figures", []))
    listed = {str(m.get("file")) for m in metas}
    # figures handed over but not listed in the report still belong in it (after the listed ones)
    metas += [{"file": k, "title": "", "caption": "", "section": "other"} for k in sorted(figs) if k not in listed]
    if not metas:
        return None
    order, groups = list(SECTIONS), {}
    for m in metas:
        sec = str(m.get("section") or "other")
        order += [] if sec in order else [sec]
        groups.setdefault(sec, []).append(m)
    return _section("figures", groups=[
        {"section": sec, "heading": SECTIONS.get(sec, "Other figures" if sec == "other" else
                                                  sec.replace("_", " ").capitalize()),
         "figures": [_figure(m, figs.get(str(m.get("file"))), r) for m in groups[sec]]}
        for sec in order if sec in groups])


# --------------------------------------------------------------------------------------------- the rest


def worst(r: dict) -> dict | None:
    time = lambda t: NA if finite(t) is None else f"{finite(t):.1f}"  # noqa: E731
    rows = [{"record": as_text(w.get("record")), "start": time(w.get("t_start")), "end": time(w.get("t_end")),
             "error": err(w.get("nrmse"))} for w in r.get("worst_windows", [])]
    if not rows:
        return None
    return _section("worst", rows=rows, defs=footnote(r, [], [(
        "mean error", "the mean over the window of |predicted - measured| / spread of the measured channel, averaged "
                      "over u, v, r and psi (the error-growth figure's curve)")]))


_PARAM_ITEM = re.compile(r"\s*([^,\[\]]+?)\s*\[([^\[\]]*)\]\s*(?:,|$)")


def _catalogue_params(params: Any, units: Mapping, notes: dict) -> dict:
    """A catalogue row's parameters: values (``name = value [unit]``), names with their units, or a text."""
    if isinstance(params, Mapping):
        return {"kind": "values", "entries": param_items(params, units, notes)}
    if isinstance(params, (list, tuple)):
        return {"kind": "names", "entries": [{"name": str(p), "unit": unit(p, units, notes) if unit(p, units) else None}
                                           for p in params if p is not None]}
    items = _PARAM_ITEM.findall(params) if isinstance(params, str) else []
    if not items or "".join(_PARAM_ITEM.sub("", params).split()):
        return {"kind": "text", "text": as_text(params)}
    return {"kind": "names", "entries": [{"name": n, "unit": unit(n, {n: u}, notes)} for n, u in items]}


def catalogue(r: dict) -> dict | None:
    rows, notes, units = [], {}, r.get("units", {})
    has_applies = any("applies" in c for c in r.get("catalogue", []))
    for c in r.get("catalogue", []):
        a = c.get("applies")
        applies = None if not has_applies else (
            {"kind": "yes"} if a is True or (isinstance(a, str) and a.strip().lower() == "yes") else
            {"kind": "na"} if a in (None, "") else {"kind": "no"} if a is False else {"kind": "why", "why": str(a)})
        rows.append({"name": as_text(c.get("name")), "physics": as_text(c.get("physics")),
                     "params": _catalogue_params(c.get("parameters"), units, notes), "enters": as_text(c.get("enters")),
                     "source": as_text(c.get("source")), "applies": applies})
    if not rows:
        return None
    return _section("catalogue", rows=rows, has_applies=has_applies, unit_notes=unit_notes(notes))


def separating(r: dict) -> dict | None:
    """The manoeuvres that would best tell the two leading candidates apart, best first (the top eight), and the
    records in hand scored the same way."""
    sep = r.get("separating_maneuver") or {}
    menu = [m for m in sep.get("menu") or [] if isinstance(m, Mapping)]
    if not menu:
        return None
    row = lambda m, what: {"what": what, "S": num(finite(m.get("S")), 2), "channel": as_text(m.get("channel")),  # noqa: E731
                           "max": num(finite(m.get("max")), 2), "diverged": as_text(m.get("diverged"))}
    rows = [row(m, f"{as_text(m.get('maneuver'))} to {as_text(m.get('side'))}, "
                   f"{100 * (finite(m.get('speed_U0')) or 0):.0f} % of the service speed") for m in menu[:8]]
    recorded = [row(m, as_text(m.get("record"))) for m in sep.get("recorded") or [] if isinstance(m, Mapping)]
    return _section("separating", pair=names(sep.get("pair") or []), text=as_text(sep.get("text")), rows=rows,
                    recorded=recorded, scale=[f"{c}: {num(finite(v), 3)}" for c, v in (sep.get("scale") or {}).items()])


def rudder_residual(r: dict) -> dict | None:
    """Mean residual N' and Y' (x 1e4) of the training rows per rudder-angle bin, baseline and final model."""
    rr = r.get("rudder_residual") or {}
    fits = [(label, rr[k]) for k, label in (("baseline", "baseline"), ("final", "final model"))
            if isinstance(rr.get(k), Mapping) and rr[k].get("bins")]
    if not fits:
        return None
    scaled = lambda x: num(None if finite(x) is None else 1e4 * finite(x), 3)  # noqa: E731
    bins = fits[0][1]["bins"]
    rows = [{"bin": f"{num(b.get('delta_from_deg'), 3)} to {num(b.get('delta_to_deg'), 3)}",
             "cells": [c for _, f in fits for c in (scaled(f["bins"][i].get("N_mean")),
                                                    scaled(f["bins"][i].get("Y_mean")))],
             "rows": as_text(b.get("rows"))} for i, b in enumerate(bins)]
    return _section("rudder_residual", models=[label for label, _ in fits], rows=rows,
                    spread=[scaled(f.get("N_spread")) for _, f in fits], rms=[scaled(f.get("N_rms")) for _, f in fits])


def notes(r: dict) -> dict | None:
    return _section("notes", entries=r["notes"]) if r.get("notes") else None


def _param_table(r: dict) -> dict | None:
    """Baseline and final parameters side by side, each with its unit."""
    b, f = (r.get(k, {}).get("parameters") or {} for k in ("baseline", "final"))
    if not b and not f:
        return None
    units = r.get("units", {})
    bk, fk = {str(k): v for k, v in b.items()}, {str(k): v for k, v in f.items()}
    cell = lambda d, n: param_value(d[n]) if n in d else None  # noqa: E731 -- None: the model has no such parameter
    rows = [{"name": n, "cells": [cell(bk, n)] + ([cell(fk, n)] if f else []),
             "unit": None if units.get(n) in (None, "") else str(units[n])} for n in dict.fromkeys([*bk, *fk])]
    return {"final": bool(f), "rows": rows, "conventions": (r.get("conventions") or "").strip()}


def data(r: dict) -> dict | None:
    rows = [{"label": label, "text": r[k]} for k, label in (("vessel", "Vessel"), ("model", "Model"),
                                                             ("structure", "Sample structure")) if r.get(k)]
    if r.get("mode"):
        rows.append({"label": "Validation", "text": MODES.get(r["mode"], r["mode"])})
    rows += [{"label": label, "list": r[k]} for k, label in (("train", "Trained on"), ("validate", "Validated on"))
             if r.get(k)]
    if r.get("depths_h_T"):
        rows.append({"label": "Water depth (h/T, depth over draft)", "list": [
            f"{k}: h/T = {num(v, 3)}" if finite(v) is not None else f"{k}: not given (deep water)"
            for k, v in r["depths_h_T"].items()]})
    fin = r.get("final", {}).get("effects")
    if isinstance(fin, list):
        rows.append({"label": "Final model adds", "effects": names(fin)})
    table = _param_table(r)
    if table:
        rows.append({"label": "Parameters", "params": table})
    return _section("data", rows=rows) if rows else None


def definitions(r: dict) -> dict | None:
    d = [{"term": k, "text": v} for k, v in r.get("definitions", {}).items() if isinstance(v, str) and v.strip()]
    return _section("definitions", entries=d) if d else None


def provenance(r: dict) -> dict | None:
    p = r.get("provenance", {})
    if not p:
        return None
    s = lambda k: as_text(p.get(k)).strip()  # noqa: E731
    rev = s("revision") + (" (with local changes to tracked files)" if s("revision") and p.get("modified") is True
                           else "")
    rows = [{"label": label, "text": val, "code": code} for label, val, code in (
        ("Package", f"{s('package')} {s('version')}".strip(), False),
        ("Git revision", rev or "not a git checkout", True), ("Command line", s("command"), True),
        ("Date (UTC)", s("date"), False)) if val]
    recs = [{k: as_text(x.get(k)) for k in ("role", "name", "sha256", "sha256_of")} for x in p.get("records", [])]
    return _section("provenance", rows=rows, records=recs)


def uncertainty(r: dict) -> dict | None:
    from .html_uncertainty import uncertainty_view

    body = uncertainty_view(r)
    return _section("uncertainty", **body) if body else None


def view(report: Any, figure_bytes: Mapping | None = None) -> dict:
    """The page's view data: title, footer, the summary line, the verdict, the divergence box, the conventions,
    then each section with something to show (``sections``, in page order, each with its ``id`` and ``title``)
    and the table of contents built from them."""
    r = normalise(report)
    figs = {str(k): v for k, v in figure_bytes.items()} if isinstance(figure_bytes, Mapping) else {}
    sections = [s for s in (ladder(r), ranking(r), errors(r), maneuvers(r), uncertainty(r), identifiability(r),
                            figures(r, figs), separating(r), rudder_residual(r), worst(r), catalogue(r), notes(r), data(r), definitions(r),
                            provenance(r)) if s is not None]
    return {"title": r.get("title") or "Model doctor report", "created_by": r.get("created_by") or "",
            "summary": summary(r), "verdict": verdict(r), "divergence": divergence(r),
            "conventions": (r.get("conventions") or "").strip(), "sections": sections,
            "contents": [{"id": "verdict", "title": "Verdict"}] + [{"id": s["id"], "title": s["title"]}
                                                                   for s in sections]}
