"""The search of identification with effects (variable projection, Golub & Pereyra 1973): the effects'
nonlinear parameters from a grid, then a bounded Nelder-Mead search on the equation error (the linear unknowns
solved at each point, ``EffectsProblem.solve``), optionally refined on the training replays' error; each discrete
variant of the effects fitted and the best kept. Functions of an
:class:`~study.identify.with_effects.problem.EffectsProblem` (``pb``); ``pb.fit`` calls :func:`fit`."""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from .replay_errors import record_errors, validation_error


@dataclass
class Fit:
    """One identification: the effects, their nonlinear parameters and variant (``outer``), the linear unknowns
    (``coefs``: free model coefficients and the effects' linear parameters), the training error."""

    effects: tuple
    outer: dict
    coefs: dict
    training_error: float
    rss: dict = field(default_factory=dict)
    evaluations: int = 0

    @property
    def values(self) -> dict:
        return {**self.outer, **self.coefs}



#: the local search's evaluations when an effect's variants are screened (see ``EffectsProblem.fit``)
SCREEN_EVALS = 25


def _half_step(grid, lo: float, hi: float) -> float:
    """Half the smallest spacing of a start grid (a tenth of the box for a one-point grid): the local search's
    first step."""
    g = np.unique(np.asarray(grid, float))
    d = np.diff(g)
    return float(0.5 * d.min()) if len(d) else 0.1 * float(hi - lo)



def fit(pb, effects, start: dict | None = None, grid: bool = True, fixed=(), refine: bool = False,
        max_evals: int = 100) -> Fit:
    """Identify the model with ``effects``: each variant of the effects fitted, the best (lowest training
    error) kept.

    The nonlinear parameters not in ``fixed`` (those keep their ``start`` values) start from ``start``
    where known and from the grid of their effect otherwise; the best start point is polished by a
    Nelder-Mead search inside the bounds (equation error, variable projection). With ``refine`` they are then polished
    on the training records' replay error (output error, the linear unknowns still by equation error at
    each point): less biased by measurement noise than the equation error.
    """
    effects = tuple(effects)
    variants = pb.variants(effects)
    if len(variants) == 1:
        return _fit_variant(pb, effects, variants[0], start, grid, fixed, refine, max_evals)
    # several variants (shallow water's formulas): each screened with a short search, then the best (and any
    # within 2 % of it) searched in full from there -- a full search of each cost four times as much
    screened = [_fit_variant(pb, effects, v, start, grid, fixed, False, SCREEN_EVALS) for v in variants]
    order = sorted(range(len(variants)), key=lambda i: screened[i].training_error)
    first = screened[order[0]].training_error
    keep = [i for i in order if screened[i].training_error <= first * 1.02 + 1e-12][:2]
    count = sum(f.evaluations for f in screened)
    best = None
    for i in keep:
        f = _fit_variant(pb, effects, variants[i], {**(start or {}), **screened[i].outer}, False, fixed,
                              refine, max_evals)
        count += f.evaluations
        if best is None or f.training_error < best.training_error:
            best = f
    best.evaluations = count
    return best

def _fit_variant(pb, effects, variant, start, grid, fixed, refine, max_evals) -> Fit:
    spec = pb.outer_params(effects)
    start = dict(start or {})
    fixed_vals = {n: start[n] for n in fixed if n in start}
    spec = [s for s in spec if s[0] not in fixed_vals]
    if not spec:
        vals = {**variant, **fixed_vals}
        coefs, J, rss = pb.solve(effects, vals)
        return Fit(effects, vals, coefs, J, rss, 1)
    names = [s[0] for s in spec]
    lo = np.array([s[1] for s in spec])
    hi = np.array([s[2] for s in spec])
    count = [0]

    def outer_of(x):
        return {**variant, **fixed_vals, **dict(zip(names, (float(v) for v in np.clip(x, lo, hi))))}

    def J(x, model=True):
        count[0] += 1
        try:
            j = pb.solve(effects, outer_of(x), model=model)[1]
            return j if np.isfinite(j) else 1e6
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            return 1e6

    known = {n: float(start[n]) for n in names if isinstance(start.get(n), (int, float))}
    new = [s for s in spec if s[0] not in known]
    if grid and new:
        pts = []
        for combo in itertools.product(*[s[3] for s in new]):
            x = dict(known)
            x.update({s[0]: g for s, g in zip(new, combo)})
            pts.append(np.array([x[n] for n in names]))
    else:
        pts = [np.array([known.get(n, 0.5 * (a + b)) for n, a, b in zip(names, lo, hi)])]
    # a local search from the best start: Nelder-Mead with a simplex of half a grid step (Powell's line
    # searches span the whole box and, measured on an identified hull with a current, jump into another
    # basin)
    steps = np.array([_half_step(s[3], a, b) for s, a, b in zip(spec, lo, hi)])

    def local(x0, model=True, evals=max_evals):
        simplex = np.vstack([x0] + [np.clip(x0 + np.eye(len(x0))[i] * steps[i] *
                                            (1 if x0[i] + steps[i] <= hi[i] else -1), lo, hi)
                                    for i in range(len(x0))])
        res = optimize.minimize(J, x0, args=(model,), method="Nelder-Mead", bounds=list(zip(lo, hi)),
                                options={"maxfev": evals, "xatol": 1e-4 * float(np.max(hi - lo)),
                                         "fatol": 1e-7, "initial_simplex": simplex})
        return np.clip(res.x, lo, hi), float(res.fun)

    if pb.model_free and grid and new:
        # an identified model absorbs most of a wrong effect: its training error is flat except in a basin a
        # few % of U0 wide around the truth (measured: a current on an identified KVLCC2 hull), which a grid
        # misses. With the model's coefficients held at the vessel config's values (its prior) the basin is
        # wide: the effect is located that way first, then everything is identified from there.
        pv = [J(p, False) for p in pts]
        xp, _ = local(pts[int(np.argmin(pv))], False)
        pts = pts + [xp]
    vals = [J(p) for p in pts]
    x0 = pts[int(np.argmin(vals))]
    xb, fb = local(x0)
    best = xb if fb <= min(vals) else x0
    if refine:
        def J_oe(x):
            count[0] += 1
            outer = outer_of(x)
            try:
                coefs = pb.solve(effects, outer)[0]
            except (ValueError, np.linalg.LinAlgError):
                return 1e6
            f = Fit(effects, outer, coefs, 0.0)
            errs = {i: record_errors(df, pb.predict(f, df, pb.infos[i]), pb.floors)
                    for i, df in enumerate(pb.records)}
            e = validation_error(errs)
            return e if np.isfinite(e) else 1e6

        simplex2 = np.vstack([best] + [np.clip(best + np.eye(len(best))[i] * 0.25 * steps[i] *
                                               (1 if best[i] + 0.25 * steps[i] <= hi[i] else -1), lo, hi)
                                       for i in range(len(best))])
        r2 = optimize.minimize(J_oe, best, method="Nelder-Mead", bounds=list(zip(lo, hi)),
                               options={"maxfev": max_evals, "xatol": 1e-4 * float(np.max(hi - lo)),
                                        "fatol": 1e-6, "initial_simplex": simplex2})
        if r2.fun < J_oe(best):
            best = np.clip(r2.x, lo, hi)
    outer = outer_of(best)
    coefs, Jb, rss = pb.solve(effects, outer)
    return Fit(effects, outer, coefs, Jb, rss, count[0])
