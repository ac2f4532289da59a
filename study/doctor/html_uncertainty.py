"""The view data of the report's section on how far the predictions can be trusted (``prediction_uncertainty``
in ``report.json``, ``study.doctor.uncertainty``): the plain summary first (which predictions extrapolate, how far,
in which states, and which coefficients carry them), then the predicted 35 deg turns with their intervals, the
validation metrics' intervals and carriers, the calibration of the extrapolation error, the models counted as
indistinguishable, and the method with what it does not cover (``templates/uncertainty.html.j2`` lays it out)."""
from __future__ import annotations

from collections.abc import Mapping

from .html_format import interval, num

PARTS = (("s_id", "identification"), ("s_struct", "structure"), ("s_extrap", "extrapolation"))


def _rows(x) -> list:
    return [a for a in x if isinstance(a, Mapping)] if isinstance(x, (list, tuple)) else []


def _dict(x) -> Mapping:
    return x if isinstance(x, Mapping) else {}


def _words(x) -> list[str]:
    return [str(a) for a in x] if isinstance(x, (list, tuple)) else []


def _real(x) -> bool:
    """A finite int or float (bools and strings are no numbers here)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and num(x) != "n/a"


def _spread(u: Mapping) -> dict:
    """The interval's parts (sd of the log of each source), why it is so wide, and its caveat."""
    parts = []
    for k, name in PARTS:
        x = u.get(k)
        parts.append(f"{name} {100 * x:.1f} %" if _real(x) else f"{name} n/a")
    return {"parts": ", ".join(parts), "why": str(u.get("why") or ""), "caveat": str(u.get("caveat") or "")}


def _carriers(cs) -> list[str]:
    return ["" if c.get("sentence") is None else str(c.get("sentence")) for c in _rows(cs)]


def _turn(t: Mapping) -> dict:
    if t.get("why"):
        return {"maneuver": str(t.get("maneuver") or ""), "why": str(t["why"])}
    ex = _dict(t.get("extrapolation"))
    text = "" if ex.get("text") is None else str(ex.get("text"))
    metrics = [{"metric": str(m), "value": num(_dict(d).get("value")),
                "interval": interval(_dict(d).get("low"), _dict(d).get("high")), **_spread(_dict(d)),
                "carriers": _carriers(_dict(d).get("carriers"))} for m, d in _dict(t.get("metrics")).items()]
    return {"maneuver": "" if t.get("maneuver") is None else str(t.get("maneuver")), "why": None,
            "extrapolates": text.startswith("EXTRAPOLATES"), "text": text, "distance": num(ex.get("distance"), 3),
            "u0": num(t.get("u0")), "n": num(t.get("n")),
            "left_out": ", ".join(map(str, t.get("setup_left_out") or [])),
            "metrics": metrics, "alternatives": ", ".join(_words(t.get("alternatives"))) or "none"}


def _validation(r: Mapping, sec: Mapping) -> dict | None:
    recs = [{"record": str(n), "text": "" if _dict(x).get("text") is None else str(_dict(x)["text"])}
            for n, x in _dict(_dict(sec.get("final")).get("records")).items()]
    rows = []
    for m in _rows(r.get("maneuver_metrics")):
        if m.get("unit") == "m" or "final_uncertainty" not in m:
            continue  # the metres rows repeat the ship lengths' ones
        iv, meas = interval(m.get("final_low"), m.get("final_high")), m.get("measured")
        held = None if iv is None or not _real(meas) else m["final_low"] <= meas <= m["final_high"]
        rows.append({"record": str(m.get("record")), "metric": str(m.get("metric")), "measured": num(meas),
                     "final": num(m.get("final")), "interval": iv, "held": held,
                     **_spread(_dict(m.get("final_uncertainty"))), "carriers": _carriers(m.get("carriers"))})
    return {"records": recs, "rows": rows} if recs or rows else None


def _calibration(sec: Mapping) -> list:
    out = []
    for role in ("final", "baseline"):
        part = _dict(sec.get(role))
        g = _dict(_dict(part.get("calibration")).get("growth"))
        if not g:
            continue
        out.append({"role": role, "sigma0": num(g.get("sigma0"), 3), "k": num(g.get("k"), 3),
                    "n": "" if g.get("n") is None else str(g.get("n")),
                    "pairs": len(_rows(_dict(part.get("calibration")).get("pairs"))), "d_max": num(g.get("d_max"), 3),
                    "note": str(g.get("note") or ""), "alternatives": ", ".join(_words(part.get("alternatives"))),
                    "excluded": "; ".join(_words(part.get("excluded"))), "notes": _words(part.get("notes"))})
    return out


def uncertainty_view(r: Mapping) -> dict | None:
    """The section's data, None when the report has no ``prediction_uncertainty``."""
    sec = _dict(r.get("prediction_uncertainty"))
    if not sec:
        return None
    return {"summary": _words(sec.get("summary")), "turns": [_turn(t) for t in _rows(sec.get("predicted_turns"))],
            "validation": _validation(r, sec), "calibration": _calibration(sec),
            "method": "" if sec.get("method") is None else str(sec.get("method"))}
