"""The report page's view data: a :class:`.report_schema.Report` turned once into plain lists and
dicts of strings and numbers, in the order and with the words the page shows them; the templates of
``templates/`` lay them out and :mod:`.html` renders them.

Each section's function reads the report as its schema types it and returns the section's data, or
None when the report has nothing for it: the page and its table of contents then leave it out.
"""
from __future__ import annotations

import base64
import math
import re
from collections.abc import Mapping
from typing import Any

from .html_format import (DIVERGED, MODES, NA, REJECTED_DEF, SECTIONS, STABILITY_DEF, TITLES, as_text, base_diverged,
                          definition, divergences, err, final_diverged, finite, fmt_p, fmt_pct, footnote, interval,
                          known, metric_num, named_in, no_final_model, num, param_items, param_value, pct,
                          stability_by_step, step_diverged, unit, unit_notes, verdict_diverged)
from .report_schema import Report


def _section(sid: str, **body) -> dict:
    return {"id": sid, "title": TITLES[sid], **body}


# --------------------------------------------------------------------------------------------- the top


def summary(r: Report) -> list:
    rows = [(label, v) for v, label in ((r.vessel, "Vessel"), (r.model, "Model"), (r.structure, "Structure")) if v]
    if r.mode:
        rows.append(("Validation", MODES.get(r.mode, r.mode)))
    return [{"label": a, "value": b} for a, b in rows]


def _with_units(text: str, units: Mapping) -> list:
    """``text`` in pieces, a piece ending at each ``name = number`` of a parameter with a unit
    (``unit``)."""
    pieces, at = [], 0
    for m in re.finditer(r"\b([A-Za-z_][A-Za-z0-9_]*) = (-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)", text):
        u = unit(m.group(1), units)
        if u:
            pieces.append({"text": text[at:m.end()], "unit": u})
            at = m.end()
    return pieces + [{"text": text[at:], "unit": None}]


def verdict(r: Report) -> dict:
    """The verdict box: its kind (``diverged``, ``found``, ``ambiguous`` or ``none``), what its
    headline names, the report's verdict sentence (with units) and what follows it."""
    missing, ambiguous = r.missing_effect, r.ambiguous
    stab = stability_by_step(r).get(1)
    v: dict = {"named": named_in(stab, long=True), "role": "status", "others": [], "defs": []}
    text = r.verdict
    show_text = True
    if verdict_diverged(r):
        recs = base_diverged(r)
        n_val = len(r.baseline["errors"]) or len(r.validate)
        v.update(kind="diverged", cls="verdict diverged", role="alert", on=known(recs),
                 of=f" {len(recs)} of {n_val}" if recs and n_val >= len(recs) and recs != ["?"] else "")
        if text.strip().lower().startswith("diverged"):
            v["rest"] = re.sub(r"^\s*diverged\s*:?\s*", "", text, flags=re.I)
            show_text = False
        v["others"] = [d for d in divergences(r) if d["what"] != "the baseline model"]
        v["defs"] = [definition(r, "diverged")]
    elif missing is not None:
        cand = next((c for c in r.ranking if c["effect"] == missing), None)
        bits = []
        if cand is not None:
            if finite(cand["improvement"]) is not None and not cand.get("diverged"):
                bits.append(f"validation error down by {fmt_pct(cand['improvement'])}")
            p = cand["p_value"]
            if p is not None and not math.isnan(p):
                bits.append(f"p {fmt_p(p)}" if p < 1e-3 else f"p = {fmt_p(p)}")
        together = [e for e in (r.missing_effects or []) if e != missing]
        if together:  # a pair named at once: the fall is the pair's, the ladder's first step
            e0, e1 = (finite(r.ladder[i].get("scored_error")) for i in (0, 1))
            bits = [f"validation error down by {fmt_pct(1 - e1 / e0)} together"] if e0 and e1 is not None else []
        v.update(kind="found", cls="verdict found", missing=" + ".join([missing, *together]), together=bool(together),
                 bits=bits,
                 inseparable=[a for a in ambiguous if a != missing])
    elif ambiguous:
        v.update(kind="ambiguous", cls="verdict ambiguous", ambiguous=ambiguous)
    else:
        same = named_in(stab)
        v.update(kind="none", cls="verdict none", same=same.replace("named in ", ""))
    v["text"] = _with_units(text, r.units or {}) if text and show_text else None
    if v["kind"] != "diverged" and "validation error" in text:
        v["defs"] = [definition(r, "validation error")]
    v["defs"] = [d for d in v["defs"] if d]
    return v


