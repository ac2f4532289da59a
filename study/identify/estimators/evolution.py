"""Differential evolution (Storn & Price 1997), scipy's implementation, on the output error or a
regression.

Zheng & Xiao (2017, Sec. 1.1, eqs. 1-5) identifies the nonlinear KT parameters by DE with the "best"
mutation (eq. 3), binomial crossover (eq. 4) and greedy selection (eq. 5): scipy's
``strategy='best1bin'``. Every generation is evaluated in ONE call (``vectorized=True``): on an
output-error problem the whole population is simulated in lock-step by the compiled batch integrator
(``study.identify.output_error``), which is what makes DE affordable. All the records of a run enter
one objective (Zheng & Xiao's (2017) "parallel processing", Sec. 1.2). The result is polished by a
bounded Gauss-Newton fit (``output_error.local_fit``: its Jacobian is one batch simulation too) when
``polish`` is set.

On a regression structure DE minimises the mean squared equation error inside a box around the
least-squares solution; it then finds least squares again (slowly). It is there so that DE can be
compared on every structure, as Zheng & Xiao (2017) compares it on differences and on integration.
"""
from __future__ import annotations

import numpy as np
from scipy import linalg
from scipy.optimize import OptimizeResult, differential_evolution

from .base import Estimator, as_arrays


class DifferentialEvolution(Estimator):
    """scipy.optimize.differential_evolution with a vectorised objective.

    Parameters
    ----------
    strategy : str
        scipy's mutation strategy ('best1bin' = Zheng & Xiao (2017) eq. 3 with binomial crossover).
    popsize : int
        Population = popsize x number of parameters (scipy's convention).
    maxiter : int
        Generations at most.
    tol, atol : float
        scipy's convergence test on the population's spread of costs.
    mutation, recombination : scipy's F (a range means dithering) and CR.
    init : str
        'sobol' or 'latinhypercube' initial population over the box.
    polish : bool
        Finish with a bounded Gauss-Newton (output error) / L-BFGS-B (regression) local fit.
    seed : int
    box_relative, box_floor : float
        Regression only: the box is theta_LS +- max(box_relative |theta_LS|, box_floor
        max|theta_LS|).
    use_x0 : bool
        Output error: put the problem's initial estimate (equation-error least squares) into the
        initial population. Off by default: Zheng & Xiao's (2017) point is that DE needs no initial
        values.
    """

    problem_types = frozenset({"regression", "output_error"})
    reports_progress = True

    def __init__(self, strategy: str = "best1bin", popsize: int = 15, maxiter: int = 300, tol: float = 1e-6,
                 atol: float = 0.0, mutation=(0.5, 1.0), recombination: float = 0.9, init: str = "sobol",
                 polish: bool = True, seed: int = 0, box_relative: float = 1.0, box_floor: float = 0.05,
                 use_x0: bool = False):
        self.strategy = strategy
        self.popsize = popsize
        self.maxiter = maxiter
        self.tol = tol
        self.atol = atol
        self.mutation = mutation
        self.recombination = recombination
        self.init = init
        self.polish = polish
        self.seed = seed
        self.box_relative = box_relative
        self.box_floor = box_floor
        self.use_x0 = use_x0

    def _run(self, func, bounds, polish, progress: bool, x0=None):
        bar = None
        if progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=self.maxiter, desc="DE generations", leave=False)

        def callback(intermediate_result):
            if bar is not None:
                bar.update(1)
                bar.set_postfix(cost=f"{intermediate_result.fun:.4g}")

        try:
            res = differential_evolution(
                func, bounds, strategy=self.strategy, maxiter=self.maxiter, popsize=self.popsize, tol=self.tol,
                atol=self.atol, mutation=tuple(self.mutation) if isinstance(self.mutation, (list, tuple))
                else self.mutation, recombination=self.recombination, seed=self.seed, polish=polish,
                init=self.init, vectorized=True, updating="deferred", callback=callback, x0=x0)
        finally:
            if bar is not None:
                bar.close()
        return res

    def fit(self, X, y, progress: bool = False):
        X, y, _ = as_arrays(X, y)
        self._init_outputs(X.shape[1])
        # equation error in the stable centred form: SS(theta) = SS_min + (theta - ls)^T A (theta - ls)
        ls, _, _, _ = linalg.lstsq(X, y, lapack_driver="gelsd")
        A = X.T @ X
        n = len(y)
        ss_min = float(np.sum((y - X @ ls) ** 2))
        w = np.maximum(self.box_relative * np.abs(ls), self.box_floor * np.max(np.abs(ls)) + 1e-300)
        bounds = np.column_stack([ls - w, ls + w])

        def cost(theta):
            t = np.asarray(theta, float)
            d = (t.T if t.ndim == 2 else t[None, :]) - ls
            c = (ss_min + np.einsum("bi,ij,bj->b", d, A, d)) / n
            return c if t.ndim == 2 else float(c[0])

        res = self._run(cost, bounds, self.polish, progress)
        self.coef_ = np.asarray(res.x, float)
        self.result_ = res
        self.diagnostics_ = {"nfev": int(res.nfev), "nit": int(res.nit), "success": float(bool(res.success)),
                             "cost": float(res.fun)}
        return self

    def fit_output_error(self, problem, progress: bool = False):
        from ..output_error import local_fit

        self._init_outputs(problem.k)
        n0 = problem.n_sim

        def polish(func, x, bounds=None, constraints=None):
            r = local_fit(problem, x)
            return OptimizeResult(x=r.x, fun=r.fun, success=r.success, nfev=r.nfev)

        x0 = None
        if self.use_x0 and problem.x0 is not None and np.all(np.isfinite(problem.x0)):
            lo, hi = problem.bounds[:, 0], problem.bounds[:, 1]
            x0 = np.clip(problem.x0, lo, hi)
        res = self._run(problem.cost, problem.bounds, polish if self.polish else False, progress, x0=x0)
        self.coef_ = np.asarray(res.x, float)
        self.result_ = res
        self.diagnostics_ = {"nfev": int(res.nfev), "nit": int(res.nit), "success": float(bool(res.success)),
                             "cost": float(res.fun), "simulations": int(problem.n_sim - n0)}
        return self
