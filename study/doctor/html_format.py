"""What the report page's view data (:mod:`.html_view`) is built from: the formatting of numbers and
units, and which replays diverged, read from a :class:`.report_schema.Report` (whose schema says
each key's type).

Numbers are formatted here: 4 significant digits, ``n/a`` for a missing or not-a-number value; an
error figure of a diverged replay (or an infinite one) is the word ``diverged`` (:data:`DIVERGED`),
never a number; ``inf`` is never shown.
"""
from __future__ import annotations

import math
import numbers
import re
from collections.abc import Iterable, Mapping
from typing import Any

from .report_schema import Report

NA = "n/a"
#: a cell's text that the templates show as the diverged mark
DIVERGED = "diverged"

#: figure sections in display order, with their headings; any other section follows, in order of appearance
SECTIONS: dict[str, str] = {"compare": "Model against measurements", "intervals": "Manoeuvre metrics and their intervals",
                            "residuals": "Residuals", "growth": "Error growth", "ladder": "Error ladder"}
MODES = {"given": "validation records given by the user", "held_out": "validation records held out by the doctor"}
#: the sections' titles (the table of contents shows the same)
TITLES = {"ladder": "Error ladder", "candidates": "Candidate effects", "errors": "Errors per record and channel",
          "maneuvers": "Manoeuvres in the ship's terms", "uncertainty": "How far the predictions can be trusted",
          "identifiability": "Which coefficients the records determine", "figures": "Figures",
          "separating": "The manoeuvre that would tell them apart",
          "rudder_residual": "Residual yaw moment against the rudder angle", "worst": "Worst windows of the baseline", "catalogue": "Catalogue of candidate effects", "notes": "Notes",
          "data": "Data and model", "definitions": "Definitions", "provenance": "Provenance"}
STABILITY_DEF = ("how many of the n refits, each with one validation record left out, name the same effect at "
                 "this step")
REJECTED_DEF = ("a step whose validation error is not below the previous step's (or whose replay diverges) is "
                "rejected: the ladder stops before it")

# --------------------------------------------------------------------------------------------- formatting


def as_float(x: Any) -> float | None:
    """``x`` as a float, or None when it is not a number (bools are not numbers here)."""
    if x is None or isinstance(x, bool):
        return None
    try:  # numbers, numeric strings, numpy scalars
        return float(x.strip() if isinstance(x, str) else x)
    except (TypeError, ValueError, OverflowError):
        return None


def finite(x: Any) -> float | None:
    v = as_float(x)
    return v if v is not None and math.isfinite(v) else None