def divergence(r: Report) -> dict | None:
    """The warning box listing every diverged replay (when the verdict is not already the
    divergence)."""
    items = [] if verdict_diverged(r) else divergences(r)
    return {"entries": items, "defs": [d for d in [definition(r, "diverged")] if d]} if items else None


# --------------------------------------------------------------------------------------------- the tables


def _baseline_val(r: Report) -> float | None:
    if base_diverged(r):
        return None
    b = finite(r.baseline["validation_error"])
    if b:
        return b
    v = finite(r.ladder[0]["validation_error"]) if r.ladder else None
    return v or None


def ladder(r: Report) -> dict | None:
    steps = r.ladder
    if not steps:
        return None
    base, base_div, stab = _baseline_val(r), bool(base_diverged(r)), stability_by_step(r)
    rows, any_div, any_rej, any_stab = [], False, False, False
    for i, s in enumerate(steps):
        div, rejected = step_diverged(s, i, r), s.get("rejected", False)
        any_div |= div
        any_rej |= rejected
        v = finite(s["validation_error"])
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
            status = {"kind": "rejected", "why": s.get("reason", "")}
        elif div:
            status = {"kind": "diverged", "on": ", ".join(known(s.get("diverged", []))) or "a record"}
        else:
            status = {"kind": "given" if i == 0 else "accepted"}
        rows.append({"cls": " ".join(c for c in ("rejected" if rejected else "", "diverged-row" if div else "") if c),
                     "step": s["step"], "effects": s["effects"],
                     "validation": err(s["validation_error"], div), "training": err(s["training_error"]),
                     "fall": fall, "named": named, "status": status})
    extra = [("fall of validation error vs baseline", "(baseline - step) / baseline of the validation error")]
    extra += ([("stability (named in k of n)", STABILITY_DEF)] if any_stab else []) + \
        ([("rejected", REJECTED_DEF)] if any_rej else [])
    defs = footnote(r, ["validation error", "training error"] + (["diverged"] if any_div else []), extra)
    return _section("ladder", rows=rows, defs=defs)


def ranking(r: Report) -> dict | None:
    units = r.units or {}
    rows, any_div, notes = [], False, {}
    for c in r.ranking:
        div_recs = c.get("diverged_records", [])
        div = c.get("diverged", False) or bool(div_recs) or math.isinf(c["validation_error"])
        any_div |= div
        sig = not div and c["significant"]
        cls = "candidate significant" if sig else "candidate"
        cls += " diverged-row" if div else ""
        cls += " chosen" if c["effect"] == r.missing_effect else ""
        mt = c.get("metrics") or {}
        e0, e1 = finite(mt.get("baseline_error")), finite(mt.get("error"))
        rows.append({"cls": cls, "effect": c["effect"], "validation": err(c["validation_error"], div),
                     "on": known(div_recs) if div else [], "improvement": pct(c["improvement"], div),
                     "metrics": [fmt_pct(e1), fmt_pct(e0)] if e0 is not None and e1 is not None else None,
                     "significant": sig, "p": fmt_p(c["p_value"]),
                     "params": param_items(c["parameters"], units, notes), "note": c["note"]})
    na = [{"effect": k, "why": x} for k, x in (r.not_applicable or {}).items()]
    b, bdiv = r.baseline, base_diverged(r)
    base = {"diverged": bool(bdiv), "validation": err(b["validation_error"]), "on": known(bdiv),
            "training": err(b.get("training_error"))}
    extra = [("p-value", "of the paired t-test of the per-record validation errors against the baseline's "
                         "(n/a when there are too few validation records to run it)"),
             ("manoeuvre metrics error", "the mean over the validation turning circles' and zigzags' metrics "
                                         "(tactical diameter, advance, transfer, overshoots...) of |predicted - "
                                         "measured| / |measured|, with the candidate (and, below, the baseline); "
                                         "n/a without such records")]
    return _section("candidates", baseline=base, rows=rows, na=na, tried=bool(rows), unit_notes=unit_notes(notes),
                    defs=footnote(r, ["validation error", "improvement"] + (["diverged"] if any_div else []), extra))


