"""Verdicts with their evidence: paired comparisons, a stated test, ties counted as ties, and a
sensitivity table.

A claim of the form "A gives lower errors than B" is decided on **pairs**: the same data (vessel,
model, set-up, seed) identified both ways, compared coefficient by coefficient (or equation by
equation, as an alternative). A pair is a **tie** when the two errors differ by less than ``tie``
(relative, 5 % by default) or both lie below ``floor`` (an error nobody would act on); ties are
reported, not dropped into either side. The verdict is the **sign test** (exact binomial test of
wins against losses, one-sided, level 0.05; scipy) in the claim's direction; the Wilcoxon
signed-rank test of the log error ratios is given beside it:

- **holds**: wins outnumber losses beyond chance (p < 0.05);
- **does not hold**: losses outnumber wins beyond chance (p < 0.05 the other way);
- **cannot tell**: neither (too few pairs, or as many losses as wins).

Within a pair, scaling both errors by the term's weight changes nothing (the same factor): the
scaled error matters where errors are aggregated (medians per equation, or across coefficients). A
verdict is then recomputed under each reasonable alternative choice (metric, pairing unit, noise
level, sampling interval, subset of models...): :func:`settle` says "depends on ..." when the
alternatives disagree with the primary choice, naming them. Verdicts are computed **per model**
(never across models of different order or size, whose coefficient counts would weight the answer)
and summarised as "holds for k of m models".

**The dataset as the unit.** The coefficients of one fit share one noise realisation, so they are
not independent evidence: :func:`dataset_errors` reduces each run to one error (the median over its
coefficients), a failed run to an infinite one (a loss), and :func:`paired_datasets` decides the
claim over independent datasets (replicates), with the effect size (median error ratio) and its
bootstrap interval over datasets, and, for "cannot tell", the smallest effect those datasets could
have detected (:data:`POWER`), so that "no difference" and "too few data" read differently.
:func:`label_invariant` scores exchangeable coefficients (two time constants) without their
labels.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import stats

ALPHA = 0.05
TIE = 0.05

__all__ = ["paired", "compare", "sensitivity", "describe", "explain", "settle", "summary", "dataset_errors",
           "paired_datasets", "describe_datasets", "detectable_win_rate", "label_invariant", "ALPHA", "TIE", "POWER"]


def paired(a, b, tie: float = TIE, floor: float = 0.0) -> dict:
    """Claim "a is lower than b" on paired errors ``a`` and ``b`` (NaN pairs dropped).

    Returns ``{'pairs', 'wins', 'losses', 'ties', 'p', 'p_reverse', 'p_wilcoxon', 'median_ratio',
    'verdict'}``: ``p`` the one-sided sign-test p-value of the claim, ``p_reverse`` of its
    opposite, ``median_ratio`` the median of a / b over pairs where b > 0."""
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
    """One line of a paired comparison: 'holds (wins 14, losses 3, ties 1 of 18; sign test p =
    0.006)'."""
    if not r["pairs"]:
        return "cannot tell (no pairs)"
    p = r["p"] if r["verdict"] != "does not hold" else r["p_reverse"]
    ps = "n/a" if not np.isfinite(p) else (f"{p:.2g}" if p >= 1e-4 else "< 1e-4")
    return (f"{r['verdict']} (wins {r['wins']}, losses {r['losses']}, ties {r['ties']} of {r['pairs']}; sign test "
            f"p = {ps}; median error ratio {r['median_ratio']:.3g})")


