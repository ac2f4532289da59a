"""The model doctor's report as one self-contained HTML5 page.

:func:`render_html` turns the report dict written to ``report.json`` (see :mod:`.diagnose`) and the figures'
PNG bytes into a page that needs nothing else: CSS inline, images as ``data:`` URIs, no JavaScript, and a
Content-Security-Policy that forbids the browser any request (so nothing can leak from, or be fetched by, a
report that is mailed around). Every string from the report is escaped (record names come from users' files);
every key may be missing, empty or of an odd type: what is there is rendered, a section that still cannot be
rendered says so in place, and the page is always produced.

Layout, for a naval architect reading on a laptop or on A4 paper: the verdict at the top (a diverged baseline
is its own warning headline, and any other diverged replay gets a warning box under it), the direction
conventions, the error ladder, the ranked candidate effects (``<table id="ranking">``, one ``<tr
class="candidate">`` each), the per-record errors, the manoeuvres in the ship's terms, the figures grouped by
section, the worst windows, the catalogue of effects, the notes, what was trained and validated on (with the
parameters), the definitions and the provenance (package version, git revision, command line, date, each
record's sha256). A table of contents under the title links to every section (and the verdict): it is built
from the sections rendered, so each of its links has its anchor on the page.

Rules the page keeps:

- every parameter is shown with its unit (the report's ``units``);
- every error figure is defined where it appears: a short footnote under each table from the report's
  ``definitions``;
- a diverged replay (``validation_error`` infinite, or named in a ``diverged`` list) is shown as *diverged*,
  never as a number or a percentage; ``inf`` is never printed;
- a figure's caption does not describe what the figure does not show (no "blue" curve when no effect was
  added, no "hatched" step when none was rejected).
"""
from __future__ import annotations

import base64
import html
import math
import numbers
import re
from collections.abc import Callable, Iterable, Mapping
from typing import Any

__all__ = ["fmt_num", "fmt_pct", "render_html"]

NA = "n/a"
DIVERGED = '<span class="dv">diverged</span>'

#: figure sections in display order, with their headings; any other section follows, in order of appearance
SECTIONS: dict[str, str] = {
    "compare": "Model against measurements",
    "residuals": "Residuals",
    "growth": "Error growth",
    "ladder": "Error ladder",
}

MODES = {
    "given": "validation records given by the user",
    "held_out": "validation records held out by the doctor",
}

#: terms of the report's ``definitions`` explained under each table that uses them (when the report has them)
STABILITY_DEF = ("how many of the n refits, each with one validation record left out, name the same effect at "
                 "this step")
REJECTED_DEF = ("a step whose validation error is not below the previous step's (or whose replay diverges) is "
                "rejected: the ladder stops before it")


# --------------------------------------------------------------------------------------------- formatting


def _e(x: Any) -> str:
    """Escaped text of anything (``None`` -> empty)."""
    if x is None:
        return ""
    return html.escape(str(x), quote=True)


def _float(x: Any) -> float | None:
    """``x`` as a float, or None when it is not a number (bools are not numbers here)."""
    if x is None or isinstance(x, bool):
        return None
    if isinstance(x, numbers.Real):
        try:
            return float(x)
        except (TypeError, ValueError, OverflowError):
            return None
    if isinstance(x, str):
        try:
            return float(x.strip())
        except ValueError:
            return None
    try:  # numpy 0-d arrays and the like
        return float(x)
    except (TypeError, ValueError, OverflowError):
        return None


