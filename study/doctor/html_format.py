"""What the report page's view data (:mod:`.html_view`) is built from: the report normalised once, at the entry
(:func:`normalise`: a key of an unexpected type counts as absent, a list entry that is not a row is dropped), the
formatting of numbers and units, and which replays diverged.

Numbers are formatted here: 4 significant digits, ``n/a`` for a missing or not-a-number value; an error figure
of a diverged replay (or an infinite one) is the word ``diverged`` (:data:`DIVERGED`), never a number; ``inf`` is
never shown.
"""
from __future__ import annotations

import math
import numbers
import re
from collections.abc import Iterable, Mapping
from typing import Any

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

_LISTS = ("ranking", "ladder", "errors_table", "worst_windows", "catalogue", "figures", "stability", "identifiability",
          "maneuver_metrics", "notes", "train", "validate", "ambiguous")
_DICTS = ("baseline", "final", "diverged", "units", "definitions", "not_applicable", "depths_h_T", "provenance",
          "prediction_uncertainty", "separating_maneuver", "rudder_residual")
#: list keys whose entries are rows (mappings); the others hold names or sentences
_ROWS = ("ranking", "ladder", "errors_table", "worst_windows", "catalogue", "figures", "stability", "identifiability",
         "maneuver_metrics")


# --------------------------------------------------------------------------------------------- the entry


def normalise(report: Any) -> dict:
    """The report with every key of its expected type: lists as lists (a lone string is one item), mappings as
    dicts, texts as strings; what cannot be read so is left out (absent, as if the report had not said it)."""
    out: dict = {}
    for k, v in (report.items() if isinstance(report, Mapping) else ()):
        k = str(k)
        if k in _LISTS:
            one = (str, Mapping) if k in _ROWS else str  # a lone row, or a lone name
            v = [v] if isinstance(v, one) else list(v) if isinstance(v, (list, tuple)) else None
            if v is not None and k == "ranking":  # a bare name is a candidate with nothing else said
                v = [c if isinstance(c, Mapping) else {"effect": c} for c in v]
            elif v is not None and k in _ROWS:
                v = [x for x in v if isinstance(x, Mapping)]
            elif v is not None:
                v = [str(x) for x in v if x is not None and str(x) != ""]
        elif k in _DICTS:
            v = {str(a): b for a, b in v.items()} if isinstance(v, Mapping) else None
            if v is not None and k == "provenance":  # its records: rows too
                recs = v.get("records")
                v["records"] = [x for x in recs if isinstance(x, Mapping)] if isinstance(recs, (list, tuple)) else []
        elif isinstance(v, (list, tuple, Mapping)):
            v = None
        elif v is not None and not isinstance(v, str):
            v = str(v)
        elif v is None:  # said and empty (a null missing_effect is a verdict): kept
            out[k] = None
        if v is not None:
            out[k] = v
    return out


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
    """A number with ``digits`` significant digits; NaN, None and non-numbers -> ``"n/a"``. ``inf`` stays
    ``"inf"`` here; the page never shows it (an infinite error is a diverged replay, see :func:`err`)."""
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
    """An error figure: ``diverged`` when the replay diverged or the value is infinite, else :func:`num`."""
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
    """``[low, high]`` to 4 significant digits, None when either is not a finite number (bools and strings are no
    numbers here)."""
    lo, hi = (float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) else None
              for x in (low, high))
    return None if lo is None or hi is None else [fmt_num(lo), fmt_num(hi)]


def as_text(x: Any) -> str:
    return "" if x is None else str(x)


def param_value(v: Any) -> str:
    """A parameter's value: a number to 4 significant digits (n/a when NaN or infinite), a word as it is."""
    return v if isinstance(v, str) and as_float(v) is None else num(v)


def records_of(x: Any) -> list[str]:
    """Record names from a ``diverged`` entry (a list of names; a bare True is "some record", ``?``)."""
    if x is True:
        return ["?"]
    if isinstance(x, str):
        return [x] if x else []
    if not isinstance(x, (list, tuple)):
        return []
    return [str(a) for a in x if a is not None and str(a) != ""]


def known(recs: list[str]) -> list[str]:
    return [x for x in recs if x != "?"]


def names(xs: Any) -> list[str]:
    xs = [xs] if isinstance(xs, str) else xs if isinstance(xs, (list, tuple)) else []
    return [str(x) for x in xs if x is not None and str(x) != ""]


def unit(name: Any, units: Mapping, notes: dict | None = None) -> dict | None:
    """The unit of a parameter (``{"text": "[m/s]", "sup": None}``), or None. With ``notes`` (remark -> number,
    filled here) a unit ``"- (non-dimensional, ...)"`` is ``[-]`` and a footnote number, its remark listed once
    under the table."""
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