def errors(r: Report) -> dict | None:
    rows, any_div, channels = [], False, set()
    bdiv, fdiv = set(base_diverged(r)), set(final_diverged(r))
    inf = lambda e, keys: any(e[k] is not None and math.isinf(e[k]) for k in keys)  # noqa: E731
    for e in r.errors_table:
        rec = e["record"]
        db = e.get("baseline_diverged", False) or rec in bdiv or inf(e, ("baseline_rmse", "baseline_nrmse"))
        df = e.get("final_diverged", False) or rec in fdiv or inf(e, ("final_rmse", "final_nrmse"))
        any_div |= db or df
        channels.add(e["channel"])
        b, f = finite(e["baseline_nrmse"]), finite(e["final_nrmse"])
        if db or df:
            change = DIVERGED
        elif b is not None and f is not None and b != 0.0:
            change = fmt_pct((f - b) / b)
            change = change if change.startswith("-") else "+" + change
        else:
            change = NA
        cells = [err(e["baseline_rmse"], db), err(e["final_rmse"], df), err(e["baseline_nrmse"], db),
                 err(e["final_nrmse"], df)]
        rows.append({"record": rec, "channel": e["channel"], "unit": e["unit"], "cells": cells, "change": change})
    if not rows:
        return None
    extra = [("RMSE", "root-mean-square error of the replayed channel, in the channel's unit"),
             ("NRMSE change", "(final - baseline) / baseline of the NRMSE; negative is better")]
    terms = ["NRMSE"] + (["track error"] if "track" in channels else []) + (["diverged"] if any_div else [])
    return _section("errors", rows=rows, defs=footnote(r, terms, extra))


def metric_rows(rows: list, bdiv: set = frozenset(), fdiv: set = frozenset()) -> list:
    """The manoeuvre metrics' rows (``study.records.maneuver_metrics.maneuver_metrics``): record,
    metric with its definition, unit, and measured, baseline and final (each with its 90 %
    interval when it has one); a replay that diverged has no metric, and says so."""
    from study.records.maneuver_metrics import COLUMNS, TURNING_METRICS, ZIGZAG_METRICS

    descriptions = {m: d for m, _, d in TURNING_METRICS + ZIGZAG_METRICS}
    out = []
    for x in rows:
        m, rec = x["metric"], x["record"]
        cells = []
        for c in COLUMNS:
            dv = (c == "baseline" and rec in bdiv) or (c == "final" and rec in fdiv)
            cells.append({"value": DIVERGED, "interval": None} if dv and finite(x[c]) is None else
                         {"value": metric_num(x[c]), "interval": interval(x.get(f"{c}_low"), x.get(f"{c}_high"))})
        out.append({"record": rec, "metric": m, "tip": descriptions.get(m), "unit": x["unit"], "cells": cells})
    return out


def maneuvers(r: Report) -> dict | None:
    if r.maneuver_metrics is None:
        return None
    from study.records.maneuver_metrics import TURNING_METRICS, ZIGZAG_METRICS

    rows = r.maneuver_metrics
    bdiv, fdiv = set(base_diverged(r)), set(final_diverged(r))
    shown = {x["metric"] for x in rows}
    return _section("maneuvers", rows=metric_rows(rows, bdiv, fdiv), same=no_final_model(r),
                    metrics=[{"metric": m, "unit": u, "text": d} for m, u, d in TURNING_METRICS + ZIGZAG_METRICS
                             if m in shown], defs=footnote(r, ["diverged"] if (bdiv or fdiv) else []))


def identifiability(r: Report) -> dict | None:
    """Per anchored coefficient of the baseline fit: prior, estimate, prior and posterior sd,
    their ratio and the doctor's sentence; the coefficients the records do not determine, and
    prior-data conflicts, marked."""
    rows, n_not, n_conf = [], 0, 0
    for it in r.identifiability or []:
        ratio, moved = it["ratio"], it["moved_prior_sd"]
        undetermined, conflict = ratio >= 0.9, abs(moved) > 2.0
        n_not += undetermined
        n_conf += conflict
        rows.append({"marked": undetermined or conflict, "coefficient": it["coefficient"],
                     "cells": [num(it["prior"]), num(it["estimate"]), num(it["prior_sd"], 3),
                               num(it["posterior_sd"], 3), num(ratio, 2), num(moved, 2)],
                     "sentence": it["sentence"]})
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


def _caption(meta: Mapping, r: Report) -> str:
    """The figure's caption, less what the figure cannot show in this report."""
    cap, sec = meta["caption"], meta["section"]
    if sec == "compare" and no_final_model(r):
        cap = re.sub(r"Measured \(dots\), the baseline model \(red\) and the model with the effects found \(blue\)",
                     "Measured (dots) and the baseline model (red)", cap)
        cap = re.sub(r",? *(and )?the model with the effects found \(blue\)", "", cap)
    if sec == "ladder" and ("hatched" in cap or "marked" in cap):
        steps = r.ladder
        rej = any(s.get("rejected") for s in steps)
        div = any(step_diverged(s, i, r) for i, s in enumerate(steps))
        head = cap.split(";")[0].rstrip(". ")
        if len(steps) <= 1:
            head = re.sub(r" and of each step with an effect added$", " (no effect was added)", head)
        bits = (["a rejected step (its error not lower) is hatched"] if rej else []) + \
               (["a diverged step is marked DIVERGED, with no bar"] if div else [])
        cap = head + ("; " + "; ".join(bits) if bits else "") + "."
    return cap