def fmt_num(x: Any, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; NaN, None and non-numbers -> ``"n/a"`` (plain text).

    ``inf`` stays ``"inf"`` here; the page itself never shows it (an infinite error is a diverged replay, see
    :func:`_err`)."""
    v = _float(x)
    if v is None or math.isnan(v):
        return NA
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{digits}g}"


def fmt_pct(frac: Any, decimals: int = 1) -> str:
    """A fraction as a percentage (0.62 -> ``"62.0 %"``); NaN, None and non-numbers -> ``"n/a"``."""
    v = _float(frac)
    if v is None or math.isnan(v):
        return NA
    if math.isinf(v):
        return "inf %" if v > 0 else "-inf %"
    return f"{100.0 * v:.{decimals}f} %"


def _finite(x: Any) -> float | None:
    v = _float(x)
    return v if v is not None and math.isfinite(v) else None


def _num(x: Any, digits: int = 4) -> str:
    """Escaped HTML of a number as the page shows it: never ``inf`` (-> n/a)."""
    v = _finite(x)
    return NA if v is None else _e(fmt_num(v, digits))


def _err(x: Any, diverged: bool = False) -> str:
    """HTML of an error figure: ``diverged`` when the replay diverged or the value is infinite, n/a when
    missing, else 4 significant digits."""
    v = _float(x)
    if diverged or (v is not None and math.isinf(v)):
        return DIVERGED
    return _num(x)


def _pct(x: Any, diverged: bool = False) -> str:
    if diverged:
        return DIVERGED
    v = _finite(x)
    return NA if v is None else _e(fmt_pct(v))


def _fmt_p(p: Any) -> str:
    v = _float(p)
    if v is None or math.isnan(v):
        return NA
    if v < 1e-3:
        return "&lt; 0.001"
    return f"{v:.2g}"


def _fmt_time(t: Any) -> str:
    v = _float(t)
    if v is None or not math.isfinite(v):
        return NA
    return f"{v:.1f}"


def _list(x: Any) -> list:
    """A list from a list/tuple (a lone string or mapping is one item); anything else -> []."""
    if x is None:
        return []
    if isinstance(x, (str, bytes, Mapping)):
        return [x]
    if isinstance(x, Iterable):
        return list(x)
    return [x]


def _dict(x: Any) -> dict:
    return dict(x) if isinstance(x, Mapping) else {}


def _str(x: Any) -> str:
    return x.strip() if isinstance(x, str) else ""


def _recs(x: Any) -> list[str]:
    """Record names from a ``diverged`` entry (a list of names; a bare True is "some record")."""
    if x is True:
        return ["?"]
    if x is None or x is False or isinstance(x, (Mapping, numbers.Number)):
        return []
    return [str(a) for a in _list(x) if a is not None and str(a) != ""]


def _names(xs: Any) -> str:
    return ", ".join(_e(x) for x in _list(xs) if x is not None and str(x) != "")


def _value(v: Any) -> str:
    """A parameter's value: a number to 4 significant digits (n/a when NaN or infinite), a word as it is."""
    if isinstance(v, str) and _float(v) is None:
        return _e(v)
    return _num(v)


def _unit(name: Any, units: Mapping, notes: dict | None = None) -> str:
    """The unit of a parameter as HTML (``[m/s]``; a remark alone in parentheses as it is), or empty. With
    ``notes`` (remark -> number, filled here) a unit ``"- (non-dimensional, ...)"`` is shown as ``[-]`` and a
    footnote number, its remark to be listed once under the table (:func:`_unit_notes`)."""
    u = units.get(str(name)) if isinstance(units, Mapping) else None
    if u is None or str(u).strip() == "":
        return ""
    u = str(u).strip()
    m = re.fullmatch(r"([^()]+?)\s*\((.+)\)", u)
    if notes is not None and m:
        k = notes.setdefault(m.group(2), len(notes) + 1)
        return f'<span class="unit">[{_e(m.group(1))}]<sup>{k}</sup></span>'
    text = u if u.startswith("(") else f"[{u}]"
    return f'<span class="unit">{_e(text)}</span>'


def _unit_notes(notes: Mapping) -> str:
    if not notes:
        return ""
    items = "; ".join(f"<sup>{k}</sup>&nbsp;{_e(t)}" for t, k in notes.items())
    return f'<p class="defs"><b>units</b>: {items}.</p>'


def _params(p: Any, units: Mapping | None = None, notes: dict | None = None) -> str:
    """Parameters as ``name = value [unit]`` lines, 4 significant digits."""
    d = _dict(p)
    if not d:
        return ""
    units = units or {}
    items = []
    for k, v in d.items():
        u = _unit(k, units, notes)
        items.append(f'<span class="param">{_e(k)}&nbsp;=&nbsp;{_value(v)}</span>' + (f" {u}" if u else ""))
    return "<br>".join(items)


def _defs(r: dict, terms: Iterable[str], extra: Iterable[tuple[str, str]] = ()) -> str:
    """A footnote under a table: the report's definitions of ``terms`` (those it has), then ``extra``."""
    d = _dict(r.get("definitions"))
    items = [(t, d[t]) for t in terms if isinstance(d.get(t), str) and d[t].strip()]
    items += [(t, x) for t, x in extra if x]
    if not items:
        return ""
    lis = "".join(f"<li><b>{_e(t)}</b>: {_e(str(x).rstrip('. '))}.</li>" for t, x in items)
    return f'<ul class="defs">{lis}</ul>'


def _pdefs(r: dict, term: str) -> str:
    d = _dict(r.get("definitions"))
    x = d.get(term)
    return f'<p class="defs"><b>{_e(term)}</b>: {_e(x.rstrip(". "))}.</p>' if isinstance(x, str) and x else ""


# --------------------------------------------------------------------------------------------- divergence


def _base_diverged(r: dict) -> list[str]:
    """Validation records on which the baseline's replay diverged (wherever the report says so)."""
    out = _recs(_dict(r.get("baseline")).get("diverged")) + _recs(_dict(r.get("diverged")).get("baseline"))
    for e in _list(r.get("errors_table")):
        if isinstance(e, Mapping) and e.get("baseline_diverged") is True and e.get("record") is not None:
            out.append(str(e.get("record")))
    steps = [s for s in _list(r.get("ladder")) if isinstance(s, Mapping)]
    if steps and str(steps[0].get("step", "baseline")) == "baseline":
        out += _recs(steps[0].get("diverged"))
    return list(dict.fromkeys(out))


def _final_diverged(r: dict) -> list[str]:
    out = _recs(_dict(r.get("final")).get("diverged"))
    for e in _list(r.get("errors_table")):
        if isinstance(e, Mapping) and e.get("final_diverged") is True and e.get("record") is not None:
            out.append(str(e.get("record")))
    return list(dict.fromkeys(out))


def _verdict_diverged(r: dict) -> bool:
    v = r.get("verdict")
    if isinstance(v, str) and v.strip().lower().startswith("diverged"):
        return True
    return bool(_base_diverged(r))


def _divergences(r: dict) -> list[tuple[str, list[str]]]:
    """(what, records) of every replay that diverged: the baseline, each ladder step, the final model, each
    candidate of the ranking."""
    out: list[tuple[str, list[str]]] = []
    seen: set[str] = set()

    def add(what: str, recs: list[str], key: str | None = None) -> None:
        key = what if key is None else key
        if recs and key not in seen:
            seen.add(key)
            out.append((what, recs))

    add("the baseline model", _base_diverged(r))
    for s in _list(r.get("ladder")):
        if isinstance(s, Mapping) and str(s.get("step")) != "baseline":
            recs = _recs(s.get("diverged"))
            v = _float(s.get("validation_error"))
            if not recs and v is not None and math.isinf(v):
                recs = ["?"]
            tag = " (rejected)" if s.get("rejected") else ""
            add(f"ladder step {s.get('step')}{tag}", recs, f"step {s.get('step')}")
    for step, recs in _dict(r.get("diverged")).items():
        if str(step) != "baseline":
            add(f"ladder step {step}", _recs(recs), f"step {step}")
    if not _no_final_model(r):  # else it is the baseline, said above
        add("the final model", _final_diverged(r))
    for c in _list(r.get("ranking")):
        if isinstance(c, Mapping) and (c.get("diverged") is True or _recs(c.get("diverged_records"))):
            add(f"candidate {c.get('effect')}", _recs(c.get("diverged_records")) or ["?"])
    return out


def _div_items(items: list[tuple[str, list[str]]]) -> str:
    lis = []
    for what, recs in items:
        on = [x for x in recs if x != "?"]
        where = f" when replayed through {_names(on)}" if on else ""
        lis.append(f"<li>{_e(what)}: <b>DIVERGED</b>{where}</li>")
    return '<ul class="div-list">' + "".join(lis) + "</ul>"


def _divergence(r: dict) -> str:
    """A warning box listing every diverged replay (when the verdict is not already the divergence)."""
    if _verdict_diverged(r):
        return ""
    items = _divergences(r)
    if not items:
        return ""
    return ('<div class="alert" id="divergence" role="alert">\n<p class="headline"><strong>DIVERGED</strong> '
            'replays in this report</p>\n' + _div_items(items) + _pdefs(r, "diverged") + "\n</div>")


# --------------------------------------------------------------------------------------------- sections


def _section(title: str, body: str, sid: str, cls: str = "") -> str:
    c = f' class="{cls}"' if cls else ""
    return f'<section id="{sid}"{c}>\n<h2>{_e(title)}</h2>\n{body}\n</section>'


def _stability(r: dict) -> dict[int, Mapping]:
    out = {}
    for s in _list(r.get("stability")):
        if isinstance(s, Mapping):
            step = _float(s.get("step"))
            if step is not None and math.isfinite(step) and int(step) not in out:
                out[int(step)] = s
    return out


def _named_in(s: Mapping | None, long: bool = False) -> str:
    """``named in k of n`` of a stability entry (its text when k/n are missing); empty without one."""
    if not isinstance(s, Mapping):
        return ""
    k, n = _finite(s.get("k")), _finite(s.get("n"))
    if k is not None and n is not None:
        txt = f"named in {int(k)} of {int(n)}"
        return txt + " with one validation record left out" if long else txt
    t = s.get("text")
    return _e(t) if isinstance(t, str) and long else ""


def _with_units(text: str, units: Mapping) -> str:
    """Escaped ``text`` with the unit after each ``name = number`` of a parameter that has one."""
    if not units:
        return text

    def put(m: re.Match) -> str:
        u = _unit(m.group(1), units)
        return m.group(0) + (f" {u}" if u else "")

    return re.sub(r"\b([A-Za-z_][A-Za-z0-9_]*) = (-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)", put, text)


def _verdict(r: dict) -> str:
    missing = r.get("missing_effect")
    missing = None if missing is None or str(missing).strip() == "" else str(missing)
    ambiguous = [str(a) for a in _list(r.get("ambiguous")) if a is not None and str(a) != ""]
    ranking = [c for c in _list(r.get("ranking")) if isinstance(c, Mapping)]
    stab = _stability(r).get(1)
    named = _named_in(stab, long=True)
    named_html = f'<br><span class="detail stability">{named}</span>' if named else ""
    role, extra, show_text = "status", "", True

    if _verdict_diverged(r):
        recs = _base_diverged(r)
        n_val = len(_dict(_dict(r.get("baseline")).get("errors"))) or len(_list(r.get("validate")))
        of = f" {len(recs)} of {n_val}" if recs and n_val >= len(recs) and recs != ["?"] else ""
        on = [x for x in recs if x != "?"]
        where = f" ({_names(on)})" if on else ""
        vt = r.get("verdict")
        if isinstance(vt, str) and vt.strip().lower().startswith("diverged"):
            rest = re.sub(r"^\s*diverged\s*:?\s*", "", vt, flags=re.I)
            head = f'<strong class="diverged-word">DIVERGED</strong>{": " + _e(rest) if rest else ""}'
            show_text = False
        else:
            head = (f'<strong class="diverged-word">DIVERGED</strong>: the baseline model diverges when replayed '
                    f'through{of} validation record(s){where}; no missing effect can be named')
        cls, role = "verdict diverged", "alert"
        others = [d for d in _divergences(r) if d[0] != "the baseline model"]
        if others:
            extra += _div_items(others)
        extra += _pdefs(r, "diverged")
    elif missing is not None:
        cand = next((c for c in ranking if str(c.get("effect")) == missing), None)
        detail = ""
        if cand is not None:
            bits = []
            if _finite(cand.get("improvement")) is not None and cand.get("diverged") is not True:
                bits.append(f"validation error down by {_e(fmt_pct(cand.get('improvement')))}")
            pv = _float(cand.get("p_value"))
            if pv is not None and not math.isnan(pv):
                bits.append(f"p {_fmt_p(pv)}" if pv < 1e-3 else f"p = {_fmt_p(pv)}")
            if bits:
                detail = f' <span class="detail">({"; ".join(bits)})</span>'
        head = f'Missing effect: <strong class="missing">{_e(missing)}</strong>{detail}{named_html}'
        if ambiguous:
            others = [a for a in ambiguous if a != missing]
            if others:
                head += f'<br><span class="detail">Not separable from: {_names(others)}</span>'
        cls = "verdict found"
    elif ambiguous:
        head = ("Ambiguous: the records do not separate "
                + " / ".join(f"<strong>{_e(a)}</strong>" for a in ambiguous) + named_html)
        cls = "verdict ambiguous"
    elif "missing_effect" in r or ranking:
        same = _named_in(stab)
        same = (f'<br><span class="detail stability">the same in {same.replace("named in ", "")} refits with one '
                'validation record left out</span>') if same else ""
        head = f"<strong>No significant missing effect</strong>{same}"
        cls = "verdict none"
    else:
        head = ""
        cls = "verdict unknown"

    text = r.get("verdict")
    text = (f'<p class="verdict-text">{_with_units(_e(text), _dict(r.get("units")))}</p>'
            if text not in (None, "") and show_text else "")
    if not head and not text:
        text = '<p class="verdict-text">No verdict in this report.</p>'
    if cls != "verdict diverged" and isinstance(r.get("verdict"), str) and "validation error" in r["verdict"]:
        extra += _pdefs(r, "validation error")
    head = f'<p class="headline">{head}</p>' if head else ""
    return f'<div class="{cls}" id="verdict" role="{role}">\n{head}\n{text}\n{extra}\n</div>'


def _summary(r: dict) -> str:
    rows = []
    for key, label in (("vessel", "Vessel"), ("model", "Model"), ("structure", "Structure")):
        if r.get(key) not in (None, ""):
            rows.append(f"<span><b>{label}:</b> {_e(r.get(key))}</span>")
    mode = r.get("mode")
    if mode not in (None, ""):
        rows.append(f"<span><b>Validation:</b> {_e(MODES.get(str(mode), mode))}</span>")
    return f'<p class="summary">{" &middot; ".join(rows)}</p>' if rows else ""


def _conventions(r: dict) -> str:
    c = _str(r.get("conventions"))
    if not c:
        return ""
    return f'<p class="conventions" id="conventions"><b>Conventions.</b> {_e(c)}</p>'


def _baseline_val(r: dict) -> float | None:
    if _base_diverged(r):
        return None
    b = _float(_dict(r.get("baseline")).get("validation_error"))
    if b is not None and math.isfinite(b) and b != 0.0:
        return b
    for step in _list(r.get("ladder")):
        if isinstance(step, Mapping):
            v = _float(step.get("validation_error"))
            if v is not None and math.isfinite(v) and v != 0.0:
                return v
            break
    return None


def _step_diverged(s: Mapping, i: int, r: dict) -> bool:
    v = _float(s.get("validation_error"))
    if _recs(s.get("diverged")) or (v is not None and math.isinf(v)):
        return True
    return i == 0 and str(s.get("step", "baseline")) == "baseline" and bool(_base_diverged(r))


def _ladder(r: dict) -> str:
    steps = [s for s in _list(r.get("ladder")) if isinstance(s, Mapping)]
    if not steps:
        return ""
    base = _baseline_val(r)
    base_div = bool(_base_diverged(r))
    stab = _stability(r)
    body, any_div, any_rej, any_stab = [], False, False, False
    for i, s in enumerate(steps):
        div = _step_diverged(s, i, r)
        rejected = s.get("rejected") is True
        any_div |= div
        any_rej |= rejected
        v = _float(s.get("validation_error"))
        if div:
            fall_txt = DIVERGED
        elif base is not None and v is not None and math.isfinite(v):
            fall = (base - v) / base
            width = max(0.0, min(1.0, fall)) * 100.0
            fall_txt = (f'<span class="fall"><span class="track"><span class="bar" style="width:{width:.1f}%">'
                        f'</span></span><span class="bartext">{_e(fmt_pct(fall))}</span></span>')
        elif base_div:
            fall_txt = '<span class="muted">n/a (baseline diverged)</span>'
        else:
            fall_txt = NA
        effects = _names(s.get("effects")) or '<span class="muted">none</span>'
        st = stab.get(i) if i > 0 and not rejected else None
        named = _named_in(st)
        any_stab |= bool(named)
        if rejected:
            why = _e(s.get("reason")) if s.get("reason") not in (None, "") else ""
            status = f'<span class="rejected-word">rejected</span>{": " + why if why else ""}'
        elif div:
            status = f'{DIVERGED} on {_names([x for x in _recs(s.get("diverged")) if x != "?"]) or "a record"}'
        elif i == 0:
            status = '<span class="muted">the model as given</span>'
        else:
            status = "accepted"
        cls = " ".join(c for c in ("rejected" if rejected else "", "diverged-row" if div else "") if c)
        cls = f' class="{cls}"' if cls else ""
        body.append(f'<tr{cls}><td>{_e(s.get("step"))}</td><td>{effects}</td>'
                    f'<td class="num">{_err(s.get("validation_error"), div)}</td>'
                    f'<td class="num">{_err(s.get("training_error"))}</td>'
                    f'<td class="num fallcell">{fall_txt}</td>'
                    f'<td class="num">{named or "&ndash;"}</td><td class="status">{status}</td></tr>')
    table = ('<table class="ladder">\n<thead><tr><th>Step</th><th>Effects in the model</th>'
             '<th class="num">Validation error [-]</th><th class="num">Training error [-]</th>'
             '<th class="num">Fall of validation error vs baseline</th>'
             '<th class="num">Stability</th><th>Status</th></tr></thead>\n<tbody>\n'
             + "\n".join(body) + "\n</tbody></table>")
    extra = [("fall of validation error vs baseline", "(baseline - step) / baseline of the validation error")]
    if any_stab:
        extra.append(("stability (named in k of n)", STABILITY_DEF))
    if any_rej:
        extra.append(("rejected", REJECTED_DEF))
    foot = _defs(r, ["validation error", "training error"] + (["diverged"] if any_div else []), extra)
    return _section("Error ladder", table + foot, "ladder")


def _ranking(r: dict) -> str:
    cands = _list(r.get("ranking"))
    b = _dict(r.get("baseline"))
    units = _dict(r.get("units"))
    missing = r.get("missing_effect")
    rows, any_div, notes = [], False, {}
    for i, c in enumerate(cands, 1):
        c = c if isinstance(c, Mapping) else {"effect": c}
        div_recs = _recs(c.get("diverged_records"))
        v = _float(c.get("validation_error"))
        div = c.get("diverged") is True or bool(div_recs) or (v is not None and math.isinf(v))
        any_div |= div
        sig = not div and (c.get("significant") is True or (
            not isinstance(c.get("significant"), (str, type(None))) and bool(c.get("significant"))))
        cls = "candidate significant" if sig else "candidate"
        if div:
            cls += " diverged-row"
        if missing is not None and str(c.get("effect")) == str(missing):
            cls += " chosen"
        mark = ('<span class="sig" title="significant">&#10003; significant</span>' if sig
                else '<span class="muted">no</span>')
        val = _err(c.get("validation_error"), div)
        on = [x for x in div_recs if x != "?"]
        if div and on:
            val += f'<br><span class="detail">on {_names(on)}</span>'
        mt = _dict(c.get("metrics"))
        e0, e1 = _finite(mt.get("baseline_error")), _finite(mt.get("error"))
        mcell = (f'{fmt_pct(e1)}<br><span class="detail">baseline {fmt_pct(e0)}</span>'
                 if e0 is not None and e1 is not None else NA)
        rows.append(f'<tr class="{cls}"><td class="num">{i}</td><td class="effect">{_e(c.get("effect"))}</td>'
                    f'<td class="num">{val}</td>'
                    f'<td class="num">{_pct(c.get("improvement"), div)}</td>'
                    f'<td class="num metrics">{mcell}</td>'
                    f'<td>{mark}</td><td class="num">{_fmt_p(c.get("p_value"))}</td>'
                    f'<td class="params">{_params(c.get("parameters"), units, notes)}</td>'
                    f'<td>{_e(c.get("note"))}</td></tr>')
    na = {str(k): v for k, v in _dict(r.get("not_applicable")).items()}
    na_html = ""
    if na:
        lis = "".join(f'<li><b>{_e(k)}</b>: {_e(v)}</li>' for k, v in na.items())
        na_html = ('<p class="legend">Not tried here (cannot act on this model or these records):</p>'
                   f'<ul class="na">{lis}</ul>')
    if not rows and not b:
        return _section("Candidate effects", na_html, "candidates") if na_html else ""
    base_line = ""
    if b:
        bdiv = _base_diverged(r)
        if bdiv:
            on = [x for x in bdiv if x != "?"]
            val = DIVERGED + (f" (on {_names(on)})" if on else "")
        else:
            val = f"<b>{_err(b.get('validation_error'))}</b>"
        base_line = (f'<p>Baseline (no added effect): validation error {val}, training error '
                     f'{_err(b.get("training_error"))}.</p>')
    if not rows:
        return _section("Candidate effects", base_line + '<p class="muted">No candidate was tried.</p>' + na_html,
                        "candidates")
    table = ('<table id="ranking" class="ranking">\n<thead><tr><th class="num">#</th><th>Effect</th>'
             '<th class="num">Validation error [-]</th><th class="num">Improvement</th>'
             '<th class="num">Manoeuvre metrics error</th><th>Significant</th>'
             '<th class="num">p&#8209;value</th><th>Identified parameters [unit]</th><th>Note</th></tr></thead>\n'
             '<tbody>\n' + "\n".join(rows) + "\n</tbody></table>")
    legend = ('<p class="legend">Candidates ranked by out-of-sample improvement: each effect is added alone to '
              'the baseline, identified on the training records and judged on the validation records. '
              '<span class="sig">&#10003; significant</span> rows are highlighted.</p>')
    extra = [("p-value", "of the paired t-test of the per-record validation errors against the baseline's "
                         "(n/a when there are too few validation records to run it)"),
             ("manoeuvre metrics error", "the mean over the validation turning circles' and zigzags' metrics "
                                         "(tactical diameter, advance, transfer, overshoots...) of |predicted - "
                                         "measured| / |measured|, with the candidate (and, below, the baseline); "
                                         "n/a without such records")]
    foot = _defs(r, ["validation error", "improvement"] + (["diverged"] if any_div else []), extra)
    return _section("Candidate effects", base_line + legend + table + _unit_notes(notes) + foot + na_html,
                    "candidates")


def _errors(r: dict) -> str:
    rows, any_div = [], False
    bdiv, fdiv = set(_base_diverged(r)), set(_final_diverged(r))
    channels = set()
    for e in _list(r.get("errors_table")):
        if not isinstance(e, Mapping):
            continue
        rec = str(e.get("record"))
        db = e.get("baseline_diverged") is True or rec in bdiv or any(
            (v := _float(e.get(k))) is not None and math.isinf(v) for k in ("baseline_rmse", "baseline_nrmse"))
        df = e.get("final_diverged") is True or rec in fdiv or any(
            (v := _float(e.get(k))) is not None and math.isinf(v) for k in ("final_rmse", "final_nrmse"))
        any_div |= db or df
        channels.add(str(e.get("channel")))
        b, f = _finite(e.get("baseline_nrmse")), _finite(e.get("final_nrmse"))
        if db or df:
            change = DIVERGED
        elif b is not None and f is not None and b != 0.0:
            change = fmt_pct((f - b) / b)
            if not change.startswith("-") and change != NA:
                change = "+" + change
            change = _e(change)
        else:
            change = NA
        unit = f" [{_e(e.get('unit'))}]" if e.get("unit") not in (None, "") else ""
        rows.append(f'<tr><td>{_e(e.get("record"))}</td><td>{_e(e.get("channel"))}{unit}</td>'
                    f'<td class="num">{_err(e.get("baseline_rmse"), db)}</td>'
                    f'<td class="num">{_err(e.get("final_rmse"), df)}</td>'
                    f'<td class="num">{_err(e.get("baseline_nrmse"), db)}</td>'
                    f'<td class="num">{_err(e.get("final_nrmse"), df)}</td>'
                    f'<td class="num">{change}</td></tr>')
    if not rows:
        return ""
    table = ('<table class="errors">\n<thead><tr><th>Record</th><th>Channel [unit]</th>'
             '<th class="num">RMSE baseline [unit]</th><th class="num">RMSE final [unit]</th>'
             '<th class="num">NRMSE baseline [-]</th><th class="num">NRMSE final [-]</th>'
             '<th class="num">NRMSE change</th></tr></thead>\n<tbody>\n' + "\n".join(rows) + "\n</tbody></table>")
    extra = [("RMSE", "root-mean-square error of the replayed channel, in the channel's unit"),
             ("NRMSE change", "(final - baseline) / baseline of the NRMSE; negative is better")]
    terms = ["NRMSE"] + (["track error"] if "track" in channels else []) + (["diverged"] if any_div else [])
    return _section("Errors per record and channel", table + _defs(r, terms, extra), "errors")


# the manoeuvre metrics' table (rows of study.maneuver_metrics.maneuver_metrics)
# ---------------------------------------------------------------------------------------------- HTML
def _metric_num(x) -> str:
    """3-4 significant digits; NaN, None, inf and non-numbers -> 'n/a'."""
    if x is None or isinstance(x, bool) or not isinstance(x, numbers.Real):
        return "n/a"
    v = float(x)
    if not math.isfinite(v):
        return "n/a"
    if v == 0:
        return "0"
    if 1e4 <= abs(v) < 1e9:
        return f"{v:.0f}"
    return f"{v:.4g}"


def _interval(row: dict, col: str) -> str:
    """Under a predicted value, its 90 % interval (``<col>_low``, ``<col>_high``; study.doctor.uncertainty)."""
    from .html_uncertainty import interval_text

    txt = interval_text(row.get(f"{col}_low"), row.get(f"{col}_high"))
    return f'<br><span class="interval">90 %: {txt}</span>' if txt else ""


def metrics_table_html(rows: list[dict]) -> str:
    """A small self-contained HTML ``<table class="maneuver-metrics">`` of ``study.maneuver_metrics.maneuver_metrics``
    rows: record, metric (its definition as a tooltip), unit, measured, baseline, final (with its 90 % interval
    under it when the row has one); numbers to 4 significant digits, NaN as ``n/a``; every string escaped. No
    rows: a table with one row saying so."""
    from ..maneuver_metrics import COLUMNS, TURNING_METRICS, ZIGZAG_METRICS

    units = {m: u for m, u, _ in TURNING_METRICS + ZIGZAG_METRICS}
    descriptions = {m: d for m, _, d in TURNING_METRICS + ZIGZAG_METRICS}
    e = lambda x: html.escape("" if x is None else str(x), quote=True)  # noqa: E731
    head = ('<table class="maneuver-metrics">\n<thead><tr><th>Record</th><th>Metric</th><th>Unit</th>'
            '<th class="num">Measured</th><th class="num">Baseline</th><th class="num">Final</th></tr></thead>\n'
            '<tbody>\n')
    body = []
    for r in rows or []:
        if not isinstance(r, dict):
            continue
        m = r.get("metric")
        tip = descriptions.get(str(m))
        title = f' title="{e(tip)}"' if tip else ""
        body.append(f'<tr><td class="record">{e(r.get("record"))}</td><td class="metric"{title}>{e(m)}</td>'
                    f'<td class="unit">{e(r.get("unit", units.get(str(m), "")))}</td>'
                    + "".join(f'<td class="num">{e(_metric_num(r.get(c)))}{_interval(r, c)}</td>' for c in COLUMNS)
                    + "</tr>")
    if not body:
        body.append('<tr><td colspan="6" class="muted">No turning circle or zigzag among the validation records: '
                    'no standard manoeuvre metrics.</td></tr>')
    return head + "\n".join(body) + "\n</tbody>\n</table>"


def _maneuvers(r: dict) -> str:
    rows = [x for x in _list(r.get("maneuver_metrics")) if isinstance(x, Mapping) and x.get("metric") is not None]
    if "maneuver_metrics" not in r or (not rows and not isinstance(r.get("maneuver_metrics"), list)):
        return ""
    from ..maneuver_metrics import TURNING_METRICS, ZIGZAG_METRICS

    rows = [dict(x) for x in rows]
    table = metrics_table_html(rows)
    bdiv, fdiv = set(_base_diverged(r)), set(_final_diverged(r))
    # a replay that diverged has no metric: say so where the table says n/a (one <tr> per row, in order)
    if rows and (bdiv or fdiv):
        lines, k = table.split("\n"), 0
        for j, line in enumerate(lines):
            if not line.startswith("<tr><td") or k >= len(rows):
                continue
            row = rows[k]
            k += 1
            cells = line.split('<td class="num">')
            if len(cells) != 4:
                continue
            for c, dv in ((2, str(row.get("record")) in bdiv), (3, str(row.get("record")) in fdiv)):
                if dv and _finite(row.get(("measured", "baseline", "final")[c - 1])) is None:
                    cells[c] = DIVERGED + cells[c][cells[c].index("</td>"):]
            lines[j] = '<td class="num">'.join(cells)
        table = "\n".join(lines)
    shown = {str(x.get("metric")) for x in rows}
    desc = [f"<b>{_e(m)}</b> [{_e(u)}]: {_e(d)}" for m, u, d in TURNING_METRICS + ZIGZAG_METRICS if m in shown]
    desc = f'<p class="defs">{"; ".join(desc)}.</p>' if desc else ""
    fin = _dict(r.get("final")).get("effects")
    base_eff = _dict(r.get("baseline")).get("effects")
    same = isinstance(fin, list) and isinstance(base_eff, list) and sorted(map(str, fin)) == sorted(map(str, base_eff))
    intro = ('<p class="legend">Standard manoeuvre metrics (IMO MSC.137(76), MSC/Circ.1053, ITTC 7.5-04-02-01) of '
             'each validation record that is a turning circle or a zigzag, on the measured record and on the '
             'replays of the baseline and of the final model (open loop, the measured rudder; a record with an '
             'approach before its manoeuvre is cut there and replayed from its measured state). n/a: the record '
             'cannot carry the metric.' + (' No effect was added: the final model is the baseline.' if same else '')
             + '</p>')
    foot = desc + _defs(r, ["diverged"] if (bdiv or fdiv) else [])
    return _section("Manoeuvres in the ship's terms", intro + table + foot, "maneuvers")


def _uncertainty(r: dict) -> str:
    from .html_uncertainty import TITLE, uncertainty_section

    body = uncertainty_section(r)
    return _section(TITLE, body, "uncertainty") if body else ""


def _mime(data: bytes) -> str:
    if data.startswith(b"\x89PNG\r\n\x1a\n"):
        return "image/png"
    if data.startswith(b"\xff\xd8\xff"):
        return "image/jpeg"
    if data.startswith((b"GIF87a", b"GIF89a")):
        return "image/gif"
    head = data[:256].lstrip()
    if head.startswith(b"<svg") or (head.startswith(b"<?xml") and b"<svg" in data[:2048]):
        return "image/svg+xml"
    return "image/png"


def _no_final_model(r: dict) -> bool:
    """True when the report says no effect was added (so no "model with the effects" is drawn anywhere)."""
    fin, base = _dict(r.get("final")), _dict(r.get("baseline"))
    if isinstance(fin.get("effects"), list) and isinstance(base.get("effects"), list):
        return sorted(map(str, fin["effects"])) == sorted(map(str, base["effects"]))
    steps = [s for s in _list(r.get("ladder")) if isinstance(s, Mapping)]
    if steps:
        return not any(s.get("rejected") is not True for s in steps[1:])
    return False


def _caption(meta: Mapping, r: dict) -> Any:
    """The figure's caption, less what the figure cannot show in this report."""
    cap = meta.get("caption")
    if not isinstance(cap, str):
        return cap
    sec = str(meta.get("section") or "")
    if sec == "compare" and _no_final_model(r):
        cap = re.sub(r"Measured \(dots\), the baseline model \(red\) and the model with the effects found \(blue\)",
                     "Measured (dots) and the baseline model (red)", cap)
        cap = re.sub(r",? *(and )?the model with the effects found \(blue\)", "", cap)
    if sec == "ladder" and ("hatched" in cap or "marked" in cap):
        steps = [s for s in _list(r.get("ladder")) if isinstance(s, Mapping)]
        rej = any(s.get("rejected") is True for s in steps)
        div = any(_step_diverged(s, i, r) for i, s in enumerate(steps))
        head = cap.split(";")[0].rstrip(". ")
        if len(steps) <= 1:
            head = re.sub(r" and of each step with an effect added$", " (no effect was added)", head)
        bits = (["a rejected step (its error not lower) is hatched"] if rej else []) + \
               (["a diverged step is marked DIVERGED, with no bar"] if div else [])
        cap = head + ("; " + "; ".join(bits) if bits else "") + "."
    return cap


def _figure(meta: Mapping, data: Any, r: dict | None = None) -> str:
    file = meta.get("file")
    title = meta.get("title")
    caption = _caption(meta, r or {})
    alt = next((str(x) for x in (title, caption) if x not in (None, "")), f"Figure {file}")
    cap = ""
    if title not in (None, "") or caption not in (None, ""):
        t = f"<b>{_e(title)}.</b> " if title not in (None, "") else ""
        cap = f"<figcaption>{t}{_e(caption)}</figcaption>"
    if isinstance(data, (bytes, bytearray, memoryview)) and len(data) > 0:
        data = bytes(data)
        uri = f"data:{_mime(data)};base64,{base64.b64encode(data).decode('ascii')}"
        img = f'<img src="{uri}" alt="{_e(alt)}" loading="eager" decoding="sync">'
    else:
        img = f'<p class="missing-figure">Figure file {_e(file)} is missing.</p>'
    return f'<figure data-file="{_e(file)}">\n{img}\n{cap}\n</figure>'


def _figures(r: dict, figures: Mapping) -> str:
    metas = [m for m in _list(r.get("figures")) if isinstance(m, Mapping)]
    listed = {str(m.get("file")) for m in metas}
    # figures handed over but not listed in the report still belong in it (after the listed ones)
    for name in sorted((k for k in figures if str(k) not in listed), key=str):
        metas.append({"file": name, "title": "", "caption": "", "section": "other"})
    if not metas:
        return ""
    order: list[str] = list(SECTIONS)
    groups: dict[str, list[Mapping]] = {}
    for m in metas:
        sec = str(m.get("section") or "other")
        if sec not in order:
            order.append(sec)
        groups.setdefault(sec, []).append(m)
    parts = []
    for sec in order:
        if sec not in groups:
            continue
        heading = SECTIONS.get(sec, "Other figures" if sec == "other" else sec.replace("_", " ").capitalize())
        figs = "\n".join(_figure(m, figures.get(str(m.get("file"))), r) for m in groups[sec])
        parts.append(f'<div class="figgroup" data-section="{_e(sec)}">\n<h3>{_e(heading)}</h3>\n{figs}\n</div>')
    return _section("Figures", "\n".join(parts), "figures")


def _worst(r: dict) -> str:
    items = []
    for w in _list(r.get("worst_windows")):
        if not isinstance(w, Mapping):
            continue
        items.append(f'<li><b>{_e(w.get("record"))}</b>, t = {_fmt_time(w.get("t_start"))} to '
                     f'{_fmt_time(w.get("t_end"))} s: mean error {_err(w.get("nrmse"))}</li>')
    if not items:
        return ""
    foot = _defs(r, [], [("mean error", "the mean over the window of |predicted - measured| / spread of the "
                                        "measured channel, averaged over u, v, r and psi (the error-growth "
                                        "figure's curve)")])
    return _section("Worst windows of the baseline", '<ol class="worst">\n' + "\n".join(items) + "\n</ol>" + foot,
                    "worst")


def _identifiability(r: dict) -> str:
    """Per anchored coefficient of the baseline fit: prior, estimate, prior and posterior sd, their ratio and the
    doctor's sentence; the coefficients the records do not determine, and prior-data conflicts, marked."""
    rows = []
    n_not, n_conf = 0, 0
    for it in _list(r.get("identifiability")):
        if not isinstance(it, Mapping):
            continue
        ratio, moved = _float(it.get("ratio")), _float(it.get("moved_prior_sd"))
        undetermined = ratio is not None and ratio >= 0.9
        conflict = moved is not None and abs(moved) > 2.0
        n_not += undetermined
        n_conf += conflict
        cls = ' class="undetermined"' if (undetermined or conflict) else ""
        cells = [_num(it.get("prior")), _num(it.get("estimate")), _num(it.get("prior_sd"), 3),
                 _num(it.get("posterior_sd"), 3), _num(ratio, 2), _num(moved, 2)]
        rows.append(f'<tr{cls}><td class="param">{_e(it.get("coefficient"))}</td>'
                    + "".join(f'<td class="num">{c}</td>' for c in cells)
                    + f'<td>{_e(it.get("sentence"))}</td></tr>')
    if not rows:
        return ""
    lead = (f"<p>{n_not} of {len(rows)} anchored coefficients are not determined by the training records (posterior "
            f"sd at least 0.9 of the prior's): a prediction that depends on them extrapolates the prior. "
            f"{n_conf} moved more than two prior sd from the prior (a prior-data conflict).</p>")
    head = ("<tr><th>Coefficient</th><th class=\"num\">Prior</th><th class=\"num\">Estimate</th>"
            "<th class=\"num\">Prior sd</th><th class=\"num\">Posterior sd</th><th class=\"num\">Ratio</th>"
            "<th class=\"num\">Moved (prior sd)</th><th>What it means</th></tr>")
    foot = _defs(r, [], [("ratio", "posterior sd / prior sd: near 0 the records determine the coefficient, near 1 "
                                   "the prior does"),
                         ("moved", "(estimate - prior) / prior sd")])
    return _section("Which coefficients the records determine",
                    lead + f'<table class="params-table">\n<thead>{head}</thead>\n<tbody>\n' + "\n".join(rows)
                    + "\n</tbody></table>" + foot, "identifiability")


def _catalogue(r: dict) -> str:
    rows, notes = [], {}
    units = _dict(r.get("units"))
    has_applies = any(isinstance(c, Mapping) and "applies" in c for c in _list(r.get("catalogue")))
    for c in _list(r.get("catalogue")):
        if not isinstance(c, Mapping):
            continue
        params = c.get("parameters")
        if isinstance(params, Mapping):
            params = _params(params, units, notes)
        elif isinstance(params, (list, tuple)):
            params = ", ".join(f"{_e(p)}{' ' + _unit(p, units, notes) if _unit(p, units) else ''}" for p in params
                               if p is not None)
        else:
            params = _param_text(params, notes)
        applies = ""
        if has_applies:
            a = c.get("applies")
            if a is True or (isinstance(a, str) and a.strip().lower() == "yes"):
                applies = "<td>yes</td>"
            elif a in (None, ""):
                applies = f"<td>{NA}</td>"
            else:
                applies = f'<td class="not-applicable">no: {_e(a)}</td>' if a is not False else "<td>no</td>"
        rows.append(f'<tr><td class="effect">{_e(c.get("name"))}</td><td>{_e(c.get("physics"))}</td>'
                    f'<td>{params}</td><td>{_e(c.get("enters"))}</td>'
                    f'<td class="source">{_e(c.get("source"))}</td>{applies}</tr>')
    if not rows:
        return ""
    table = ('<table class="catalogue">\n<thead><tr><th>Effect</th><th>Physics</th><th>Parameters [unit]</th>'
             '<th>How it enters the model</th><th>Source</th>' + ("<th>Applies here</th>" if has_applies else "")
             + '</tr></thead>\n<tbody>\n' + "\n".join(rows) + "\n</tbody></table>")
    return _section("Catalogue of candidate effects", table + _unit_notes(notes), "catalogue")


_PARAM_ITEM = re.compile(r"\s*([^,\[\]]+?)\s*\[([^\[\]]*)\]\s*(?:,|$)")


def _param_text(text: Any, notes: dict) -> str:
    """A catalogue row's ``"name [unit], name [unit]"`` with its units as in the ranking (a long remark as a
    footnote number); any other text escaped as it is."""
    if not isinstance(text, str):
        return _e(text)
    items = _PARAM_ITEM.findall(text)
    if not items or "".join(_PARAM_ITEM.sub("", text).split()):
        return _e(text)
    return ", ".join(f'{_e(n)} {_unit(n, {n: u}, notes)}' for n, u in items)


def _notes(r: dict) -> str:
    items = [f"<li>{_e(n)}</li>" for n in _list(r.get("notes")) if n not in (None, "")]
    if not items:
        return ""
    return _section("Notes", "<ul>\n" + "\n".join(items) + "\n</ul>", "notes")


def _param_table(r: dict) -> str:
    """Baseline and final parameters side by side, each with its unit."""
    b, f = _dict(_dict(r.get("baseline")).get("parameters")), _dict(_dict(r.get("final")).get("parameters"))
    if not b and not f:
        return ""
    units = _dict(r.get("units"))
    names = list(dict.fromkeys([*map(str, b), *map(str, f)]))
    bk, fk = {str(k): v for k, v in b.items()}, {str(k): v for k, v in f.items()}
    rows = []
    for n in names:
        u = units.get(n)
        u = _e(u) if u not in (None, "") else '<span class="muted">not given</span>'
        dash = '<span class="muted">&ndash;</span>'
        cells = [_value(bk[n]) if n in bk else dash] + ([_value(fk[n]) if n in fk else dash] if f else [])
        rows.append(f'<tr><td class="param">{_e(n)}</td>' + "".join(f'<td class="num">{c}</td>' for c in cells)
                    + f'<td class="unit">{u}</td></tr>')
    head = '<th class="num">Baseline</th>' + ('<th class="num">Final</th>' if f else "")
    return (f'<table class="params-table">\n<thead><tr><th>Parameter</th>{head}<th>Unit</th></tr></thead>\n'
            '<tbody>\n' + "\n".join(rows) + "\n</tbody></table>")


def _data(r: dict) -> str:
    rows = []
    for key, label in (("vessel", "Vessel"), ("model", "Model"), ("structure", "Sample structure")):
        if r.get(key) not in (None, ""):
            rows.append(f"<tr><th>{label}</th><td>{_e(r.get(key))}</td></tr>")
    if r.get("mode") not in (None, ""):
        mode = r.get("mode")
        rows.append(f"<tr><th>Validation</th><td>{_e(MODES.get(str(mode), mode))}</td></tr>")
    for key, label in (("train", "Trained on"), ("validate", "Validated on")):
        recs = [x for x in _list(r.get(key)) if x not in (None, "")]
        if recs:
            lis = "".join(f"<li>{_e(x)}</li>" for x in recs)
            rows.append(f'<tr><th>{label}</th><td><ul class="records">{lis}</ul></td></tr>')
    depths = _dict(r.get("depths_h_T"))
    if depths:
        lis = "".join(f"<li>{_e(k)}: {'h/T = ' + _num(v, 3) if _finite(v) is not None else 'not given (deep water)'}"
                      f"</li>" for k, v in depths.items())
        rows.append(f'<tr><th>Water depth (h/T, depth over draft)</th><td><ul class="records">{lis}</ul></td></tr>')
    fin = _dict(r.get("final"))
    if isinstance(fin.get("effects"), list):
        eff = _names(fin.get("effects")) or '<span class="muted">none (the baseline)</span>'
        rows.append(f"<tr><th>Final model adds</th><td>{eff}</td></tr>")
    table = _param_table(r)
    if table:
        conv = _str(r.get("conventions"))
        conv = f'<p class="defs"><b>Conventions</b>: {_e(conv)}.</p>' if conv else ""
        rows.append(f'<tr><th>Parameters</th><td>{table}{conv}</td></tr>')
    if not rows:
        return ""
    return _section("Data and model", '<table class="data">\n' + "\n".join(rows) + "\n</table>", "data")


def _provenance(r: dict) -> str:
    p = _dict(r.get("provenance"))
    if not p:
        return ""
    rev = _str(p.get("revision"))
    if rev and p.get("modified") is True:
        rev += " (with local changes to tracked files)"
    rows = []
    for key, label, val in (("package", "Package", f"{_str(p.get('package'))} {_str(p.get('version'))}".strip()),
                            ("revision", "Git revision", rev or "not a git checkout"),
                            ("command", "Command line", _str(p.get("command"))),
                            ("date", "Date (UTC)", _str(p.get("date")))):
        if val:
            cls = ' class="param"' if key in ("revision", "command") else ""
            rows.append(f"<tr><th>{label}</th><td{cls}>{_e(val)}</td></tr>")
    recs = [x for x in _list(p.get("records")) if isinstance(x, Mapping)]
    if recs:
        lis = "".join(f'<tr><td>{_e(x.get("role"))}</td><td>{_e(x.get("name"))}</td>'
                      f'<td class="param sha">{_e(x.get("sha256"))}</td><td>{_e(x.get("sha256_of"))}</td></tr>'
                      for x in recs)
        rows.append('<tr><th>Records (sha256)</th><td><table class="params-table records-sha">'
                    "<thead><tr><th>Role</th><th>Record</th><th>sha256</th><th>Of</th></tr></thead>"
                    f"<tbody>{lis}</tbody></table></td></tr>")
    if not rows:
        return ""
    return _section("Provenance", '<table class="data">\n' + "\n".join(rows) + "\n</table>", "provenance")


_SECTION_HEAD = re.compile(r'<section id="([^"]+)"[^>]*>\s*<h2>(.*?)</h2>', re.S)


def _toc(parts: list) -> str:
    """The table of contents: the verdict and every rendered section, in page order, each linked to its id."""
    items = []
    for p in parts:
        if 'id="verdict"' in p:
            items.append(("verdict", "Verdict"))
        items += _SECTION_HEAD.findall(p)
    if not items:
        return ""
    lis = "".join(f'<li><a href="#{sid}">{title}</a></li>' for sid, title in items)  # already escaped
    return f'<nav id="contents" class="toc" aria-label="Contents"><h2>Contents</h2><ol>{lis}</ol></nav>'


def _definitions(r: dict) -> str:
    d = {str(k): v for k, v in _dict(r.get("definitions")).items() if isinstance(v, str) and v.strip()}
    if not d:
        return ""
    items = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in d.items())
    return _section("Definitions", f'<dl class="definitions">{items}</dl>', "definitions")


