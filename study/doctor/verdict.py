"""The doctor's one-line verdict (the report's ``verdict``), from a finished ladder
(``Doctor.result``)."""
from __future__ import annotations

from .decision import EXPLAINS_MOST


def verdict_line(doctor) -> str:
    """The report's one line: the missing effect with its fall of the error and its
    parameters, a tie, a rejected best candidate or nothing significant; a diverged baseline
    said first."""
    r = doctor.result
    base, m = r["base"], r["missing"]
    stab = {s["step"]: s for s in r["stability"]}
    scored = r["scored"]
    prefix = ""
    if base.diverged:
        prefix = (f"Diverged: the baseline model diverges when replayed through {len(base.diverged)} of "
                  f"{len(base.errors)} validation record(s) ({', '.join(base.diverged)}); " +
                  ("those are not scored. " if scored else "no record is left to compare on, so no missing "
                   "effect can be named"))
    if not scored:
        verdict = prefix
    elif m:
        e0, e1 = r["ladder"][0]["scored_error"], r["ladder"][1]["scored_error"]
        named = r.get("named_first") or [m]
        pars = list(doctor.problem.describe(r["ladder_fits"][1], named, model=False).items())
        fmt = lambda v: f"{v:.4g}" if isinstance(v, (int, float)) else str(v)  # noqa: E731
        on = f" on the other {len(scored)} record(s)" if base.diverged else ""
        what = f"Missing effect: {m}" if len(named) == 1 else f"Missing effects: {' and '.join(named)}, together"
        verdict = prefix + (f"{what} (validation error{on} {e0:.3g} -> {e1:.3g}, "
                            f"{100 * (1 - e1 / e0):.0f} % lower; " +
                            ", ".join(f"{k} = {fmt(v)}" for k, v in pars[:6]) +
                            (", ..." if len(pars) > 6 else "") + ")")
        if base.diverged:
            still = [x for x in base.diverged if x in r["ladder"][1]["diverged"]]
            verdict += (f"; with it {', '.join(still)} still diverge(s)" if still else
                        f"; with it the replay of {', '.join(base.diverged)} is stable")
        if 1 in stab and stab[1]["k"] is not None:
            verdict += (f"; named{' together' if len(named) > 1 else ''} in {stab[1]['k']} of {stab[1]['n']} "
                        "with one validation record left out")
        if e1 > (1.0 - EXPLAINS_MOST) * e0:
            verdict += (f"; it removes less than {100 * EXPLAINS_MOST:.0f} % of the error: it may stand in for a "
                        "cause no candidate models")
        acc = [s for s in r["ladder"][2:] if not s.get("rejected")]
        if acc:
            verdict += "; then " + ", ".join(s["step"][2:] for s in acc)
    elif r["ambiguous"]:
        verdict = prefix + (f"The data cannot tell {r['ambiguous'][0]} from {r['ambiguous'][1]} apart; both "
                            "lower the validation error about equally")
    elif len(r["ladder"]) > 1 and r["ladder"][1].get("rejected"):
        st = r["ladder"][1]
        verdict = prefix + (f"No missing effect named: the best candidate, {st['step'][2:]}, was rejected "
                            f"({st['reason']})")
    else:
        verdict = prefix + "No significant missing effect"
        if 1 in stab and stab[1]["k"] is not None:
            verdict += f" (the same in {stab[1]['k']} of {stab[1]['n']} with one validation record left out)"
    return verdict
