"""Verdicts with their evidence: paired comparisons, a stated test, ties counted as ties, and a sensitivity table.

A claim of the form "A gives lower errors than B" is decided on **pairs**: the same data (vessel, model,
set-up, seed) identified both ways, compared coefficient by coefficient (or equation by equation, as an
alternative). A pair is a **tie** when the two errors differ by less than ``tie`` (relative, 5 % by default) or
both lie below ``floor`` (an error nobody would act on); ties are reported, not dropped into either side. The
verdict is the **sign test** (exact binomial test of wins against losses, one-sided, level 0.05; scipy) in the
claim's direction; the Wilcoxon signed-rank test of the log error ratios is given beside it:

- **holds**: wins outnumber losses beyond chance (p < 0.05);
- **does not hold**: losses outnumber wins beyond chance (p < 0.05 the other way);
- **cannot tell**: neither (too few pairs, or as many losses as wins).

Within a pair, scaling both errors by the term's weight changes nothing (the same factor): the scaled error
matters where errors are aggregated (medians per equation, or across coefficients). A verdict is then recomputed
under each reasonable alternative choice (metric, pairing unit, noise level,
sampling interval, subset of models...): :func:`settle` says "depends on ..." when the alternatives disagree with
the primary choice, naming them. Verdicts are computed **per model** (never across models of different order or
size, whose coefficient counts would weight the answer) and summarised as "holds for k of m models".
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import stats

ALPHA = 0.05
TIE = 0.05

__all__ = ["paired", "compare", "sensitivity", "describe", "explain", "settle", "summary", "ALPHA", "TIE"]


def paired(a, b, tie: float = TIE, floor: float = 0.0) -> dict:
    """Claim "a is lower than b" on paired errors ``a`` and ``b`` (NaN pairs dropped).

    Returns ``{'pairs', 'wins', 'losses', 'ties', 'p', 'p_reverse', 'p_wilcoxon', 'median_ratio', 'verdict'}``:
    ``p`` the one-sided sign-test p-value of the claim, ``p_reverse`` of its opposite, ``median_ratio`` the median
    of a / b over pairs where b > 0."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = np.abs(a[ok]), np.abs(b[ok])
    scale = np.maximum(np.maximum(a, b), 1e-300)
    small = (a <= floor) & (b <= floor)
    wins = int(np.sum(((b - a) > tie * scale) & ~small))
    losses = int(np.sum(((a - b) > tie * scale) & ~small))
    n = int(len(a))
    ties = n - wins - losses
    decided = wins + losses
    p = stats.binomtest(wins, decided, 0.5, alternative="greater").pvalue if decided else math.nan
    p_rev = stats.binomtest(losses, decided, 0.5, alternative="greater").pvalue if decided else math.nan
    pos = (a > 0) & (b > 0)
    lr = np.log(b[pos] / a[pos])
    lr = lr[np.abs(lr) > 0]
    p_w = float(stats.wilcoxon(lr, alternative="greater").pvalue) if len(lr) >= 6 else math.nan
    ratio = float(np.median(a[b > 0] / b[b > 0])) if np.any(b > 0) else math.nan
    if decided and p < ALPHA:
        verdict = "holds"
    elif decided and p_rev < ALPHA:
        verdict = "does not hold"
    else:
        verdict = "cannot tell"
    return {"pairs": n, "wins": wins, "losses": losses, "ties": ties, "p": float(p), "p_reverse": float(p_rev),
            "p_wilcoxon": p_w, "median_ratio": ratio, "verdict": verdict}


def describe(r: dict) -> str:
    """One line of a paired comparison: 'holds (wins 14, losses 3, ties 1 of 18; sign test p = 0.006)'."""
    if not r["pairs"]:
        return "cannot tell (no pairs)"
    p = r["p"] if r["verdict"] != "does not hold" else r["p_reverse"]
    ps = "n/a" if not np.isfinite(p) else (f"{p:.2g}" if p >= 1e-4 else "< 1e-4")
    return (f"{r['verdict']} (wins {r['wins']}, losses {r['losses']}, ties {r['ties']} of {r['pairs']}; sign test "
            f"p = {ps}; median error ratio {r['median_ratio']:.3g})")