def settle(table: pd.DataFrame, primary: str = "primary") -> str:
    """The claim's verdict from its sensitivity table (``choice`` and ``verdict`` columns, the
    primary choice's row named ``primary``): the primary verdict if every alternative agrees,
    else 'depends on ...' naming the alternatives that disagree and what they give."""
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
    """'holds for 3 of 4 models (kcs: cannot tell)' from model -> verdict; 'holds for both
    models', 'holds for all 3 models' when they agree."""
    if not per_model:
        return "not run"
    n = len(per_model)
    counts = pd.Series(list(per_model.values())).value_counts()
    top = counts.index[0]
    if counts.iloc[0] == n:
        if n == 1:  # "the one model order", not "the one model orders"
            return f"{top} for {next(iter(per_model))}"
        return f"{top} for {'both' if n == 2 else f'all {n}'} {noun}"
    if 2 * counts.iloc[0] <= n:  # no majority: every verdict with what it applies to
        groups = [f"{v} for {', '.join(m for m, x in per_model.items() if x == v)}" for v in counts.index]
        return f"mixed over the {n} {noun}: " + "; ".join(groups)
    others = [f"{m}: {v}" for m, v in per_model.items() if v != top]
    return f"{top} for {counts.iloc[0]} of {n} {noun} ({'; '.join(others)})"


def compare(p: pd.DataFrame, by: str, a, b, keys: list, metric: str, unit: str = "coefficient",
            tie: float = TIE, floor: float = 0.0) -> dict:
    """:func:`paired` of the rows with ``by == a`` against those with ``by == b``, matched on
    ``keys`` (which must name the data: model, set-up, seed, ...). ``unit='coefficient'``: one
    pair per coefficient (``equation``, ``name``); ``'equation'``: one pair per equation, the
    median of its coefficients' ``metric``."""
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
    """The claim "``a`` beats ``b``" under each choice ``(label, rows, metric, unit)``; the first
    is the primary (labelled 'primary: <label>'). One row per choice with the paired statistics."""
    rows = []
    for i, (label, rows_of, metric, unit) in enumerate(choices):
        r = compare(rows_of if rows_of is not None else p, by, a, b, keys, metric, unit, tie=tie, floor=floor)
        rows.append({"choice": "primary" if i == 0 else label, "what": label, **r})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------------------------- the dataset as the unit

#: power at which :func:`paired_datasets` states the smallest effect its datasets could have detected
POWER = 0.8
N_BOOT = 2000


def dataset_errors(p: pd.DataFrame, by: str, keys: list, metric: str = "abs_rel_error",
                   runs: pd.DataFrame | None = None, summary: str = "median") -> pd.DataFrame:
    """One error per dataset and method: rows are the datasets (``keys``: everything that names the
    data, the replicate or seed among them), columns the values of ``by``, each cell the ``summary``
    (median or mean) of ``metric`` over the run's coefficients. The coefficients of one fit are
    never counted as separate evidence.

    ``runs`` (every status): a run of a dataset that failed, or that gave no finite error, is an
    infinite error, so it loses its pair instead of dropping out of it."""
    cols = list(keys) + [by]
    q = p[cols + [metric]].copy()
    q[metric] = q[metric].astype(float).abs()
    per = q.groupby(cols, dropna=False)[metric].agg(summary).reset_index()
    if runs is not None and len(runs):
        bad = runs[[c for c in cols if c in runs]].copy()
        if len(bad.columns) == len(cols):
            failed = runs["status"].eq("failed") if "status" in runs else pd.Series(False, index=runs.index)
            bad = bad[failed.to_numpy()].assign(**{metric: np.inf})
            per = pd.concat([per, bad], ignore_index=True)
    per[metric] = per[metric].fillna(np.inf)  # a run with no finite error counts as a failure
    return per.pivot_table(index=list(keys), columns=by, values=metric, aggfunc="max", dropna=False)


def _critical_wins(n: int, alpha: float = ALPHA) -> int | None:
    """The fewest wins of ``n`` decided pairs a one-sided sign test calls significant (None: no
    number can)."""
    for k in range(n + 1):
        if stats.binomtest(k, n, 0.5, alternative="greater").pvalue < alpha:
            return k
    return None


