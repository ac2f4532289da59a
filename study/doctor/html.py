"""The model doctor's report as one self-contained HTML5 page.

:func:`render_html` turns the report dict written to ``report.json`` (see :mod:`.diagnose`) and the figures'
PNG bytes into a page that needs nothing else: CSS inline, images as ``data:`` URIs, no JavaScript, and a
Content-Security-Policy that forbids the browser any request (so nothing can leak from, or be fetched by, a
report that is mailed around). Every string from the report is escaped (record names come from users' files);
every key may be missing, empty or of an odd type: what is there is rendered, a section that still cannot be
rendered says so in place, and the page is always produced.

Layout, for a naval architect reading on a laptop or on A4 paper: the verdict at the top, the error ladder
right under it, the ranked candidate effects (``<table id="ranking">``, one ``<tr class="candidate">`` each),
the per-record errors, the figures grouped by section, the worst windows, the catalogue of effects, the notes,
and what was trained and validated on.
"""
from __future__ import annotations

import base64
import html
import math
import numbers
from collections.abc import Callable, Iterable, Mapping
from typing import Any

__all__ = ["fmt_num", "fmt_pct", "render_html"]

NA = "n/a"

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
    """A number with ``digits`` significant digits; NaN, None and non-numbers -> ``"n/a"`` (plain text)."""
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


def _params(p: Any) -> str:
    """Parameters as ``name = value`` lines, 4 significant digits."""
    d = _dict(p)
    if not d:
        return ""
    items = [f'<span class="param">{_e(k)}&nbsp;=&nbsp;{_e(fmt_num(v))}</span>' for k, v in d.items()]
    return "<br>".join(items)


def _names(xs: Any) -> str:
    return ", ".join(_e(x) for x in _list(xs) if x is not None and str(x) != "")


# --------------------------------------------------------------------------------------------- sections


def _section(title: str, body: str, sid: str, cls: str = "") -> str:
    c = f' class="{cls}"' if cls else ""
    return f'<section id="{sid}"{c}>\n<h2>{_e(title)}</h2>\n{body}\n</section>'


def _verdict(r: dict) -> str:
    missing = r.get("missing_effect")
    missing = None if missing is None or str(missing).strip() == "" else str(missing)
    ambiguous = [str(a) for a in _list(r.get("ambiguous")) if a is not None and str(a) != ""]
    ranking = [c for c in _list(r.get("ranking")) if isinstance(c, Mapping)]

    if missing is not None:
        cand = next((c for c in ranking if str(c.get("effect")) == missing), None)
        detail = ""
        if cand is not None:
            bits = []
            if _float(cand.get("improvement")) is not None:
                bits.append(f"validation error down by {_e(fmt_pct(cand.get('improvement')))}")
            pv = _float(cand.get("p_value"))
            if pv is not None and not math.isnan(pv):
                bits.append(f"p {_fmt_p(pv)}" if pv < 1e-3 else f"p = {_fmt_p(pv)}")
            if bits:
                detail = f' <span class="detail">({"; ".join(bits)})</span>'
        head = f'Missing effect: <strong class="missing">{_e(missing)}</strong>{detail}'
        if ambiguous:
            others = [a for a in ambiguous if a != missing]
            if others:
                head += f'<br><span class="detail">Not separable from: {_names(others)}</span>'
        cls = "verdict found"
    elif ambiguous:
        head = ("Ambiguous: the records do not separate "
                + " / ".join(f"<strong>{_e(a)}</strong>" for a in ambiguous))
        cls = "verdict ambiguous"
    elif "missing_effect" in r or ranking:
        head = "<strong>No significant missing effect</strong>"
        cls = "verdict none"
    else:
        head = ""
        cls = "verdict unknown"

    text = r.get("verdict")
    text = f'<p class="verdict-text">{_e(text)}</p>' if text not in (None, "") else ""
    if not head and not text:
        text = '<p class="verdict-text">No verdict in this report.</p>'
    head = f'<p class="headline">{head}</p>' if head else ""
    return f'<div class="{cls}" id="verdict" role="status">\n{head}\n{text}\n</div>'


def _summary(r: dict) -> str:
    rows = []
    for key, label in (("vessel", "Vessel"), ("model", "Model"), ("structure", "Structure")):
        if r.get(key) not in (None, ""):
            rows.append(f"<span><b>{label}:</b> {_e(r.get(key))}</span>")
    mode = r.get("mode")
    if mode not in (None, ""):
        rows.append(f"<span><b>Validation:</b> {_e(MODES.get(str(mode), mode))}</span>")
    return f'<p class="summary">{" &middot; ".join(rows)}</p>' if rows else ""