def fmt_num(x: Any, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; NaN, None and non-numbers -> ``"n/a"``.
    ``inf`` stays ``"inf"`` here; the page never shows it (an infinite error is a diverged
    replay, see :func:`err`)."""
    v = as_float(x)
    if v is None or math.isnan(v):
        return NA
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{digits}g}"


def fmt_pct(frac: Any, decimals: int = 1) -> str:
    """A fraction as a percentage (0.62 -> ``"62.0 %"``); NaN, None and non-numbers -> ``"n/a"``."""
    v = as_float(frac)
    if v is None or math.isnan(v):
        return NA
    if math.isinf(v):
        return "inf %" if v > 0 else "-inf %"
    return f"{100.0 * v:.{decimals}f} %"


def num(x: Any, digits: int = 4) -> str:
    """A number as the page shows it: never ``inf`` (-> n/a)."""
    v = finite(x)
    return NA if v is None else fmt_num(v, digits)


def err(x: Any, diverged: bool = False) -> str:
    """An error figure: ``diverged`` when the replay diverged or the value is infinite, else
    :func:`num`."""
    v = as_float(x)
    return DIVERGED if diverged or (v is not None and math.isinf(v)) else num(x)


def pct(x: Any, diverged: bool = False) -> str:
    if diverged:
        return DIVERGED
    v = finite(x)
    return NA if v is None else fmt_pct(v)


def fmt_p(p: Any) -> str:
    v = as_float(p)
    if v is None or math.isnan(v):
        return NA
    return "< 0.001" if v < 1e-3 else f"{v:.2g}"


def metric_num(x: Any) -> str:
    """A manoeuvre metric: 3-4 significant digits; NaN, None, inf and non-numbers -> 'n/a'."""
    if x is None or isinstance(x, bool) or not isinstance(x, numbers.Real) or not math.isfinite(float(x)):
        return NA
    v = float(x)
    return "0" if v == 0 else f"{v:.0f}" if 1e4 <= abs(v) < 1e9 else f"{v:.4g}"


def interval(low: Any, high: Any) -> list[str] | None:
    """``[low, high]`` to 4 significant digits, None when either is not a finite number (bools
    and strings are no numbers here)."""
    lo, hi = (float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) else None
              for x in (low, high))
    return None if lo is None or hi is None else [fmt_num(lo), fmt_num(hi)]


def as_text(x: Any) -> str:
    return "" if x is None else str(x)


def param_value(v: Any) -> str:
    """A parameter's value: a number to 4 significant digits (n/a when NaN or infinite), a word
    as it is."""
    return v if isinstance(v, str) and as_float(v) is None else num(v)


def known(recs: list[str]) -> list[str]:
    return [x for x in recs if x != "?"]


def unit(name: Any, units: Mapping, notes: dict | None = None) -> dict | None:
    """The unit of a parameter (``{"text": "[m/s]", "sup": None}``), or None. With ``notes``
    (remark -> number, filled here) a unit ``"- (non-dimensional, ...)"`` is ``[-]`` and a
    footnote number, its remark listed once under the table."""
    u = units.get(str(name))
    if u is None or str(u).strip() == "":
        return None
    u = str(u).strip()
    m = re.fullmatch(r"([^()]+?)\s*\((.+)\)", u)
    if notes is not None and m:
        return {"text": f"[{m.group(1)}]", "sup": notes.setdefault(m.group(2), len(notes) + 1)}
    return {"text": u if u.startswith("(") else f"[{u}]", "sup": None}


def unit_notes(notes: Mapping) -> list:
    return [{"sup": k, "text": t} for t, k in notes.items()]


def param_items(p: Mapping, units: Mapping, notes: dict | None = None) -> list:
    """Parameters as ``{name, value, unit}``, 4 significant digits."""
    return [{"name": k, "value": param_value(v), "unit": unit(k, units, notes)} for k, v in p.items()]


def footnote(r: Report, terms: Iterable[str], extra: Iterable[tuple[str, str]] = ()) -> list:
    """A footnote under a table: the report's definitions of ``terms`` (those it has), then
    ``extra``."""
    d = r.definitions or {}
    items = [(t, d[t]) for t in terms if d.get(t, "").strip()] + [(t, x) for t, x in extra if x]
    return [{"term": t, "text": x.rstrip(". ")} for t, x in items]


def definition(r: Report, term: str) -> dict | None:
    x = (r.definitions or {}).get(term)
    return {"term": term, "text": x.rstrip(". ")} if x else None


# --------------------------------------------------------------------------------------------- divergence


def base_diverged(r: Report) -> list[str]:
    """Validation records on which the baseline's replay diverged (wherever the report says so)."""
    out = r.baseline.get("diverged", []) + (r.diverged or {}).get("baseline", [])
    out += [e["record"] for e in r.errors_table if e.get("baseline_diverged")]
    if r.ladder and r.ladder[0]["step"] == "baseline":
        out += r.ladder[0].get("diverged", [])
    return list(dict.fromkeys(out))


def final_diverged(r: Report) -> list[str]:
    out = r.final.get("diverged", []) + [e["record"] for e in r.errors_table if e.get("final_diverged")]
    return list(dict.fromkeys(out))


def verdict_diverged(r: Report) -> bool:
    return r.verdict.strip().lower().startswith("diverged") or bool(base_diverged(r))


def no_final_model(r: Report) -> bool:
    """True when the report says no effect was added (so no "model with the effects" is drawn
    anywhere)."""
    return sorted(r.final["effects"]) == sorted(r.baseline["effects"])


def divergences(r: Report) -> list[dict]:
    """``{what, on}`` of every replay that diverged: the baseline, each ladder step, the final
    model, each candidate of the ranking (``on``: the records named)."""
    out, seen = [], set()

    def add(what: str, recs: list[str], key: str | None = None) -> None:
        key = what if key is None else key
        if recs and key not in seen:
            seen.add(key)
            out.append({"what": what, "on": known(recs)})

    add("the baseline model", base_diverged(r))
    for s in r.ladder:
        if s["step"] != "baseline":
            recs = s.get("diverged", [])
            if not recs and math.isinf(s["validation_error"]):
                recs = ["?"]
            tag = " (rejected)" if s.get("rejected") else ""
            add(f"ladder step {s['step']}{tag}", recs, f"step {s['step']}")
    for step, recs in (r.diverged or {}).items():
        if step != "baseline":
            add(f"ladder step {step}", recs, f"step {step}")
    if not no_final_model(r):  # else it is the baseline, said above
        add("the final model", final_diverged(r))
    for c in r.ranking:
        if c.get("diverged") or c.get("diverged_records"):
            add(f"candidate {c['effect']}", c.get("diverged_records") or ["?"])
    return out


def step_diverged(s: Mapping, i: int, r: Report) -> bool:
    if s.get("diverged") or math.isinf(s["validation_error"]):
        return True
    return i == 0 and s["step"] == "baseline" and bool(base_diverged(r))


def stability_by_step(r: Report) -> dict[int, Mapping]:
    out: dict[int, Mapping] = {}
    for s in r.stability or []:
        if s.get("step") is not None:
            out.setdefault(s["step"], s)
    return out


def named_in(s: Mapping | None, long: bool = False) -> str:
    """``named in k of n`` of a stability entry (its text when k is None); empty without one."""
    if s is None:
        return ""
    if s["k"] is not None:
        return f"named in {s['k']} of {s['n']}" + (" with one validation record left out" if long else "")
    return s["text"] if long else ""