def detectable_win_rate(n: int, power: float = POWER, alpha: float = ALPHA) -> float:
    """The smallest probability of a win that ``n`` decided pairs detect with the sign test with
    probability ``power`` (inf when no win rate can be detected: too few pairs)."""
    k = _critical_wins(n, alpha) if n >= 1 else None
    if k is None:
        return math.inf
    lo, hi = 0.5, 1.0
    for _ in range(60):  # bisection on P(Binomial(n, q) >= k) = power
        mid = 0.5 * (lo + hi)
        if stats.binom.sf(k - 1, n, mid) >= power:
            hi = mid
        else:
            lo = mid
    return hi


def paired_datasets(a, b, tie: float = TIE, floor: float = 0.0, n_boot: int = N_BOOT, seed: int = 0) -> dict:
    """Claim "a's error is lower than b's" over **datasets**: ``a[i]``, ``b[i]`` are the two
    methods' errors on dataset ``i`` (inf: the method failed there; NaN: the dataset lacks one of
    them and is dropped).

    Returns the sign test of :func:`paired` (wins, losses, ties of datasets; ``p``, ``p_reverse``,
    ``verdict``) and the effect size: ``ratio``, the median over datasets of a / b (below 1: a is
    better), with its ``ratio_low``, ``ratio_high`` 95 % percentile bootstrap interval over
    datasets, and ``detectable_ratio``: the ratio a true effect must reach (either way) for these
    datasets to detect it with probability :data:`POWER`, with the spread of the observed log ratios
    (inf when no effect could be detected: too few datasets). A "cannot tell" with a detectable
    ratio near 1 means no difference; far from 1, too few data.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = ~(np.isnan(a) | np.isnan(b))
    a, b = a[ok], b[ok]
    both_inf = np.isinf(a) & np.isinf(b)
    fa, fb = np.where(np.isinf(a), 1e300, a), np.where(np.isinf(b), 1e300, b)
    r = paired(np.where(both_inf, 0.0, fa), np.where(both_inf, 0.0, fb), tie=tie, floor=floor)
    finite = np.isfinite(a) & np.isfinite(b) & (a > 0) & (b > 0)
    lr = np.log(a[finite] / b[finite])
    out = {**r, "datasets": int(len(a)), "failed_a": int(np.sum(np.isinf(a))), "failed_b": int(np.sum(np.isinf(b)))}
    if len(lr):
        rng = np.random.default_rng(seed)
        boot = np.median(lr[rng.integers(0, len(lr), size=(n_boot, len(lr)))], axis=1)
        out.update(ratio=float(np.exp(np.median(lr))), ratio_low=float(np.exp(np.quantile(boot, 0.025))),
                   ratio_high=float(np.exp(np.quantile(boot, 0.975))))
    else:
        out.update(ratio=math.nan, ratio_low=math.nan, ratio_high=math.nan)
    q = detectable_win_rate(r["wins"] + r["losses"] or len(a))
    s = float(np.std(lr, ddof=1)) if len(lr) > 1 else math.nan
    # log ratios ~ Normal(delta, s): P(win) = Phi(delta / s), so the detectable |delta| is s * Phi^-1(q)
    out["detectable_ratio"] = float(np.exp(-s * stats.norm.ppf(q))) if np.isfinite(q) and np.isfinite(s) else math.inf
    return out


def describe_datasets(r: dict, unit: str = "datasets") -> str:
    """One line of :func:`paired_datasets`: verdict, counts of datasets, sign test, effect with
    its interval, and, for "cannot tell", the smallest effect the datasets could have detected."""
    if not r["pairs"]:
        return f"cannot tell (no {unit})"
    p = r["p"] if r["verdict"] != "does not hold" else r["p_reverse"]
    ps = "n/a" if not np.isfinite(p) else (f"{p:.2g}" if p >= 1e-4 else "< 1e-4")
    eff = (f"median error ratio {r['ratio']:.3g} [{r['ratio_low']:.3g}, {r['ratio_high']:.3g}]"
           if np.isfinite(r["ratio"]) else "no finite error ratio")
    fails = f"; failures {r['failed_a']} / {r['failed_b']}" if r.get("failed_a") or r.get("failed_b") else ""
    text = (f"{r['verdict']} ({r['wins']} wins, {r['losses']} losses, {r['ties']} ties of {r['pairs']} {unit}"
            f"{fails}; sign test p = {ps}; {eff}")
    if r["verdict"] == "cannot tell":
        d = r["detectable_ratio"]
        text += ("; no effect detectable with so few" if not np.isfinite(d) or d <= 0 else
                 f"; {POWER:.0%} power only for ratios below {d:.3g} or above {1 / d:.3g}")
    return text + ")"


def label_invariant(p: pd.DataFrame, groups: list, by: str = "run_id") -> pd.DataFrame:
    """``p`` with exchangeable coefficients scored without their labels: within each run (``by``)
    and each group of names (e.g. ``("T1", "T2")``: two time constants of one model, which no
    data orders), the estimates are matched to the truths in the order that gives the smallest
    total relative error, and ``estimate``, ``rel_error``, ``abs_rel_error`` follow. Returns a
    copy."""
    from itertools import permutations

    out = p.copy()
    for names in groups:
        sel = out["name"].isin(names)
        for _, idx in out[sel].groupby(by).groups.items():
            rows = out.loc[idx]
            if len(rows) != len(names):
                continue
            est, tru = rows["estimate"].to_numpy(float), rows["truth"].to_numpy(float)
            best = min(permutations(range(len(est))), key=lambda perm: float(np.nansum(
                np.abs(est[list(perm)] - tru) / np.abs(np.where(tru == 0, np.nan, tru)))))
            new = est[list(best)]
            out.loc[idx, "estimate"] = new
            rel = (new - tru) / np.abs(np.where(tru == 0, np.nan, tru))
            out.loc[idx, "rel_error"] = rel
            if "abs_rel_error" in out:
                out.loc[idx, "abs_rel_error"] = np.abs(rel)
    return out


# ------------------------------------------------------------------------ one sensitivity display for every claim

#: the columns of every claim's sensitivity table, in order
SENSITIVITY_COLUMNS = ["claim", "comparison", "choice", "verdict", "unit", "datasets", "wins", "losses", "ties",
                       "failed_a", "failed_b", "p", "p_reverse", "ratio", "ratio_low", "ratio_high",
                       "detectable_ratio"]


def _dataset_keys(p: pd.DataFrame, keys: list) -> list:
    """``keys`` plus the replicate (each replicate is its own dataset), where the table has it."""
    return list(keys) + [c for c in ("replicate",) if c in p.columns and c not in keys]


def _fill_replicate(d: pd.DataFrame | None) -> pd.DataFrame | None:
    if d is not None and "replicate" in d.columns:
        d = d.assign(replicate=d["replicate"].fillna(0).astype(int))
    return d


def compare_datasets(p: pd.DataFrame, by: str, a, b, keys: list, metric: str = "abs_rel_error",
                     runs: pd.DataFrame | None = None, summary: str = "median", tie: float = TIE,
                     floor: float = 0.0) -> dict:
    """:func:`paired_datasets` of method ``a`` against ``b`` (values of column ``by``) over the
    datasets named by ``keys`` and the replicate: one error per dataset and method (``summary``
    of ``metric`` over the run's coefficients), a failed run an infinite error.
    ``summary='coefficient'``: each coefficient its own pair (the coefficients of one fit are not
    independent; shown only as the counting unit a reader might expect)."""
    p, runs = _fill_replicate(p), _fill_replicate(runs)
    k = _dataset_keys(p, keys)
    if summary == "coefficient":
        r = compare(p, by, a, b, k, metric, "coefficient", tie=tie, floor=floor)
        return {**r, "datasets": r["pairs"], "failed_a": 0, "failed_b": 0, "ratio": r["median_ratio"],
                "ratio_low": math.nan, "ratio_high": math.nan, "detectable_ratio": math.nan}
    q = p[p[by].isin([a, b])]
    rr = None if runs is None else runs[runs[by].isin([a, b])]
    if not len(q) and (rr is None or not len(rr)):
        return {**paired_datasets([], []), "pairs": 0}
    tab = dataset_errors(q, by, k, metric, runs=rr, summary=summary)
    if a not in tab or b not in tab:
        return {**paired_datasets([], []), "pairs": 0}
    return paired_datasets(tab[a].to_numpy(float), tab[b].to_numpy(float), tie=tie, floor=floor)


def dataset_sensitivity(claim: str, comparison: str, p: pd.DataFrame, runs: pd.DataFrame | None, by: str, a, b,
                        keys: list, subsets: list = (), metric: str = "abs_rel_error", tie: float = TIE,
                        floor: float = 0.0, alt_metric: str | None = "scaled_error") -> pd.DataFrame:
    """One claim's comparison under its primary choice and every other reasonable one, one row
    each (:data:`SENSITIVITY_COLUMNS`). The primary: datasets as the unit, the median of
    ``metric`` over each run's coefficients, ties within ``tie``, both errors below ``floor`` a
    tie. Always varied: the tie (1 %, 10 %), the floor (none; ten times, or 0.1 % where there is
    none), the per-dataset summary (mean), the counting unit (coefficients, not independent), the
    metric (``alt_metric`` where the table has it); then each of ``subsets``: ``(label, params,
    runs)`` (one noise level, one sampling interval, one model...)."""
    rows = []

    def add(label, pp, rr, **kw):
        args = {"metric": metric, "summary": "median", "tie": tie, "floor": floor, **kw}
        r = compare_datasets(pp, by, a, b, keys, runs=rr, **args)
        unit = "coefficients (not independent)" if args["summary"] == "coefficient" else "datasets"
        rows.append({"claim": claim, "comparison": comparison, "choice": "primary" if not rows else label,
                     "what": label, "unit": unit, **r})

    add("datasets, median relative error of each run's coefficients", p, runs)
    add("ties within 1 %", p, runs, tie=0.01)
    add("ties within 10 %", p, runs, tie=0.10)
    add("no floor" if floor else "floor 0.1 %", p, runs, floor=0.0 if floor else 0.001)
    if floor:
        add(f"floor {100 * 10 * floor:g} %", p, runs, floor=10 * floor)
    add("datasets, mean relative error of each run's coefficients", p, runs, summary="mean")
    add("coefficients as the unit (not independent)", p, runs, summary="coefficient")
    if alt_metric and alt_metric in p.columns and p[alt_metric].notna().any():
        add(f"metric {alt_metric} (error in units of its equation)", p, runs, metric=alt_metric)
    for label, pp, rr in subsets:
        add(label, pp, rr)
    t = pd.DataFrame(rows)
    t = t[t["pairs"] > 0] if len(t) > 1 else t
    return t


def dataset_verdict(t: pd.DataFrame) -> tuple[str, str]:
    """(verdict, numbers) of a :func:`dataset_sensitivity` table: the primary verdict, or
    'depends on the choice' naming every choice that flips it (:func:`settle`), and the primary's
    numbers (:func:`describe_datasets`) with the flips' own verdicts."""
    if not len(t):
        return "not run", "no datasets"
    prim = t.iloc[0].to_dict()
    off = t[(t["choice"] != "primary") & (t["verdict"] != prim["verdict"])]
    text = describe_datasets(prim)
    text += ("; flips: " + ", ".join(f"{w}: {v}" for w, v in zip(off["what"], off["verdict"])) if len(off) else
             f"; the same under all {len(t) - 1} other choices")
    return settle(t), text


def tidy_sensitivity(t: pd.DataFrame) -> pd.DataFrame:
    """The sensitivity table as written: :data:`SENSITIVITY_COLUMNS`, the choice's label in
    ``choice``."""
    t = t.assign(choice=t["what"]) if "what" in t else t
    return t[[c for c in SENSITIVITY_COLUMNS if c in t.columns]]


# ------------------------------------------------------------------------------ coverage with the dataset as the unit

#: 90 % intervals covering the truth 80-97 % of the time are called calibrated
COVERAGE_BAND = (0.80, 0.97)
NOMINAL = 0.90


def coverage_over_datasets(p: pd.DataFrame, dataset: str = "run_id", nominal: float = NOMINAL,
                           band: tuple = COVERAGE_BAND, n_boot: int = N_BOOT, seed: int = 0) -> dict:
    """Coverage of the truth by the intervals (``ci_low``, ``ci_high``) of ``p``'s rows, the
    dataset (``dataset``: one run is one dataset) as the unit: the share of intervals that hold
    the truth, with its 95 % percentile bootstrap interval over datasets (the coefficients of one
    fit miss together, so they are resampled together), how the misses fall (datasets that miss
    none, every one, of their coefficients) and the verdict on "about ``nominal``": **holds**
    when the coverage is inside ``band``; **does not hold** when its interval lies wholly outside
    the band; **cannot tell** otherwise. ``vs_nominal`` says whether the interval lies below or
    above ``nominal`` (intervals measurably too narrow or too wide, though perhaps inside the
    band)."""
    if not len(p):
        return {"datasets": 0, "intervals": 0, "covered": 0, "coverage": math.nan, "cov_low": math.nan,
                "cov_high": math.nan, "verdict": "not run"}
    hit = ((p["ci_low"] <= p["truth"]) & (p["truth"] <= p["ci_high"])).astype(float)
    g = pd.DataFrame({"d": p[dataset].to_numpy(), "hit": hit.to_numpy()}).groupby("d")["hit"].agg(["sum", "count"])
    k, n = g["sum"].to_numpy(float), g["count"].to_numpy(float)
    cov = float(k.sum() / n.sum())
    if len(g) > 1:
        rng = np.random.default_rng(seed)
        idx = rng.integers(0, len(g), size=(n_boot, len(g)))
        boot = k[idx].sum(axis=1) / n[idx].sum(axis=1)
        lo, hi = (float(x) for x in np.quantile(boot, [0.025, 0.975]))
    else:
        lo, hi = 0.0, 1.0  # one dataset: its coefficients are one draw
    # "about 90 %" is the band: in it, the claim holds; its interval wholly outside, it does not; else cannot tell.
    # Whether the interval excludes the nominal level is said beside it (intervals measurably too narrow or wide)
    verdict = ("holds" if band[0] <= cov <= band[1] else
               "does not hold" if (hi < band[0] or lo > band[1]) else "cannot tell")
    nominal_side = "below" if hi < nominal else ("above" if lo > nominal else "consistent")
    width = ((p["ci_high"] - p["ci_low"]) / p["truth"].abs().where(p["truth"] != 0)).median()
    err = (p["abs_rel_error"] if "abs_rel_error" in p else
           (p["estimate"] - p["truth"]).abs() / p["truth"].abs().where(p["truth"] != 0))
    return {"datasets": int(len(g)), "intervals": int(n.sum()), "covered": int(k.sum()), "coverage": cov,
            "cov_low": lo, "cov_high": hi, "all_covered": int(np.sum(k == n)), "none_covered": int(np.sum(k == 0)),
            "median_rel_width": float(width), "median_abs_rel_error": float(err.median()), "verdict": verdict,
            "vs_nominal": nominal_side}


def describe_coverage(c: dict) -> str:
    """One line of :func:`coverage_over_datasets`."""
    if not c.get("datasets"):
        return "no datasets"
    return (f"{int(c['covered'])}/{int(c['intervals'])} intervals of {int(c['datasets'])} datasets covered "
            f"({100 * c['coverage']:.0f} %, 95 % over datasets {100 * c['cov_low']:.0f}-{100 * c['cov_high']:.0f} %; "
            f"datasets missing every coefficient {int(c['none_covered'])}, none {int(c['all_covered'])}; median width "
            f"{100 * c['median_rel_width']:.3g} % of the truth, median error {100 * c['median_abs_rel_error']:.2g} %"
            + {"below": "; below 90 % beyond chance", "above": "; above 90 % beyond chance"}.get(
                c.get("vs_nominal"), "") + ")")