def _baseline_val(r: dict) -> float | None:
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


def _ladder(r: dict) -> str:
    steps = [s for s in _list(r.get("ladder")) if isinstance(s, Mapping)]
    if not steps:
        return ""
    base = _baseline_val(r)
    body = []
    for s in steps:
        v = _float(s.get("validation_error"))
        if base is not None and v is not None and math.isfinite(v):
            fall = (base - v) / base
            width = max(0.0, min(1.0, fall)) * 100.0
            fall_txt = (f'<span class="bar" style="width:{width:.1f}%"></span>'
                        f'<span class="bartext">{_e(fmt_pct(fall))}</span>')
        else:
            fall_txt = NA
        effects = _names(s.get("effects")) or '<span class="muted">none</span>'
        body.append(f'<tr><td>{_e(s.get("step"))}</td><td>{effects}</td>'
                    f'<td class="num">{_e(fmt_num(s.get("validation_error")))}</td>'
                    f'<td class="num">{_e(fmt_num(s.get("training_error")))}</td>'
                    f'<td class="num fall">{fall_txt}</td></tr>')
    table = ('<table class="ladder">\n<thead><tr><th>Step</th><th>Effects added</th>'
             '<th class="num">Validation error</th><th class="num">Training error</th>'
             '<th class="num">Fall of validation error vs baseline</th></tr></thead>\n<tbody>\n'
             + "\n".join(body) + "\n</tbody></table>")
    return _section("Error ladder", table, "ladder")


def _ranking(r: dict) -> str:
    cands = _list(r.get("ranking"))
    b = _dict(r.get("baseline"))
    missing = r.get("missing_effect")
    rows = []
    for i, c in enumerate(cands, 1):
        c = c if isinstance(c, Mapping) else {"effect": c}
        sig = c.get("significant") is True or (
            not isinstance(c.get("significant"), (str, type(None))) and bool(c.get("significant")))
        cls = "candidate significant" if sig else "candidate"
        if missing is not None and str(c.get("effect")) == str(missing):
            cls += " chosen"
        mark = ('<span class="sig" title="significant">&#10003; significant</span>' if sig
                else '<span class="muted">no</span>')
        rows.append(f'<tr class="{cls}"><td class="num">{i}</td><td class="effect">{_e(c.get("effect"))}</td>'
                    f'<td class="num">{_e(fmt_num(c.get("validation_error")))}</td>'
                    f'<td class="num">{_e(fmt_pct(c.get("improvement")))}</td>'
                    f'<td>{mark}</td><td class="num">{_fmt_p(c.get("p_value"))}</td>'
                    f'<td class="params">{_params(c.get("parameters"))}</td><td>{_e(c.get("note"))}</td></tr>')
    if not rows and not b:
        return ""
    base_line = ""
    if b:
        base_line = (f'<p>Baseline (no added effect): validation error '
                     f'<b>{_e(fmt_num(b.get("validation_error")))}</b>, training error '
                     f'{_e(fmt_num(b.get("training_error")))}.</p>')
    if not rows:
        return _section("Candidate effects", base_line + '<p class="muted">No candidate was tried.</p>',
                        "candidates")
    table = ('<table id="ranking" class="ranking">\n<thead><tr><th class="num">#</th><th>Effect</th>'
             '<th class="num">Validation error</th><th class="num">Improvement</th><th>Significant</th>'
             '<th class="num">p&#8209;value</th><th>Identified parameters</th><th>Note</th></tr></thead>\n<tbody>\n'
             + "\n".join(rows) + "\n</tbody></table>")
    legend = ('<p class="legend">Candidates ranked by out-of-sample improvement: each effect is added alone to '
              'the baseline, identified on the training records and judged on the validation records. '
              '<span class="sig">&#10003; significant</span> rows are highlighted.</p>')
    return _section("Candidate effects", base_line + legend + table, "candidates")


