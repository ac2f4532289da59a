"""Step-by-step identification by differential evolution on the output error: Zou et al.'s method,
the comparator of Zheng & Xiao (2017, Sec. 3.1).

Zheng & Xiao (2017) identify every parameter of the nonlinear KT model at once from several records
("parallel processing", :class:`.evolution.DifferentialEvolution`) and set it against the
step-by-step method of their reference [3] (Zou et al.), which they quote:

1. K from a turning test at a small rudder angle;
2. with K fixed, alpha from a turning test at a large rudder angle;
3. with K and alpha fixed, T (T1, T2, T3) from a zigzag at a large rudder angle.

:class:`StagedEvolution` runs those stages on the same records the parallel fit uses. Each stage is
an output-error fit by differential evolution on the records it names (their indices in the run's
training manoeuvres, in order) of every parameter not kept by an earlier stage nor held by this one
(``hold``: values for this stage only); it then keeps the parameters it names (``keep``), and the
last stage keeps everything. Stage 1 holds alpha at zero (a small-rudder turn is taken as linear:
one steady turn cannot tell K from alpha, K delta = r + alpha r^3) and fits T on the turn as a
nuisance, keeping only K. Assumption (labelled): the quoted steps do not say how K is read from the
turn; here it is the output-error fit of the turn's heading, the same fit the parallel method uses,
so that the two differ only in staging.
"""
from __future__ import annotations

import copy

import numpy as np

from .evolution import DifferentialEvolution

__all__ = ["StagedEvolution"]

#: Zou et al.'s steps for records ordered (small turn, large turn, large zigzag); ``parameters`` are kept
ZOU_STAGES = ({"records": [0], "hold": {"alpha": 0.0}, "keep": ["K"]}, {"records": [1], "keep": ["alpha"]},
              {"records": [2]})


def _restricted(problem, segments: list):
    """A copy of an output-error problem over some of its segments (its initial-state parameters
    with them)."""
    sub = copy.copy(problem)
    sub.segments = [problem.segments[i] for i in segments]
    where = {old: new for new, old in enumerate(segments)}
    keep = [j for j, (seg, _, _) in enumerate(problem.init_params) if seg in where]
    sub.init_params = [(where[problem.init_params[j][0]],) + tuple(problem.init_params[j][1:]) for j in keep]
    sub.names = problem.model_names + [problem.init_params[j][2] for j in keep]
    rows = list(range(problem.k_model)) + [problem.k_model + j for j in keep]
    sub.bounds = None if problem.bounds is None else problem.bounds[rows]
    sub.x0 = None if problem.x0 is None else problem.x0[rows]
    sub.n_total = int(sum(len(s["Y"]) for s in sub.segments))
    sub.n_obs = np.array([sub.n_total] * len(problem.outputs))
    return sub, keep


class _Fixed:
    """An output-error problem with some model parameters held: the interface :func:`local_fit`
    and DE use (``k``, ``bounds``, ``cost``, ``residuals``, ``last_diverged``, ``n_total``,
    ``polish_skipped``), over the free parameters only."""

    def __init__(self, problem, free: list, held: dict):
        self.problem, self.free = problem, free
        self.full = np.array([held.get(n, np.nan) for n in problem.names], float)
        self.idx = [problem.names.index(n) for n in free]
        self.bounds = problem.bounds[self.idx]
        self.k = len(free)
        self.n_total = problem.n_total
        self.polish_skipped = 0

    @property
    def last_diverged(self):
        return self.problem.last_diverged

    def expand(self, x) -> np.ndarray:
        x = np.asarray(x, float)
        X = np.repeat(self.full[:, None], 1 if x.ndim == 1 else x.shape[1], axis=1)
        X[self.idx] = x if x.ndim == 2 else x[:, None]
        return X

    def cost(self, x):
        c = self.problem.cost(self.expand(x))
        return float(np.ravel(c)[0]) if np.ndim(x) == 1 else c

    def residuals(self, X, scale=None):
        return self.problem.residuals(self.expand(X), scale)


