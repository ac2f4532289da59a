"""The view data of the report's section on how far the predictions can be trusted
(``prediction_uncertainty`` in ``report.json``, written by ``study.doctor.uncertainty``): the
plain summary first (which predictions extrapolate, how far, in which states, and which
coefficients carry them), then the predicted 35 deg turns with their intervals (and, when the
verdict is a tie, as each tied reading predicts them and mixed), the validation
metrics' intervals and carriers, the calibration of the extrapolation error, the models counted
as indistinguishable, and the method with what it does not cover
(``templates/uncertainty.html.j2`` lays it out). A part the section does not have is left out;
its numbers are formatted as elsewhere on the page."""
from __future__ import annotations

from collections.abc import Mapping

from .html_format import as_text, interval, num
from .report_schema import Report
from .measurement_noise import agrees

PARTS = (("s_id", "identification"), ("s_struct", "structure"), ("s_extrap", "extrapolation"))


def _real(x) -> bool:
    """A finite int or float (bools and strings are no numbers here)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and num(x) != "n/a"


def _spread(u: Mapping) -> dict:
    """The interval's parts (sd of the log of each source), why it is so wide, and its caveat."""
    parts = ", ".join(f"{name} {100 * u[k]:.1f} %" if _real(u.get(k)) else f"{name} n/a" for k, name in PARTS)
    return {"parts": parts, "why": as_text(u.get("why")), "caveat": as_text(u.get("caveat"))}


def _carriers(cs) -> list[str]:
    return [as_text(c.get("sentence")) for c in cs or []]


def _turn(t: Mapping) -> dict:
    if t.get("why"):
        return {"maneuver": as_text(t.get("maneuver")), "why": str(t["why"])}
    ex = t.get("extrapolation") or {}
    metrics = [{"metric": str(m), "value": num(d.get("value")), "interval": interval(d.get("low"), d.get("high")),
                **_spread(d), "carriers": _carriers(d.get("carriers"))} for m, d in (t.get("metrics") or {}).items()]
    return {"maneuver": as_text(t.get("maneuver")), "why": None, "text": as_text(ex.get("text")),
            "extrapolates": as_text(ex.get("text")).startswith("EXTRAPOLATES"), "distance": num(ex.get("distance"), 3),
            "u0": num(t.get("u0")), "n": num(t.get("n")),
            "left_out": ", ".join(map(str, t.get("setup_left_out") or [])),
            "metrics": metrics, "alternatives": ", ".join(map(str, t.get("alternatives") or [])) or "none"}


def _tie(sec: Mapping) -> dict | None:
    """The turns as each tied reading predicts them, and their equal mixture."""
    tie = sec.get("tie") or {}
    turns = []
    for t in tie.get("turns") or []:
        rows = [{"metric": str(m), "value": num(d.get("value")), "interval": interval(d.get("low"), d.get("high")),
                 "readings": "; ".join(f"{e} {num(x.get('value'))} ({num(x.get('low'))}-{num(x.get('high'))})"
                                       for e, x in (d.get("readings") or {}).items())}
                for m, d in (t.get("metrics") or {}).items()]
        turns.append({"maneuver": as_text(t.get("maneuver")), "rows": rows})
    return {"readings": " and ".join(map(str, tie.get("readings") or [])), "turns": turns} if turns else None


def _validation(r: Report, sec: Mapping) -> dict | None:
    recs = [{"record": str(n), "text": as_text(x.get("text"))}
            for n, x in ((sec.get("final") or {}).get("records") or {}).items()]
    rows = []
    for m in r.maneuver_metrics or []:
        if m["unit"] == "m" or "final_uncertainty" not in m:
            continue  # the metres rows repeat the ship lengths' ones
        iv, meas = interval(m.get("final_low"), m.get("final_high")), m["measured"]
        held = None if iv is None or not _real(meas) else m["final_low"] <= meas <= m["final_high"]
        rows.append({"record": m["record"], "metric": m["metric"], "measured": num(meas),
                     "measured_interval": interval(m.get("measured_low"), m.get("measured_high")),
                     "final": num(m["final"]), "interval": iv, "held": held, "agrees": agrees(m),
                     "tie": _tie_cell(m),
                     **_spread(m.get("final_uncertainty") or {}), "carriers": _carriers(m.get("carriers"))})
    return {"records": recs, "rows": rows, "tie": any(x["tie"] for x in rows)} if recs or rows else None


def _tie_cell(m: Mapping) -> str:
    """Under a tie, the tied readings' mixture with its interval and whether it holds the measured
    value; empty otherwise."""
    iv = interval(m.get("tie_low"), m.get("tie_high"))
    if iv is None:
        return ""
    held = m["tie_low"] <= m["measured"] <= m["tie_high"] if _real(m.get("measured")) else None
    return f"{num(m.get('tie'))} ({iv[0]}\u2013{iv[1]})" + ("" if held is None else "; holds it" if held else
                                                          "; misses it")


def _calibration(sec: Mapping) -> list:
    out = []
    for role in ("final", "baseline"):
        part = sec.get(role) or {}
        cal = part.get("calibration") or {}
        g = cal.get("growth") or {}
        if not g:
            continue
        out.append({"role": role, "sigma0": num(g.get("sigma0"), 3), "k": num(g.get("k"), 3),
                    "n": as_text(g.get("n")), "pairs": len(cal.get("pairs") or []), "d_max": num(g.get("d_max"), 3),
                    "note": as_text(g.get("note")),
                    "alternatives": ", ".join(map(str, part.get("alternatives") or [])),
                    "excluded": "; ".join(map(str, part.get("excluded") or [])),
                    "notes": [str(n) for n in part.get("notes") or []]})
    return out


def uncertainty_view(r: Report) -> dict | None:
    """The section's data, None when the report has no ``prediction_uncertainty``."""
    sec = r.prediction_uncertainty
    if not sec:
        return None
    return {"summary": [str(s) for s in sec.get("summary") or []],
            "turns": [_turn(t) for t in sec.get("predicted_turns") or []], "tie": _tie(sec),
            "validation": _validation(r, sec),
            "calibration": _calibration(sec), "method": as_text(sec.get("method"))}