def _errors(r: dict) -> str:
    rows = []
    for e in _list(r.get("errors_table")):
        if not isinstance(e, Mapping):
            continue
        b, f = _float(e.get("baseline_nrmse")), _float(e.get("final_nrmse"))
        if b is not None and f is not None and math.isfinite(b) and math.isfinite(f) and b != 0.0:
            change = fmt_pct((f - b) / b)
            if not change.startswith("-") and change != NA:
                change = "+" + change
        else:
            change = NA
        unit = f" [{_e(e.get('unit'))}]" if e.get("unit") not in (None, "") else ""
        rows.append(f'<tr><td>{_e(e.get("record"))}</td><td>{_e(e.get("channel"))}{unit}</td>'
                    f'<td class="num">{_e(fmt_num(e.get("baseline_rmse")))}</td>'
                    f'<td class="num">{_e(fmt_num(e.get("final_rmse")))}</td>'
                    f'<td class="num">{_e(fmt_num(e.get("baseline_nrmse")))}</td>'
                    f'<td class="num">{_e(fmt_num(e.get("final_nrmse")))}</td>'
                    f'<td class="num">{_e(change)}</td></tr>')
    if not rows:
        return ""
    table = ('<table class="errors">\n<thead><tr><th>Record</th><th>Channel [unit]</th>'
             '<th class="num">RMSE baseline</th><th class="num">RMSE final</th>'
             '<th class="num">NRMSE baseline</th><th class="num">NRMSE final</th>'
             '<th class="num">NRMSE change</th></tr></thead>\n<tbody>\n' + "\n".join(rows) + "\n</tbody></table>")
    return _section("Errors per record and channel", table, "errors")


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


def _figure(meta: Mapping, data: Any) -> str:
    file = meta.get("file")
    title = meta.get("title")
    caption = meta.get("caption")
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
        figs = "\n".join(_figure(m, figures.get(str(m.get("file")))) for m in groups[sec])
        parts.append(f'<div class="figgroup" data-section="{_e(sec)}">\n<h3>{_e(heading)}</h3>\n{figs}\n</div>')
    return _section("Figures", "\n".join(parts), "figures")


def _worst(r: dict) -> str:
    items = []
    for w in _list(r.get("worst_windows")):
        if not isinstance(w, Mapping):
            continue
        items.append(f'<li><b>{_e(w.get("record"))}</b>, t = {_fmt_time(w.get("t_start"))} to '
                     f'{_fmt_time(w.get("t_end"))} s: NRMSE {_e(fmt_num(w.get("nrmse")))}</li>')
    if not items:
        return ""
    return _section("Worst windows of the baseline", '<ol class="worst">\n' + "\n".join(items) + "\n</ol>",
                    "worst")


def _catalogue(r: dict) -> str:
    rows = []
    for c in _list(r.get("catalogue")):
        if not isinstance(c, Mapping):
            continue
        params = c.get("parameters")
        if isinstance(params, Mapping):
            params = _params(params)
        elif isinstance(params, (list, tuple)):
            params = _names(params)
        else:
            params = _e(params)
        rows.append(f'<tr><td class="effect">{_e(c.get("name"))}</td><td>{_e(c.get("physics"))}</td>'
                    f'<td>{params}</td><td>{_e(c.get("enters"))}</td>'
                    f'<td class="source">{_e(c.get("source"))}</td></tr>')
    if not rows:
        return ""
    table = ('<table class="catalogue">\n<thead><tr><th>Effect</th><th>Physics</th><th>Parameters</th>'
             '<th>How it enters the model</th><th>Source</th></tr></thead>\n<tbody>\n'
             + "\n".join(rows) + "\n</tbody></table>")
    return _section("Catalogue of candidate effects", table, "catalogue")


def _notes(r: dict) -> str:
    items = [f"<li>{_e(n)}</li>" for n in _list(r.get("notes")) if n not in (None, "")]
    if not items:
        return ""
    return _section("Notes", "<ul>\n" + "\n".join(items) + "\n</ul>", "notes")


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
    b = _dict(r.get("baseline"))
    if _dict(b.get("parameters")):
        rows.append(f'<tr><th>Baseline parameters</th><td class="params">{_params(b.get("parameters"))}</td></tr>')
    if not rows:
        return ""
    return _section("Data and model", '<table class="data">\n' + "\n".join(rows) + "\n</table>", "data")