def settle(table: pd.DataFrame, primary: str = "primary") -> str:
    """The claim's verdict from its sensitivity table (``choice`` and ``verdict`` columns, the primary choice's
    row named ``primary``): the primary verdict if every alternative agrees, else 'depends on ...' naming the
    alternatives that disagree and what they give."""
    if not len(table):
        return "not run"
    base = table.loc[table["choice"] == primary, "verdict"]
    base = base.iloc[0] if len(base) else table["verdict"].iloc[0]
    off = table[(table["choice"] != primary) & (table["verdict"] != base)]
    if not len(off):
        return base
    parts = [f"{v} with {', '.join(off.loc[off['verdict'] == v, 'choice'])}" for v in dict.fromkeys(off["verdict"])]
    return f"{base}; depends on the choice: " + "; ".join(parts)


def explain(table: pd.DataFrame) -> str:
    """The primary comparison in a line, then the choices under which the verdict differs."""
    prim = table.iloc[0].to_dict()
    off = table[(table["choice"] != "primary") & (table["verdict"] != prim["verdict"])]
    return describe(prim) + ("; other choices: " + ", ".join(f"{w}: {v}" for w, v in zip(off["what"], off["verdict"]))
                             if len(off) else "; the same under every other choice")


def summary(per_model: dict, noun: str = "models") -> str:
    """'holds for 3 of 4 models (kcs: cannot tell)' from model -> verdict; 'holds for both models', 'holds for
    all 3 models' when they agree."""
    if not per_model:
        return "not run"
    n = len(per_model)
    counts = pd.Series(list(per_model.values())).value_counts()
    top = counts.index[0]
    if counts.iloc[0] == n:
        return f"{top} for {'the one' if n == 1 else 'both' if n == 2 else f'all {n}'} {noun}"
    if 2 * counts.iloc[0] <= n:  # no majority: every verdict with what it applies to
        groups = [f"{v} for {', '.join(m for m, x in per_model.items() if x == v)}" for v in counts.index]
        return f"mixed over the {n} {noun}: " + "; ".join(groups)
    others = [f"{m}: {v}" for m, v in per_model.items() if v != top]
    return f"{top} for {counts.iloc[0]} of {n} {noun} ({'; '.join(others)})"


def compare(p: pd.DataFrame, by: str, a, b, keys: list, metric: str, unit: str = "coefficient",
            tie: float = TIE, floor: float = 0.0) -> dict:
    """:func:`paired` of the rows with ``by == a`` against those with ``by == b``, matched on ``keys`` (which must
    name the data: model, set-up, seed, ...). ``unit='coefficient'``: one pair per coefficient (``equation``,
    ``name``); ``'equation'``: one pair per equation, the median of its coefficients' ``metric``."""
    q = p[p[by].isin([a, b])]
    if unit == "equation":
        q = q.groupby(list(keys) + ["equation", by], dropna=False)[metric].median().reset_index()
        idx = list(keys) + ["equation"]
    else:
        idx = list(keys) + ["equation", "name"]
    if not len(q):
        return paired([], [])
    piv = q.pivot_table(index=idx, columns=by, values=metric, aggfunc="first", dropna=False)
    if a not in piv or b not in piv:
        return paired([], [])
    return paired(piv[a], piv[b], tie=tie, floor=floor)


def sensitivity(p: pd.DataFrame, by: str, a, b, keys: list, choices: list, tie: float = TIE,
                floor: float = 0.0) -> pd.DataFrame:
    """The claim "``a`` beats ``b``" under each choice ``(label, rows, metric, unit)``; the first is the primary
    (labelled 'primary: <label>'). One row per choice with the paired statistics."""
    rows = []
    for i, (label, rows_of, metric, unit) in enumerate(choices):
        r = compare(rows_of if rows_of is not None else p, by, a, b, keys, metric, unit, tie=tie, floor=floor)
        rows.append({"choice": "primary" if i == 0 else label, "what": label, **r})
    return pd.DataFrame(rows)
