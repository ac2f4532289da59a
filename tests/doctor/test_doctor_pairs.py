"""The ladder's look-ahead of one (study.doctor.pairs): a pair is taken only where no single candidate explains
the records, it passes the bars a ladder step does, and a pair holding the step's best candidate is left to the
ladder's one-after-the-other steps. The rule on made-up validation errors; the doctor on simulated records is in
test_doctor_effects.py."""
from __future__ import annotations

from types import SimpleNamespace

from study.doctor.decision import Evaluation, Options
from study.doctor.pairs import better_pair, pair_beats, pool

RECORDS = ["a", "b", "c", "d"]


def ev(effects, errors) -> Evaluation:
    """An evaluation whose per-record validation errors are ``errors`` (every channel's NRMSE the same)."""
    per = {r: {c: {"rmse": e, "nrmse": e} for c in ("u", "v", "r", "psi")} for r, e in zip(RECORDS, errors)}
    return Evaluation(tuple(effects), SimpleNamespace(outer={}), per, float(sum(errors) / len(errors)), 0.0, 0.0)


class FakeDoctor:
    """What ``better_pair`` asks of the doctor: its options and an ``evaluate`` of a set of effects."""

    def __init__(self, table: dict):
        self.opt, self.table, self.asked = Options(), table, []

    def evaluate(self, effects, start=None):
        key = tuple(sorted(effects))
        self.asked.append(key)
        return self.table[key]


def ranking_of(evs: dict) -> list:
    return sorted(({"effect": e, "validation_error": x.validation_error} for e, x in evs.items()),
                  key=lambda r: r["validation_error"])


BASE = ev((), [1.0, 1.1, 0.9, 1.05])
# the records' truth is current + yaw_bias; wind stands in for both and ranks first
SINGLES = {"wind": ev(("wind",), [0.40, 0.45, 0.38, 0.42]), "current": ev(("current",), [0.50, 0.55, 0.5, 0.52]),
           "yaw_bias": ev(("yaw_bias",), [0.7, 0.8, 0.75, 0.72]), "shallow_water": ev(("shallow_water",), [1.0] * 4)}
PAIRS = {("current", "yaw_bias"): ev(("current", "yaw_bias"), [0.05, 0.06, 0.05, 0.04]),
         ("current", "wind"): ev(("current", "wind"), [0.35, 0.4, 0.36, 0.38]),
         ("wind", "yaw_bias"): ev(("wind", "yaw_bias"), [0.38, 0.44, 0.37, 0.4])}


def test_a_pair_no_single_candidate_explains_is_taken_at_once():
    doc = FakeDoctor(PAIRS)
    out = better_pair(doc, BASE, ranking_of(SINGLES), SINGLES, "wind", RECORDS)
    assert out is not None and sorted(out["pair"]) == ["current", "yaw_bias"]
    assert out["best_single"] == "wind" and (out["k"], out["n"]) == (4, 4)
    # the pairs holding the step's own choice are the ladder's to take, one after the other: not fitted here
    assert all("wind" not in k for k in doc.asked) and len(doc.asked) == 1


def test_no_pair_when_the_best_single_candidate_explains_as_much():
    """The best pair only 5 % below the best single candidate: under min_improvement, the ladder goes on as it is."""
    pairs = {**PAIRS, ("current", "yaw_bias"): ev(("current", "yaw_bias"), [0.38, 0.43, 0.36, 0.40])}
    assert better_pair(FakeDoctor(pairs), BASE, ranking_of(SINGLES), SINGLES, "wind", RECORDS) is None


def test_a_pair_must_need_both_of_its_members():
    """current alone already as good as the pair: yaw_bias adds nothing, so the pair is not taken (the ladder
    would take current and stop)."""
    singles = dict(SINGLES, current=ev(("current",), [0.055, 0.06, 0.05, 0.045]))
    pairs = {**PAIRS, ("current", "wind"): ev(("current", "wind"), [0.3] * 4)}
    assert not pair_beats(pairs[("current", "yaw_bias")], [singles["current"], singles["yaw_bias"]],
                          singles["current"], BASE, Options(), RECORDS)
    assert better_pair(FakeDoctor(pairs), BASE, ranking_of(singles), singles, None, RECORDS) is None


def test_a_pair_that_hangs_on_one_record_is_not_taken():
    """Better on one record only (the mean falls, but the paired test across the records does not pass, and with
    each record left out the pair wins in at most half)."""
    pairs = {**PAIRS, ("current", "yaw_bias"): ev(("current", "yaw_bias"), [0.02, 0.6, 0.55, 0.6])}
    singles = dict(SINGLES, wind=ev(("wind",), [0.9, 0.45, 0.4, 0.42]))
    assert better_pair(FakeDoctor(pairs), BASE, ranking_of(singles), singles, "wind", RECORDS) is None


def test_a_tie_is_resolved_when_the_two_together_explain_the_records():
    """Two candidates that tie alone (the step names neither) and together explain the records: both named."""
    singles = {"yaw_bias": ev(("yaw_bias",), [0.5, 0.52, 0.49, 0.5]),
               "rudder_inflow": ev(("rudder_inflow",), [0.51, 0.5, 0.5, 0.52]),
               "current": ev(("current",), [0.9, 0.95, 0.9, 0.92])}
    pairs = {("rudder_inflow", "yaw_bias"): ev(("rudder_inflow", "yaw_bias"), [0.1, 0.12, 0.1, 0.11]),
             ("current", "yaw_bias"): ev(("current", "yaw_bias"), [0.45, 0.5, 0.46, 0.47]),
             ("current", "rudder_inflow"): ev(("current", "rudder_inflow"), [0.5, 0.5, 0.5, 0.5])}
    out = better_pair(FakeDoctor(pairs), BASE, ranking_of(singles), singles, None, RECORDS)
    assert out is not None and sorted(out["pair"]) == ["rudder_inflow", "yaw_bias"]


def test_the_pool_skips_diverged_and_implausible_candidates():
    ranking = [{"effect": "wind", "validation_error": 0.1}, {"effect": "current", "validation_error": float("inf")},
               {"effect": "yaw_bias", "validation_error": 0.3, "diverged": True}, {"effect": "shallow_water",
                                                                                   "validation_error": 0.4},
               {"effect": "rudder_inflow", "validation_error": 0.5}, {"effect": "added", "validation_error": 0.6}]
    evs = {e: None for e in ("wind", "current", "yaw_bias", "shallow_water", "added")}  # rudder_inflow implausible
    assert pool(ranking, evs) == ["wind", "shallow_water", "added"]