CSS = """
@page { size: A4; margin: 15mm 14mm; }
:root { color-scheme: light; }
* { box-sizing: border-box; }
html { font-size: 15px; }
body { margin: 0 auto; max-width: 62rem; padding: 1.2rem 1.4rem 3rem; color: #1b1b1b; background: #fff;
       font-family: system-ui, -apple-system, "Segoe UI", "DejaVu Sans", "Liberation Sans", Arial, sans-serif;
       line-height: 1.45; }
h1 { font-size: 1.6rem; margin: 0 0 .3rem; }
h2 { font-size: 1.2rem; margin: 1.8rem 0 .6rem; padding-bottom: .2rem; border-bottom: 1px solid #bbb; }
h3 { font-size: 1.02rem; margin: 1.2rem 0 .5rem; }
p { margin: .4rem 0; }
.summary { color: #444; margin-bottom: .8rem; }
.summary span { white-space: nowrap; }
.verdict { border: 2px solid #555; border-left-width: 8px; background: #f4f4f4; padding: .7rem 1rem;
           margin: .8rem 0 1rem; }
.verdict.found { border-color: #1d6b3a; background: #eef6f0; }
.verdict.ambiguous { border-color: #9a6a00; background: #fbf5e6; }
.verdict.none { border-color: #44546a; background: #f1f3f6; }
.verdict .headline { font-size: 1.15rem; margin: 0; }
.verdict .verdict-text { margin: .4rem 0 0; }
.detail { font-size: .92rem; color: #333; font-weight: normal; }
table { border-collapse: collapse; width: 100%; margin: .4rem 0 .8rem; font-size: .92rem; }
th, td { border-bottom: 1px solid #d4d4d4; padding: .3rem .45rem; text-align: left; vertical-align: top; }
thead th { border-bottom: 2px solid #777; background: #f6f6f6; font-weight: 600; }
td { overflow-wrap: anywhere; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; }
td.num { white-space: nowrap; overflow-wrap: normal; }
td.params, .param { font-variant-numeric: tabular-nums; font-family: ui-monospace, "DejaVu Sans Mono",
                    "Liberation Mono", monospace; font-size: .85rem; overflow-wrap: normal; }
.param { white-space: nowrap; }
td.effect { font-weight: 600; overflow-wrap: normal; }
td.source { font-size: .85rem; color: #333; }
tr.significant td { background: #eef6f0; }
tr.significant td:first-child { box-shadow: inset 4px 0 0 #1d6b3a; }
tr.chosen td.effect::after { content: " \\2190 missing effect"; font-weight: normal; color: #1d6b3a;
                             font-size: .85rem; }
.sig { color: #1d6b3a; font-weight: 700; white-space: nowrap; }
.muted { color: #777; }
.legend { font-size: .88rem; color: #444; }
td.fall { position: relative; min-width: 7rem; }
td.fall .bar { position: absolute; left: .45rem; top: .35rem; bottom: .35rem; max-width: calc(100% - .9rem);
               background: #cfe5d6; }
td.fall .bartext { position: relative; }
table.data th { width: 12rem; background: #f6f6f6; font-weight: 600; border-bottom: 1px solid #d4d4d4; }
ul.records { margin: 0; padding-left: 1.1rem; }
figure { margin: .8rem 0 1.4rem; padding: 0; break-inside: avoid; page-break-inside: avoid; }
figure img { display: block; max-width: 100%; height: auto; margin: 0 auto; border: 1px solid #e2e2e2; }
figcaption { font-size: .9rem; color: #333; margin-top: .35rem; }
.missing-figure { border: 1px dashed #999; padding: 1rem; color: #666; text-align: center; }
.section-error { color: #8a1c1c; font-size: .9rem; }
ol.worst li { margin: .15rem 0; }
footer { margin-top: 2rem; padding-top: .5rem; border-top: 1px solid #ccc; font-size: .85rem; color: #555; }
@media (max-width: 40rem) { html { font-size: 14px; } table { display: block; overflow-x: auto; } }
@media print {
  html { font-size: 10pt; }
  table { font-size: .88rem; }
  body { max-width: none; padding: 0; }
  * { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
  h2, h3 { break-after: avoid; page-break-after: avoid; }
  tr, .verdict { break-inside: avoid; page-break-inside: avoid; }
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
        _safe(_ladder, r),
        _safe(_ranking, r),
        _safe(_errors, r),
        _safe(_figures, r, figs),
        _safe(_worst, r),
        _safe(_catalogue, r),
        _safe(_notes, r),
        _safe(_data, r),
    ]
    body = "\n".join(p for p in parts if p)
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
<style>{CSS}</style>
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
