"""The search of identification with effects (variable projection, Golub & Pereyra 1973): the
effects' nonlinear parameters from a grid, then a bounded Nelder-Mead search on the equation
error (the linear unknowns solved at each point, ``EffectsProblem.solve``), optionally refined on
the training replays' error; each discrete variant of the effects fitted and the best kept.
Functions of an :class:`~study.identify.with_effects.problem.EffectsProblem` (``pb``); ``pb.fit``
calls :func:`fit`."""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from .replay_errors import record_errors, scored_channels, validation_error


@dataclass
class Fit:
    """One identification: the effects, their nonlinear parameters and variant (``outer``), the
    linear unknowns (``coefs``: free model coefficients and the effects' linear parameters), the
    training error."""

    effects: tuple
    outer: dict
    coefs: dict
    training_error: float
    rss: dict = field(default_factory=dict)
    evaluations: int = 0

    @property
    def values(self) -> dict:
        return {**self.outer, **self.coefs}



#: the local search's evaluations when an effect's variants are screened (see :func:`fit`)
SCREEN_EVALS = 25


def _half_step(grid, lo: float, hi: float) -> float:
    """Half the smallest spacing of a start grid (a tenth of the box for a one-point grid): the
    local search's first step."""
    g = np.unique(np.asarray(grid, float))
    d = np.diff(g)
    return float(0.5 * d.min()) if len(d) else 0.1 * float(hi - lo)



def fit(pb, effects, start: dict | None = None, grid: bool = True, fixed=(), refine: bool = False,
        max_evals: int = 100) -> Fit:
    """Identify the model with ``effects``: each variant of the effects fitted, the best (lowest
    training error) kept.

    The nonlinear parameters not in ``fixed`` (those keep their ``start`` values) start from
    ``start`` where known and from the grid of their effect otherwise; the best start point is
    polished by a Nelder-Mead search inside the bounds (equation error, variable projection). With
    ``refine`` they are then polished on the training records' replay error (output error, the
    linear unknowns still by equation error at each point): less biased by measurement noise than
    the equation error.
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


class _Objectives:
    """The search's objectives over the free nonlinear parameters ``names`` of a variant (inside
    their box ``lo`` .. ``hi``), and how many times they were evaluated (``count``)."""

    def __init__(self, pb, effects, held: dict, spec: list):
        self.pb, self.effects, self.held = pb, effects, held  # held: the variant and the fixed parameters
        self.names = [s[0] for s in spec]
        self.lo = np.array([s[1] for s in spec])
        self.hi = np.array([s[2] for s in spec])
        self.count = 0

    def outer_of(self, x) -> dict:
        """The effects' nonlinear parameters at the point ``x`` (clipped into the box)."""
        return {**self.held, **dict(zip(self.names, (float(v) for v in np.clip(x, self.lo, self.hi))))}

    def equation_error(self, x, model=True) -> float:
        """The equation error at ``x`` (with ``model`` False, the model's coefficients held at
        the vessel config's values); 1e6 where it cannot be computed."""
        self.count += 1
        try:
            j = self.pb.solve(self.effects, self.outer_of(x), model=model)[1]
            return j if np.isfinite(j) else 1e6
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            return 1e6

    def replay_error(self, x) -> float:
        """The training records' replay error at ``x`` (output error; the linear unknowns by
        equation error); 1e6 where it cannot be computed."""
        self.count += 1
        pb = self.pb
        outer = self.outer_of(x)
        try:
            coefs = pb.solve(self.effects, outer)[0]
        except (ValueError, np.linalg.LinAlgError):
            return 1e6
        f = Fit(self.effects, outer, coefs, 0.0)
        errs = {i: record_errors(df, pb.predict(f, df, pb.infos[i]), pb.floors, scored_channels(pb.infos[i].meta))
                for i, df in enumerate(pb.records)}
        e = validation_error(errs)
        return e if np.isfinite(e) else 1e6


def _start_points(obj: _Objectives, new: list, known: dict, grid: bool) -> list:
    """The search's start points: with ``grid``, every point of the grids of the parameters
    ``new`` (the others at their ``known`` values); else one point (the known values, the middle
    of the box for the others)."""
    if grid and new:
        pts = []
        for combo in itertools.product(*[s[3] for s in new]):
            x = dict(known)
            x.update({s[0]: g for s, g in zip(new, combo)})
            pts.append(np.array([x[n] for n in obj.names]))
        return pts
    return [np.array([known.get(n, 0.5 * (a + b)) for n, a, b in zip(obj.names, obj.lo, obj.hi)])]


