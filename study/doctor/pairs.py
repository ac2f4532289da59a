"""The ladder's look-ahead of one: a pair of candidates that explains the records where no single
one does.

The ladder is a greedy forward selection: each step takes the best single candidate. When two
effects act at once, the best single candidate can be a third one that stands in for both (a wind
whose drift and yaw moment mimic a current and a yaw bias together), or the two can tie, each
explaining about half: then the greedy step names the stand-in, or nothing, and the true pair is
never tried. So each step also fits the pairs of its ``POOL`` best candidates (equation error, as
the ranking does) and takes a pair at once when it passes the same bars a step after the first
does (:func:`better_pair`). A pair that holds the step's best single candidate changes nothing:
the ladder takes that candidate and then, if it still helps, its partner, one after the other.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

from .decision import Evaluation, Options, compare, mean_on

#: the step's best candidates whose pairs are tried (3: three more fits a step; a setting)
POOL = 3


def pool(ranking: list, evs: dict, size: int = POOL) -> list:
    """The ``size`` best candidates of a step's ranking that did not diverge and are plausible here
    (those in ``evs``), best first."""
    return [r["effect"] for r in ranking
            if r["effect"] in evs and np.isfinite(r["validation_error"]) and not r.get("diverged")][:size]


def pair_beats(pair: Evaluation, members: list, best: Evaluation, base: Evaluation, opt: Options,
               records: list) -> bool:
    """Whether ``pair`` passes the bars on ``records``: significant against the step's fit ``base``,
    its best single candidate ``best`` (``decision.compare``: at least ``min_improvement`` lower, the paired test
    when there are enough records) and against each of its two members alone (each is needed)."""
    p = pair.per_record(records)
    return all(compare(ev.per_record(records), p, opt)["significant"] for ev in [base, best, *members])


def better_pair(doctor, base: Evaluation, ranking: list, evs: dict, named, scored: list) -> dict | None:
    """The pair the step takes instead of its single candidate, or None.

    ``base`` the step's (equation-error) fit, ``ranking``/``evs`` its candidates, ``named`` the
    single candidate it would take (None: none, or a tie). The pairs of the :func:`pool` that do not
    hold ``named`` are fitted; the best one is taken when it passes :func:`pair_beats` on the scored
    records, and still does in more than half of the repetitions with one validation record left
    out (as a step after the first must: a pair is two steps at once). Returns ``{'pair', 'evaluation',
    'singles'`` (each member's validation error alone), ``'best_single', 'best_error', 'k', 'n'}``."""
    top = pool(ranking, evs)
    if len(top) < 2 or not scored:
        return None
    best = evs[top[0]]
    fits = {}
    for a, b in combinations(top, 2):
        if named in (a, b):
            continue
        fits[(a, b)] = doctor.evaluate(base.effects + (a, b), start=base.fit.outer)
    if not fits:
        return None
    (a, b), ev = min(fits.items(), key=lambda kv: mean_on(kv[1], scored))
    members = [evs[a], evs[b]]
    if not pair_beats(ev, members, best, base, doctor.opt, scored):
        return None
    n = len(scored)
    # leave-one-out needs two records at least
    k = sum(pair_beats(ev, members, best, base, doctor.opt, [x for x in scored if x != r])
            for r in scored) if n >= 2 else 0
    if n >= 2 and 2 * k <= n:
        return None
    return {"pair": [a, b], "evaluation": ev, "singles": {e: mean_on(evs[e], scored) for e in (a, b)},
            "best_single": top[0], "best_error": mean_on(best, scored), "k": int(k), "n": n}