def _figure(meta: Mapping, data: Any, r: Report) -> dict:
    file, title, caption = meta["file"], meta["title"], _caption(meta, r)
    src = None
    if isinstance(data, (bytes, bytearray, memoryview)) and len(data) > 0:
        data = bytes(data)
        src = f"data:{_mime(data)};base64,{base64.b64encode(data).decode('ascii')}"
    return {"file": file, "title": title, "caption": caption, "src": src, "alt": title or caption or f"Figure {file}"}


def figures(r: Report, figs: Mapping) -> dict | None:
    metas = list(r.figures)
    listed = {m["file"] for m in metas}
    # figures handed over but not listed in the report still belong in it (after the listed ones)
    metas += [{"file": k, "title": "", "caption": "", "section": "other"} for k in sorted(figs) if k not in listed]
    if not metas:
        return None
    order, groups = list(SECTIONS), {}
    for m in metas:
        sec = m["section"] or "other"
        order += [] if sec in order else [sec]
        groups.setdefault(sec, []).append(m)
    return _section("figures", groups=[
        {"section": sec, "heading": SECTIONS.get(sec, "Other figures" if sec == "other" else
                                                  sec.replace("_", " ").capitalize()),
         "figures": [_figure(m, figs.get(m["file"]), r) for m in groups[sec]]}
        for sec in order if sec in groups])


# --------------------------------------------------------------------------------------------- the rest


def worst(r: Report) -> dict | None:
    time = lambda t: NA if finite(t) is None else f"{t:.1f}"  # noqa: E731
    rows = [{"record": w["record"], "start": time(w["t_start"]), "end": time(w["t_end"]), "error": err(w["nrmse"])}
            for w in r.worst_windows]
    if not rows:
        return None
    return _section("worst", rows=rows, defs=footnote(r, [], [(
        "mean error", "the mean over the window of |predicted - measured| / spread of the measured channel, averaged "
                      "over u, v, r and psi (the error-growth figure's curve)")]))


_PARAM_ITEM = re.compile(r"\s*([^,\[\]]+?)\s*\[([^\[\]]*)\]\s*(?:,|$)")


def _catalogue_params(params: str, notes: dict) -> dict:
    """A catalogue row's parameters: names with their units (``name [unit], ...``), or a text."""
    items = _PARAM_ITEM.findall(params)
    if not items or "".join(_PARAM_ITEM.sub("", params).split()):
        return {"kind": "text", "text": params}
    return {"kind": "names", "entries": [{"name": n, "unit": unit(n, {n: u}, notes)} for n, u in items]}


def catalogue(r: Report) -> dict | None:
    rows, notes = [], {}
    has_applies = any("applies" in c for c in r.catalogue)
    for c in r.catalogue:
        a = c.get("applies", "")
        applies = None if not has_applies else (
            {"kind": "yes"} if a.strip().lower() == "yes" else {"kind": "na"} if not a else {"kind": "why", "why": a})
        rows.append({"name": c["name"], "physics": c["physics"], "params": _catalogue_params(c["parameters"], notes),
                     "enters": c["enters"], "source": c["source"], "applies": applies})
    if not rows:
        return None
    return _section("catalogue", rows=rows, has_applies=has_applies, unit_notes=unit_notes(notes))


def separating(r: Report) -> dict | None:
    """The manoeuvres that would best tell the two leading candidates apart, best first (the top
    eight), and the records in hand scored the same way."""
    sep = r.separating_maneuver
    menu = sep["menu"] if sep else []
    if not menu:
        return None
    row = lambda m, what: {"what": what, "S": num(finite(m.get("S")), 2), "channel": as_text(m.get("channel")),  # noqa: E731
                           "max": num(finite(m.get("max")), 2), "diverged": as_text(m.get("diverged"))}
    rows = [row(m, f"{as_text(m.get('maneuver'))} to {as_text(m.get('side'))}, "
                   f"{100 * (finite(m.get('speed_U0')) or 0):.0f} % of the service speed") for m in menu[:8]]
    recorded = [row(m, m["record"]) for m in sep["recorded"]]
    return _section("separating", pair=sep["pair"], text=sep["text"], rows=rows, recorded=recorded,
                    scale=[f"{c}: {num(finite(v), 3)}" for c, v in sep["scale"].items()])


