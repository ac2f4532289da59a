"""The report page's section on how far the predictions can be trusted (``prediction_uncertainty`` in
``report.json``, ``study.doctor.uncertainty``): the plain summary first (which predictions extrapolate, how far,
in which states, and which coefficients carry them), then the predicted 35 deg turns with their intervals, the
validation metrics' intervals and carriers, the calibration of the extrapolation error, the models counted as
indistinguishable, and the method with what it does not cover. Every string escaped; any key may be missing."""
from __future__ import annotations

import html
import math
from collections.abc import Mapping


PARTS = (("s_id", "identification"), ("s_struct", "structure"), ("s_extrap", "extrapolation"))
TITLE = "How far the predictions can be trusted"


def _e(x) -> str:
    return "" if x is None else html.escape(str(x), quote=True)


def _finite(x) -> float | None:
    """``x`` as a finite float, else None (bools and strings are no numbers here)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    return float(x) if math.isfinite(x) else None


def _num(x, digits: int = 4) -> str:
    v = _finite(x)
    return "n/a" if v is None else f"{v:.{digits}g}"


def _list(x) -> list:
    return list(x) if isinstance(x, (list, tuple)) else []


def _dict(x) -> dict:
    return dict(x) if isinstance(x, Mapping) else {}


def interval_text(low, high) -> str:
    """``low-high`` to 3-4 significant digits, '' when either is not a finite number."""
    lo, hi = _finite(low), _finite(high)
    return f"{_num(lo)}&ndash;{_num(hi)}" if lo is not None and hi is not None else ""


def _parts(u: Mapping) -> str:
    out = []
    for k, name in PARTS:
        x = _finite(u.get(k))
        out.append(f"{name} {100 * x:.1f} %" if x is not None else f"{name} n/a")
    why, caveat = u.get("why"), u.get("caveat")
    return ", ".join(out) + (f" ({_e(why)})" if why else "") + (f'<br><span class="caveat">{_e(caveat)}</span>'
                                                                 if caveat else "")


def _carriers(cs) -> str:
    items = [f"<li>{_e(c.get('sentence'))}</li>" for c in _list(cs) if isinstance(c, Mapping)]
    return f'<ul class="carriers">{"".join(items)}</ul>' if items else '<span class="muted">none above 5 %</span>'


def _turns(sec: Mapping) -> str:
    out = []
    for t in _list(sec.get("predicted_turns")):
        if not isinstance(t, Mapping):
            continue
        head = f"<h3>{_e(t.get('maneuver'))}</h3>"
        if t.get("why"):
            out.append(head + f"<p class=\"muted\">Not predicted: {_e(t['why'])}</p>")
            continue
        ex = _dict(t.get("extrapolation"))
        cls = "extrapolates" if str(ex.get("text", "")).startswith("EXTRAPOLATES") else "inside"
        lead = (f'<p class="{cls}">{_e(ex.get("text"))} (distance {_num(ex.get("distance"), 3)}).</p>'
                f'<p class="legend">From a steady approach at {_num(t.get("u0"), 4)} m/s, propeller at '
                f'{_num(t.get("n"), 4)} rps (the model\'s own self-propulsion point)'
                + (f"; set-up effects left out: {_e(', '.join(map(str, t['setup_left_out'])))}"
                   if t.get("setup_left_out") else "") + ".</p>")
        rows = []
        for m, d in _dict(t.get("metrics")).items():
            d = _dict(d)
            rows.append(f'<tr><td class="metric">{_e(m)}</td><td class="num">{_num(d.get("value"))}</td>'
                        f'<td class="num">{interval_text(d.get("low"), d.get("high"))}</td>'
                        f'<td class="parts">{_parts(d)}</td><td>{_carriers(d.get("carriers"))}</td></tr>')
        table = ('<table class="uncertainty"><thead><tr><th>Metric [L]</th><th class="num">Predicted</th>'
                 '<th class="num">90 % interval</th><th>Parts (sd of the log)</th><th>Carried by</th></tr></thead>'
                 f'<tbody>{"".join(rows)}</tbody></table>')
        alts = ", ".join(map(str, _list(t.get("alternatives")))) or "none"
        out.append(head + lead + table + f'<p class="legend">Models counted as indistinguishable: {_e(alts)}.</p>')
    return "".join(out)


def _validation(r: Mapping, sec: Mapping) -> str:
    recs = _dict(_dict(sec.get("final")).get("records"))
    lines = [f"<li><b>{_e(n)}</b>: {_e(_dict(x).get('text'))}</li>" for n, x in recs.items()]
    rows = []
    for m in _list(r.get("maneuver_metrics")):
        if not isinstance(m, Mapping) or m.get("unit") == "m" or "final_uncertainty" not in m:
            continue  # the metres rows repeat the ship lengths' ones
        u = _dict(m.get("final_uncertainty"))
        lo, hi, meas = _finite(m.get("final_low")), _finite(m.get("final_high")), _finite(m.get("measured"))
        held = "" if None in (lo, hi, meas) else ("yes" if lo <= meas <= hi else "<b>no</b>")
        rows.append(f'<tr><td class="record">{_e(m.get("record"))}</td><td class="metric">{_e(m.get("metric"))}</td>'
                    f'<td class="num">{_num(m.get("measured"))}</td><td class="num">{_num(m.get("final"))}</td>'
                    f'<td class="num">{interval_text(lo, hi)}</td><td>{held}</td><td class="parts">{_parts(u)}</td>'
                    f'<td>{_carriers(m.get("carriers"))}</td></tr>')
    if not rows and not lines:
        return ""
    table = ('<table class="uncertainty"><thead><tr><th>Record</th><th>Metric</th><th class="num">Measured</th>'
             '<th class="num">Final</th><th class="num">90 % interval</th><th>Holds it</th><th>Parts (sd of the '
             'log)</th><th>Carried by</th></tr></thead>' + f'<tbody>{"".join(rows)}</tbody></table>') if rows else ""
    return ("<h3>The validation records</h3>" + (f'<ul class="extrapolation">{"".join(lines)}</ul>' if lines else "")
            + table)


def _calibration(sec: Mapping) -> str:
    out = []
    for role in ("final", "baseline"):
        part = _dict(sec.get(role))
        g = _dict(_dict(part.get("calibration")).get("growth"))
        if not g:
            continue
        pairs = [p for p in _list(_dict(part.get("calibration")).get("pairs")) if isinstance(p, Mapping)]
        out.append(f"<li><b>{role}</b>: floor s0 = {_num(g.get('sigma0'), 3)}, growth k = {_num(g.get('k'), 3)} per "
                   f"unit distance, from {_e(g.get('n'))} held-out records' RMS yaw rate at speed ({len(pairs)} "
                   f"held-out replays, farthest {_num(g.get('d_max'), 3)} outside its training envelope)"
                   + (f"; {_e(g.get('note'))}" if g.get("note") else "") + ". Indistinguishable models: "
                   + _e(", ".join(map(str, _list(part.get("alternatives")))) or "none") + ".</li>")
        excl = [str(x) for x in _list(part.get("excluded"))]
        if excl:
            out.append(f'<li class="muted">{role}, not counted: {_e("; ".join(excl))}.</li>')
        for n in _list(part.get("notes")):
            out.append(f'<li class="muted">{_e(n)}</li>')
    return f"<h3>Calibration and alternatives</h3><ul>{''.join(out)}</ul>" if out else ""


def uncertainty_section(r: Mapping) -> str:
    """The section's body (empty when the report has no ``prediction_uncertainty``); its title is ``TITLE``."""
    sec = _dict(r.get("prediction_uncertainty"))
    if not sec:
        return ""
    summ = "".join(f"<li>{_e(s)}</li>" for s in _list(sec.get("summary")))
    body = (f'<ul class="summary-list">{summ}</ul>' if summ else "") + _turns(sec) + _validation(r, sec) + \
        _calibration(sec) + f'<p class="defs"><b>How the interval is built</b>: {_e(sec.get("method"))}</p>'
    return body


CSS = """
table.uncertainty td.parts { font-size: .82rem; color: #333; min-width: 11rem; }
table.uncertainty ul.carriers { margin: 0; padding-left: 1rem; font-size: .82rem; }
p.extrapolates { color: #7a0016; font-weight: 600; }
span.interval { font-size: .8rem; color: #555; }
span.caveat { color: #8a4b00; }
"""