CSS = """
@page { size: A4; margin: 15mm 14mm; }
:root { color-scheme: light; }
* { box-sizing: border-box; }
html { font-size: 15px; }
body { margin: 0 auto; max-width: 64rem; padding: 1.2rem 1.4rem 3rem; color: #1b1b1b; background: #fff;
       font-family: system-ui, -apple-system, "Segoe UI", "DejaVu Sans", "Liberation Sans", Arial, sans-serif;
       line-height: 1.45; }
h1 { font-size: 1.6rem; margin: 0 0 .3rem; }
h2 { font-size: 1.2rem; margin: 1.8rem 0 .6rem; padding-bottom: .2rem; border-bottom: 1px solid #bbb; }
h3 { font-size: 1.02rem; margin: 1.2rem 0 .5rem; }
p { margin: .4rem 0; }
.summary { color: #444; margin-bottom: .8rem; }
.summary span { white-space: nowrap; }
.verdict, .alert { border: 2px solid #555; border-left-width: 8px; background: #f4f4f4; padding: .7rem 1rem;
                   margin: .8rem 0 1rem; }
.verdict.found { border-color: #1d6b3a; background: #eef6f0; }
.verdict.ambiguous { border-color: #9a6a00; background: #fbf5e6; }
.verdict.none { border-color: #44546a; background: #f1f3f6; }
.verdict.diverged, .alert { border-color: #b00020; background: #fdecee; }
.verdict.diverged .headline { font-size: 1.3rem; color: #7a0016; }
.diverged-word, .alert .headline strong { color: #b00020; letter-spacing: .04em; }
.verdict .headline, .alert .headline { font-size: 1.15rem; margin: 0; }
.verdict .verdict-text { margin: .4rem 0 0; }
.verdict .defs, .alert .defs { margin-top: .5rem; }
ul.div-list { margin: .3rem 0; padding-left: 1.3rem; }
.detail { font-size: .92rem; color: #333; font-weight: normal; }
.stability { color: #1d4f6b; }
.conventions { font-size: .9rem; color: #333; background: #f6f7f9; border: 1px solid #d9dde3; padding: .45rem .7rem;
               margin: .6rem 0 1rem; }
table { border-collapse: collapse; width: 100%; margin: .4rem 0 .3rem; font-size: .92rem; }
th, td { border-bottom: 1px solid #d4d4d4; padding: .3rem .45rem; text-align: left; vertical-align: top; }
thead th { border-bottom: 2px solid #777; background: #f6f6f6; font-weight: 600; }
td { overflow-wrap: break-word; }
table.ladder td:first-child { white-space: nowrap; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; }
td.num { white-space: nowrap; overflow-wrap: normal; }
td.params, .param { font-variant-numeric: tabular-nums; font-family: ui-monospace, "DejaVu Sans Mono",
                    "Liberation Mono", monospace; font-size: .85rem; overflow-wrap: normal; }
.param { white-space: nowrap; }
span.unit { font-family: system-ui, -apple-system, "Segoe UI", "DejaVu Sans", sans-serif; font-size: .8rem;
             color: #555; display: inline-block; }
td.params { line-height: 1.35; }
td.effect { font-weight: 600; overflow-wrap: normal; }
td.source { font-size: .85rem; color: #333; }
td.not-applicable { color: #8a4b00; font-size: .88rem; }
tr.significant td { background: #eef6f0; }
tr.significant td:first-child { box-shadow: inset 4px 0 0 #1d6b3a; }
tr.chosen td.effect::after { content: " \\2190 missing effect"; font-weight: normal; color: #1d6b3a;
                             font-size: .85rem; }
tr.diverged-row td { background: #fdecee; }
tr.undetermined td { background: #fff6e0; }
tr.rejected td { background: repeating-linear-gradient(135deg, #fff 0, #fff 6px, #f1f1f1 6px, #f1f1f1 9px);
                 color: #555; }
.dv { color: #b00020; font-weight: 700; text-transform: uppercase; letter-spacing: .03em; font-size: .88em; }
.rejected-word { color: #8a4b00; font-weight: 700; }
td.status { font-size: .88rem; }
.sig { color: #1d6b3a; font-weight: 700; white-space: nowrap; }
.muted { color: #777; }
.legend { font-size: .88rem; color: #444; }
.defs { font-size: .84rem; color: #444; margin: .25rem 0 .35rem; }
ul.defs { list-style: none; padding-left: 0; }
ul.defs li { margin: .12rem 0; }
ul.na { font-size: .88rem; color: #444; margin-top: .1rem; }
td.fallcell { min-width: 9.5rem; }
.fall { display: inline-flex; align-items: center; gap: .45rem; justify-content: flex-end; }
.fall .track { display: inline-block; width: 5rem; height: .8rem; background: #f0f0f0; position: relative; }
.fall .bar { position: absolute; left: 0; top: 0; bottom: 0; background: #7fb893; }
.fall .bartext { min-width: 3.6rem; text-align: right; }
table.data > tbody > tr > th, table.data > tr > th { width: 12rem; background: #f6f6f6; font-weight: 600;
                                                     border-bottom: 1px solid #d4d4d4; }
table.params-table { width: auto; min-width: 60%; margin: 0 0 .3rem; font-size: .86rem; }
table.params-table td.param { white-space: nowrap; }
table.params-table td.unit { font-size: .82rem; }
table.maneuver-metrics td.metric { white-space: nowrap; }
ul.records { margin: 0; padding-left: 1.1rem; }
dl.definitions { font-size: .9rem; }
dl.definitions dt { font-weight: 600; margin-top: .4rem; }
dl.definitions dd { margin: .1rem 0 0 1.2rem; }
figure { margin: .8rem 0 1.4rem; padding: 0; break-inside: avoid; page-break-inside: avoid; }
figure img { display: block; max-width: 100%; height: auto; margin: 0 auto; border: 1px solid #e2e2e2; }
figcaption { font-size: .9rem; color: #333; margin-top: .35rem; }
.missing-figure { border: 1px dashed #999; padding: 1rem; color: #666; text-align: center; }
.section-error { color: #8a1c1c; font-size: .9rem; }
ol.worst li { margin: .15rem 0; }
nav.toc { font-size: .9rem; background: #f6f7f9; border: 1px solid #d9dde3; padding: .3rem .9rem .5rem;
          margin: .6rem 0 1rem; }
nav.toc h2 { font-size: 1rem; margin: .3rem 0; border: none; }
nav.toc ol { margin: 0; padding-left: 1.4rem; columns: 2; }
td.sha { font-size: .75rem; overflow-wrap: anywhere; white-space: normal; }
@media print { nav.toc { display: none; } }
footer { margin-top: 2rem; padding-top: .5rem; border-top: 1px solid #ccc; font-size: .85rem; color: #555; }
@media (max-width: 40rem) { html { font-size: 14px; } table { display: block; overflow-x: auto; } }
@media print {
  html { font-size: 10pt; }
  table { font-size: .88rem; }
  body { max-width: none; padding: 0; }
  * { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
  h2, h3 { break-after: avoid; page-break-after: avoid; }
  tr, .verdict, .alert { break-inside: avoid; page-break-inside: avoid; }
  thead { display: table-header-group; }
  figure img { max-height: 22cm; width: auto; }
  section#figures { break-before: auto; }
}
"""