def rudder_residual(r: Report) -> dict | None:
    """Mean residual N' and Y' (x 1e4) of the training rows per rudder-angle bin, baseline and
    final model."""
    rr = r.rudder_residual or {}
    fits = [(label, rr[k]) for k, label in (("baseline", "baseline"), ("final", "final model"))
            if rr.get(k) and rr[k].get("bins")]
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


def notes(r: Report) -> dict | None:
    return _section("notes", entries=r.notes) if r.notes else None


def _param_table(r: Report) -> dict | None:
    """Baseline and final parameters side by side, each with its unit."""
    b, f = r.baseline["parameters"], r.final["parameters"]
    if not b and not f:
        return None
    units = r.units or {}
    cell = lambda d, n: param_value(d[n]) if n in d else None  # noqa: E731 -- None: the model has no such parameter
    rows = [{"name": n, "cells": [cell(b, n)] + ([cell(f, n)] if f else []),
             "unit": None if units.get(n) in (None, "") else units[n]} for n in dict.fromkeys([*b, *f])]
    return {"final": bool(f), "rows": rows, "conventions": (r.conventions or "").strip()}


def data(r: Report) -> dict | None:
    rows = [{"label": label, "text": v} for v, label in ((r.vessel, "Vessel"), (r.model, "Model"),
                                                         (r.structure, "Sample structure")) if v]
    if r.mode:
        rows.append({"label": "Validation", "text": MODES.get(r.mode, r.mode)})
    rows += [{"label": label, "list": v} for v, label in ((r.train, "Trained on"), (r.validate, "Validated on")) if v]
    if r.depths_h_T:
        rows.append({"label": "Water depth (h/T, depth over draft)", "list": [
            f"{k}: h/T = {num(v, 3)}" if finite(v) is not None else f"{k}: not given (deep water)"
            for k, v in r.depths_h_T.items()]})
    rows.append({"label": "Final model adds", "effects": r.final["effects"]})
    table = _param_table(r)
    if table:
        rows.append({"label": "Parameters", "params": table})
    return _section("data", rows=rows)


def definitions(r: Report) -> dict | None:
    d = [{"term": k, "text": v} for k, v in (r.definitions or {}).items() if v.strip()]
    return _section("definitions", entries=d) if d else None


def provenance(r: Report) -> dict | None:
    p = r.provenance
    if not p:
        return None
    s = lambda k: as_text(p[k]).strip()  # noqa: E731
    rev = s("revision") + (" (with local changes to tracked files)" if s("revision") and p["modified"] is True
                           else "")
    rows = [{"label": label, "text": val, "code": code} for label, val, code in (
        ("Package", f"{s('package')} {s('version')}".strip(), False),
        ("Git revision", rev or "not a git checkout", True), ("Command line", s("command"), True),
        ("Date (UTC)", s("date"), False)) if val]
    recs = [{k: x[k] for k in ("role", "name", "sha256", "sha256_of")} for x in p["records"]]
    return _section("provenance", rows=rows, records=recs)


def uncertainty(r: Report) -> dict | None:
    from .html_uncertainty import uncertainty_view

    body = uncertainty_view(r)
    return _section("uncertainty", **body) if body else None


def view(r: Report, figure_bytes: Mapping | None = None) -> dict:
    """The page's view data: title, footer, the summary line, the verdict, the divergence box,
    the conventions, then each section with something to show (``sections``, in page order, each
    with its ``id`` and ``title``) and the table of contents built from them."""
    figs = {str(k): v for k, v in figure_bytes.items()} if isinstance(figure_bytes, Mapping) else {}
    sections = [s for s in (ladder(r), ranking(r), errors(r), maneuvers(r), uncertainty(r), identifiability(r),
                            figures(r, figs), separating(r), rudder_residual(r), worst(r), catalogue(r), notes(r), data(r), definitions(r),
                            provenance(r)) if s is not None]
    return {"title": r.title or "Model doctor report", "created_by": r.created_by,
            "summary": summary(r), "verdict": verdict(r), "divergence": divergence(r),
            "conventions": (r.conventions or "").strip(), "sections": sections,
            "contents": [{"id": "verdict", "title": "Verdict"}] + [{"id": s["id"], "title": s["title"]}
                                                                   for s in sections]}