def _nelder_mead(fun, x0, steps, lo, hi, evals: int, fatol: float, args=()):
    """A bounded Nelder-Mead search from ``x0`` whose first simplex steps ``steps`` along each
    axis (backwards where a step forwards would leave the box)."""
    simplex = np.vstack([x0] + [np.clip(x0 + np.eye(len(x0))[i] * steps[i] *
                                        (1 if x0[i] + steps[i] <= hi[i] else -1), lo, hi)
                                for i in range(len(x0))])
    return optimize.minimize(fun, x0, args=args, method="Nelder-Mead", bounds=list(zip(lo, hi)),
                             options={"maxfev": evals, "xatol": 1e-4 * float(np.max(hi - lo)), "fatol": fatol,
                                      "initial_simplex": simplex})


def _local(obj: _Objectives, x0, steps, evals: int, model=True):
    """The local search on the equation error from ``x0``: its end point (in the box) and error."""
    res = _nelder_mead(obj.equation_error, x0, steps, obj.lo, obj.hi, evals, 1e-7, args=(model,))
    return np.clip(res.x, obj.lo, obj.hi), float(res.fun)


def _search_equation_error(obj: _Objectives, pts: list, steps, max_evals: int, locate: bool):
    """The best point of the equation error: the best start point polished by a local search
    (kept only if it improves). With ``locate``, a start point is added first: the best one with
    the model's coefficients held at the vessel config's values, polished the same way."""
    if locate:
        # an identified model absorbs most of a wrong effect: its training error is flat except in a basin a
        # few % of U0 wide around the truth (measured: a current on an identified KVLCC2 hull), which a grid
        # misses. With the model's coefficients held at the vessel config's values (its prior) the basin is
        # wide: the effect is located that way first, then everything is identified from there.
        pv = [obj.equation_error(p, False) for p in pts]
        xp, _ = _local(obj, pts[int(np.argmin(pv))], steps, max_evals, False)
        pts = pts + [xp]
    vals = [obj.equation_error(p) for p in pts]
    x0 = pts[int(np.argmin(vals))]
    xb, fb = _local(obj, x0, steps, max_evals)
    return xb if fb <= min(vals) else x0


def _refine_on_replays(obj: _Objectives, best, steps, max_evals: int):
    """``best`` polished on the training records' replay error (a Nelder-Mead search with a
    simplex of a quarter of the first one's steps), kept only if it improves."""
    r2 = _nelder_mead(obj.replay_error, best, 0.25 * steps, obj.lo, obj.hi, max_evals, 1e-6)
    if r2.fun < obj.replay_error(best):
        return np.clip(r2.x, obj.lo, obj.hi)
    return best


def _fit_variant(pb, effects, variant, start, grid, fixed, refine, max_evals) -> Fit:
    """One variant of ``effects`` fitted (the arguments as for :func:`fit`): the equation error
    searched from the start points, then optionally refined on the replay error."""
    spec = pb.outer_params(effects)
    start = dict(start or {})
    fixed_vals = {n: start[n] for n in fixed if n in start}
    spec = [s for s in spec if s[0] not in fixed_vals]
    if not spec:
        vals = {**variant, **fixed_vals}
        coefs, J, rss = pb.solve(effects, vals)
        return Fit(effects, vals, coefs, J, rss, 1)
    obj = _Objectives(pb, effects, {**variant, **fixed_vals}, spec)
    known = {n: float(start[n]) for n in obj.names if isinstance(start.get(n), (int, float))}
    new = [s for s in spec if s[0] not in known]
    pts = _start_points(obj, new, known, grid)
    # a local search from the best start: Nelder-Mead with a simplex of half a grid step (Powell's line
    # searches span the whole box and, measured on an identified hull with a current, jump into another
    # basin)
    steps = np.array([_half_step(s[3], a, b) for s, a, b in zip(spec, obj.lo, obj.hi)])
    best = _search_equation_error(obj, pts, steps, max_evals, bool(pb.model_free and grid and new))
    if refine:
        best = _refine_on_replays(obj, best, steps, max_evals)
    outer = obj.outer_of(best)
    coefs, Jb, rss = pb.solve(effects, outer)
    return Fit(effects, outer, coefs, Jb, rss, obj.count)
