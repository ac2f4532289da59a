"""The doctor's decision rule (steps 3 and 4 of ``study.doctor.diagnose``): a candidate's
per-record validation errors against its base's -- the improvement of the mean, the paired test
when there are enough records, significance -- and the verdict over the candidates: the best
significant one, or a tie the records cannot settle. Also the doctor's options and one
evaluation's errors."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from ..identify.with_effects import diverged_records, record_error

#: a named effect that removes less than this share of the validation error is said to explain it only in part:
#: it may stand in for a cause no candidate models (a larger added mass was measured to pass for a rudder-hull
#: interaction with 37 %; a hidden effect of the catalogue removes more than half in every case the doctor is
#: tested on)
EXPLAINS_MOST = 0.5

#: the consistency test needs this many validation records (a paired t-test on fewer has no power)
MIN_RECORDS_FOR_TEST = 3


@dataclass
class Options:
    min_improvement: float = 0.10
    alpha: float = 0.05
    tie: float = 0.10
    max_steps: int = 3
    candidates: tuple | None = None  # None: every discovered effect
    structure: str | dict | None = None  # None: Savitzky-Golay over 0.2 L/U0 (see EffectsProblem)
    effect_path: tuple = ()  # extra folders of effect YAMLs (the user's own effects)
    checks: str = "error"  # the record checks that need the vessel: error | warn | off
    anchor: float | None = 0.3  # an identified model's coefficients anchored to the vessel config's, relative sd
    # (their prior: published, captive tests, CFD); None or 0: plain least squares
    keep_setup_effects: bool = False  # keep set-up effects in predictions for another facility or scale


@dataclass
class Evaluation:
    effects: tuple
    fit: object
    errors: dict  # record -> channel -> {rmse, nrmse}, and 'diverged'
    validation_error: float
    training_error: float
    seconds: float
    fold_fits: list = field(default_factory=list)

    @property
    def diverged(self) -> list:
        return diverged_records(self.errors)

    def per_record(self, records=None) -> np.ndarray:
        return np.array([record_error(self.errors[r]) for r in (records or list(self.errors))])



def mean_on(ev: Evaluation, records: list) -> float:
    return float(np.mean(ev.per_record(records))) if records else math.inf


def compare(base: np.ndarray, cand: np.ndarray, opt: Options) -> dict:
    """The decision rule for one candidate against its base, from per-record validation errors:
    improvement of the mean, the paired test when there are enough records, significance.
    Diverged (inf) errors on either side make no comparison."""
    out = {"improvement": None, "p_value": None, "significant": False, "diverged": False}
    if not (np.all(np.isfinite(base)) and np.all(np.isfinite(cand))):
        out["diverged"] = bool(not np.all(np.isfinite(cand)))
        return out
    e0, e1 = float(np.mean(base)), float(np.mean(cand))
    imp = (e0 - e1) / e0 if e0 > 0 else 0.0
    ok = imp >= opt.min_improvement
    p = None
    if len(base) >= MIN_RECORDS_FOR_TEST:
        d = np.log(base) - np.log(cand)
        if np.allclose(d, d[0]):
            p = 0.0 if d[0] > 0 else 1.0
        else:
            p = float(stats.ttest_1samp(d, 0.0, alternative="greater").pvalue)
        ok = ok and p < opt.alpha
    out.update(improvement=float(imp), p_value=p, significant=bool(ok))
    return out


def decide(base: Evaluation, cands: dict, opt: Options, records=None) -> tuple:
    """(named effect or None, ambiguous pair or [], rows sorted best first) on the given
    validation records."""
    records = list(records) if records is not None else list(base.errors)
    if not records:  # nothing to score: the rows still show each candidate (every comparison void)
        records = list(base.errors)
    b = base.per_record(records)
    rows = []
    for name, ev in cands.items():
        c = ev.per_record(records)
        rows.append({"effect": name, "validation_error": float(np.mean(c)), **compare(b, c, opt)})
    rows.sort(key=lambda d: (not np.isfinite(d["validation_error"]), d["validation_error"]))
    if not np.all(np.isfinite(b)):
        return None, [], rows
    sig = [r for r in rows if r["significant"]]
    if not sig:
        return None, [], rows
    if len(sig) > 1 and sig[1]["validation_error"] <= sig[0]["validation_error"] * (1 + opt.tie):
        return None, [sig[0]["effect"], sig[1]["effect"]], rows
    return sig[0]["effect"], [], rows