class StagedEvolution(DifferentialEvolution):
    """Differential evolution in stages (Zou et al.'s step-by-step identification), output error
    only.

    Parameters
    ----------
    stages : list of dict
        Each ``{"records": [i, ...], "hold": {name: value}, "keep": [name, ...]}``: the training
        records (indices, in the order of the run's training manoeuvres) the stage fits, parameters
        held at a value in this stage only, and the model parameters it fixes for the stages after
        it (the last stage fixes all). Default: Zou et al.'s three steps for (small turn, large
        turn, large zigzag).
    **kwargs
        :class:`.evolution.DifferentialEvolution`'s hyper-parameters, used in every stage.
    """

    problem_types = frozenset({"output_error"})

    def __init__(self, stages=ZOU_STAGES, strategy: str = "best1bin", popsize: int = 15, maxiter: int = 300,
                 tol: float = 1e-6, atol: float = 0.0, mutation=(0.5, 1.0), recombination: float = 0.9,
                 init: str = "sobol", polish: bool = True, seed: int = 0, box_relative: float = 1.0,
                 box_floor: float = 0.05, use_x0: bool = False):
        super().__init__(strategy=strategy, popsize=popsize, maxiter=maxiter, tol=tol, atol=atol, mutation=mutation,
                         recombination=recombination, init=init, polish=polish, seed=seed,
                         box_relative=box_relative, box_floor=box_floor, use_x0=use_x0)
        self.stages = stages

    def _check_stages(self, problem) -> list:
        stages = [dict(s) for s in (self.stages or [])]
        records = sorted({s["record"] for s in problem.segments})
        if not stages:
            raise ValueError("staged DE: 'stages' is empty; give [{records: [0], keep: [K]}, ...]")
        for i, s in enumerate(stages):
            bad = [r for r in s.get("records", []) if r not in records]
            if not s.get("records") or bad:
                raise ValueError(f"staged DE: stage {i + 1} names records {s.get('records')}; the run's training "
                                 f"records with a usable segment are {records} (in the order of maneuvers.train)")
            unknown = [n for n in list(s.get("keep") or []) + list(s.get("hold") or {})
                       if n not in problem.model_names]
            if unknown:
                raise ValueError(f"staged DE: stage {i + 1} keeps or holds {unknown}, not parameters of the model "
                                 f"({', '.join(problem.model_names)})")
        return stages

    def fit_output_error(self, problem, progress: bool = False):
        from scipy.optimize import OptimizeResult

        from ..output_error import local_fit

        stages = self._check_stages(problem)
        self._init_outputs(problem.k)
        n0 = problem.n_sim
        held: dict = {}
        coef = np.full(problem.k, np.nan)
        nfev = nit = sims = 0
        success = True
        for i, stage in enumerate(stages):
            segs = [j for j, s in enumerate(problem.segments) if s["record"] in stage["records"]]
            sub, inits = _restricted(problem, segs)
            hold = {**{k: float(v) for k, v in (stage.get("hold") or {}).items()}, **held}
            free = [n for n in sub.names if n not in hold]
            view = _Fixed(sub, free, hold)

            def polish(func, x, bounds=None, constraints=None, view=view):
                r = local_fit(view, x)
                return OptimizeResult(x=r.x, fun=r.fun, success=r.success, nfev=r.nfev)

            res = self._run(view.cost, view.bounds, polish if self.polish else False, progress)
            problem.polish_skipped += view.polish_skipped
            sims += sub.n_sim - n0  # the restricted copy counts its own replays
            x = view.expand(res.x)[:, 0]
            nfev, nit, success = nfev + int(res.nfev), nit + int(res.nit), success and bool(res.success)
            last = i == len(stages) - 1
            for n in (problem.model_names if last else stage.get("keep") or []):
                held.setdefault(n, float(x[sub.names.index(n)]))
            for jj, j in enumerate(inits):  # each segment's initial state from the stage that fitted it
                coef[problem.k_model + j] = x[problem.k_model + jj]
        coef[:problem.k_model] = [held[n] for n in problem.model_names]
        # a segment no stage fitted keeps its measured initial state
        miss = np.isnan(coef)
        if miss.any():
            start = np.array([problem.segments[s]["state0"][row] for s, row, _ in problem.init_params])
            coef[miss] = start[miss[problem.k_model:]]
        self.coef_ = coef
        self.result_ = None
        self.diagnostics_ = {"nfev": nfev, "nit": nit, "success": float(success), "stages": float(len(stages)),
                             "cost": float(problem.cost(coef)), "simulations": int(sims)}
        return self