def param_items(p: Any, units: Mapping, notes: dict | None = None) -> list:
    """Parameters as ``{name, value, unit}``, 4 significant digits."""
    return [{"name": str(k), "value": param_value(v), "unit": unit(k, units, notes)}
            for k, v in (p.items() if isinstance(p, Mapping) else ())]


def footnote(r: dict, terms: Iterable[str], extra: Iterable[tuple[str, str]] = ()) -> list:
    """A footnote under a table: the report's definitions of ``terms`` (those it has), then ``extra``."""
    d = r.get("definitions", {})
    items = [(t, d[t]) for t in terms if isinstance(d.get(t), str) and d[t].strip()] + [(t, x) for t, x in extra if x]
    return [{"term": t, "text": str(x).rstrip(". ")} for t, x in items]


def definition(r: dict, term: str) -> dict | None:
    x = r.get("definitions", {}).get(term)
    return {"term": term, "text": x.rstrip(". ")} if isinstance(x, str) and x else None


# --------------------------------------------------------------------------------------------- divergence


def base_diverged(r: dict) -> list[str]:
    """Validation records on which the baseline's replay diverged (wherever the report says so)."""
    out = records_of(r.get("baseline", {}).get("diverged")) + records_of(r.get("diverged", {}).get("baseline"))
    out += [str(e["record"]) for e in r.get("errors_table", []) if e.get("baseline_diverged") is True
            and e.get("record") is not None]
    steps = r.get("ladder", [])
    if steps and str(steps[0].get("step", "baseline")) == "baseline":
        out += records_of(steps[0].get("diverged"))
    return list(dict.fromkeys(out))


def final_diverged(r: dict) -> list[str]:
    out = records_of(r.get("final", {}).get("diverged"))
    out += [str(e["record"]) for e in r.get("errors_table", []) if e.get("final_diverged") is True
            and e.get("record") is not None]
    return list(dict.fromkeys(out))


def verdict_diverged(r: dict) -> bool:
    return (r.get("verdict") or "").strip().lower().startswith("diverged") or bool(base_diverged(r))


def no_final_model(r: dict) -> bool:
    """True when the report says no effect was added (so no "model with the effects" is drawn anywhere)."""
    fin, base = r.get("final", {}).get("effects"), r.get("baseline", {}).get("effects")
    if isinstance(fin, list) and isinstance(base, list):
        return sorted(map(str, fin)) == sorted(map(str, base))
    steps = r.get("ladder", [])
    return bool(steps) and not any(s.get("rejected") is not True for s in steps[1:])


def divergences(r: dict) -> list[dict]:
    """``{what, on}`` of every replay that diverged: the baseline, each ladder step, the final model, each
    candidate of the ranking (``on``: the records named)."""
    out, seen = [], set()

    def add(what: str, recs: list[str], key: str | None = None) -> None:
        key = what if key is None else key
        if recs and key not in seen:
            seen.add(key)
            out.append({"what": what, "on": known(recs)})

    add("the baseline model", base_diverged(r))
    for s in r.get("ladder", []):
        if str(s.get("step")) != "baseline":
            recs = records_of(s.get("diverged"))
            v = as_float(s.get("validation_error"))
            if not recs and v is not None and math.isinf(v):
                recs = ["?"]
            tag = " (rejected)" if s.get("rejected") else ""
            add(f"ladder step {s.get('step')}{tag}", recs, f"step {s.get('step')}")
    for step, recs in r.get("diverged", {}).items():
        if step != "baseline":
            add(f"ladder step {step}", records_of(recs), f"step {step}")
    if not no_final_model(r):  # else it is the baseline, said above
        add("the final model", final_diverged(r))
    for c in r["ranking"] if "ranking" in r else []:
        if c.get("diverged") is True or records_of(c.get("diverged_records")):
            add(f"candidate {c.get('effect')}", records_of(c.get("diverged_records")) or ["?"])
    return out


def step_diverged(s: Mapping, i: int, r: dict) -> bool:
    v = as_float(s.get("validation_error"))
    if records_of(s.get("diverged")) or (v is not None and math.isinf(v)):
        return True
    return i == 0 and str(s.get("step", "baseline")) == "baseline" and bool(base_diverged(r))


def stability_by_step(r: dict) -> dict[int, Mapping]:
    out: dict[int, Mapping] = {}
    for s in r.get("stability", []):
        step = finite(s.get("step"))
        if step is not None:
            out.setdefault(int(step), s)
    return out


def named_in(s: Mapping | None, long: bool = False) -> str:
    """``named in k of n`` of a stability entry (its text when k/n are missing); empty without one."""
    if s is None:
        return ""
    k, n = finite(s.get("k")), finite(s.get("n"))
    if k is not None and n is not None:
        return f"named in {int(k)} of {int(n)}" + (" with one validation record left out" if long else "")
    t = s.get("text")
    return t if isinstance(t, str) and long else ""