# the page may load nothing from anywhere: images are data: URIs, styles inline, no scripts at all
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'; base-uri 'none'; form-action 'none'"


def _safe(fn: Callable[..., str], *args: Any) -> str:
    """A section, or a short note in its place when the report's contents are too odd to render."""
    try:
        return fn(*args)
    except Exception as exc:  # noqa: BLE001 - a report page is always produced
        name = fn.__name__.strip("_")
        return (f'<p class="section-error">Section "{_e(name)}" could not be rendered '
                f"({_e(type(exc).__name__)}: {_e(exc)}).</p>")


def _uncertainty_css() -> str:
    from .html_uncertainty import CSS as UNCERTAINTY_CSS

    return UNCERTAINTY_CSS


def render_html(report: Mapping | None, figures: Mapping[str, bytes] | None = None) -> str:
    """The self-contained HTML5 page of a doctor's report.

    ``report`` is the dict written to ``report.json`` (any key may be missing or empty); ``figures`` maps a
    figure's file name (as in ``report["figures"][i]["file"]``) to its PNG bytes, embedded as data URIs.
    """
    r = _dict(report)
    figs = {str(k): v for k, v in _dict(figures).items()}
    title = r.get("title") if r.get("title") not in (None, "") else "Model doctor report"
    parts = [
        _safe(_summary, r),
        _safe(_verdict, r),
        _safe(_divergence, r),
        _safe(_conventions, r),
        _safe(_ladder, r),
        _safe(_ranking, r),
        _safe(_errors, r),
        _safe(_maneuvers, r),
        _safe(_uncertainty, r),
        _safe(_identifiability, r),
        _safe(_figures, r, figs),
        _safe(_worst, r),
        _safe(_catalogue, r),
        _safe(_notes, r),
        _safe(_data, r),
        _safe(_definitions, r),
        _safe(_provenance, r),
    ]
    toc = _toc(parts)
    body = "\n".join(p for p in parts[:2] + [toc] + parts[2:] if p)
    footer = ""
    if r.get("created_by") not in (None, ""):
        footer = f'<footer>Created by {_e(r.get("created_by"))}.</footer>'
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta http-equiv="Content-Security-Policy" content="{CSP}">
<meta name="generator" content="study.doctor.html">
<title>{_e(title)}</title>
<style>{CSS}{_uncertainty_css()}</style>
</head>
<body>
<header>
<h1>{_e(title)}</h1>
</header>
<main>
{body}
</main>
{footer}
</body>
</html>
"""
