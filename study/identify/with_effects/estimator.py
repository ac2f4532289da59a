"""The estimator of a force model with effects (``model.effects=[current, ...]``): variable
projection (:func:`.search.fit`) behind the estimators' contract
(``study.identify.estimators.base``).

Its problem is a :class:`ModelWithEffects`: an :class:`~.problem.EffectsProblem` (the records, the
model and the effects' catalogue) and the effects to identify. The rows depend on the effects'
nonlinear parameters, so the problem is no regression problem: the estimator declares the problem
type ``"effects"`` and ``Estimator.fit_problem`` hands it to :meth:`VariableProjection.fit_effects`.

It is the one way a model with effects is identified: a study run (``study.identify.fit``, through
``fit_problem``) and the model doctor (its ranking, ladder, folds and refits, through
:func:`identify_effects`) both come to :meth:`VariableProjection.fit_effects`. The doctor fits one
problem many times; the problem keeps its caches (rows, replays) between fits, and ``fit_effects``'s
``start``, ``grid`` and ``fixed`` carry a warm start from one fit to the next.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..estimators.base import Estimator
from . import search
from .problem import EffectsProblem
from .search import Fit


@dataclass(frozen=True)
class ModelWithEffects:
    """The problem of the problem type ``"effects"``: an :class:`EffectsProblem` and the effects to
    identify.

    Attributes
    ----------
    problem : EffectsProblem
        The training records, the model's free coefficients and the effects' catalogue.
    effects : tuple of str
        The effects identified with the model (``model.effects``).
    """

    problem: EffectsProblem
    effects: tuple
    problem_type: ClassVar[str] = "effects"


class VariableProjection(Estimator):
    """Variable projection (Golub & Pereyra 1973) of a force model with effects.

    For given values of the effects' nonlinear parameters every linear unknown (the model's free
    coefficients, the effects' linear parameters) follows by least squares over X, Y and N together;
    the nonlinear parameters are searched (a grid, then a bounded Nelder-Mead search on the equation
    error) and, with ``refine``, polished on the training records' replay error.

    Parameters
    ----------
    refine : bool
        Polish the nonlinear parameters on the training records' replays.
    max_evals : int
        Evaluations of each local search.

    Attributes
    ----------
    coef_ : ndarray
        The estimate of each name in ``names_``: the effects' parameters in the user's terms
        (current as speed and direction, ...) and the free coefficients.
    names_ : list of str
        The names of ``coef_``.
    equations_ : dict
        ``{name: equation}``: a coefficient's equation, ``"effect"`` for an effect's parameter.
    coefficients_ : dict
        The vessel's identified coefficients (the model's and those the effects free).
    diagnostics_ : dict
        ``training_error`` (mean over X, Y, N of the residual over the target's sum of squares) and
        ``effect_evaluations``.
    vessel_ : study.sim.Vessel
        The identified model with its own steering gear, for closed-loop manoeuvres.
    fit_ : study.identify.with_effects.Fit
        The search's result.
    """

    problem_types: ClassVar[frozenset] = frozenset({"effects"})

    def __init__(self, refine: bool = True, max_evals: int = 100):
        self.refine = refine
        self.max_evals = max_evals

    def fit(self, X, y):
        raise NotImplementedError("VariableProjection fits a model with effects (fit_effects), not a regression")

    def fit_effects(self, problem: EffectsProblem, effects=(), start: dict | None = None, grid: bool = True,
                    fixed=()):
        """Identify ``problem``'s model with ``effects``. Returns ``self``.

        ``start``: values of nonlinear parameters to start from (a warm start from an earlier
        fit; the others start from their effect's grid); ``grid``: search the grid of start
        points of those ``start`` does not give; ``fixed``: nonlinear parameters held at their
        ``start`` values. ``fit_problem`` fits from the grids."""
        effects = tuple(effects)
        fit = search.fit(problem, effects, dict(start) if start else None, bool(grid), tuple(fixed),
                         bool(self.refine), int(self.max_evals))
        free = problem.free_coefficients(effects)  # coefficient -> equation (the model's and the effects')
        freed = {c: fit.coefs[c] for c in free if c in fit.coefs}
        values = {k: float(v) for k, v in {**problem.describe(fit), **freed}.items() if isinstance(v, (int, float))}
        self._init_outputs(len(values))
        self.names_ = list(values)
        self.coef_ = np.array([values[n] for n in self.names_], float)
        self.equations_ = {n: free.get(n, "effect") for n in self.names_}
        self.coefficients_ = {k: float(v) for k, v in fit.coefs.items() if k in problem.base.param_names}
        self.diagnostics_ = {"training_error": fit.training_error, "effect_evaluations": fit.evaluations}
        self.fit_, self.problem_, self.effects_ = fit, problem, effects
        return self

    @property
    def vessel_(self):
        """The identified model with its own steering gear, for closed-loop manoeuvres (built
        when asked: the doctor's many fits never need it)."""
        return self.problem_.vessel(self.effects_, self.fit_.values, None, self.fit_.coefs, replay=False)

    def replay(self, df, meta: dict | None = None, name: str = ""):
        """The identified model replayed through a record (its measured rudder and propeller, its
        own depth, the effects as identified), or None when it diverges
        (:meth:`EffectsProblem.predict`)."""
        pb = self.problem_
        return pb.predict(self.fit_, df, pb.info_for(df, meta, name))

    def predict(self, X):
        raise NotImplementedError("VariableProjection predicts by replaying a record (replay), not from rows")

    def skip(self, model, structure) -> tuple[bool, str]:
        if not getattr(model, "effects", ()):
            return True, (f"estimator 'VariableProjection' identifies a model with effects (model.effects); model "
                          f"'{model.name}' has none")
        if model.type != "kind" or structure.simulates:
            return True, "model.effects need a force model (type: kind) and a regression structure"
        return False, ""


def identify_effects(problem: EffectsProblem, effects=(), refine: bool = False, max_evals: int = 100,
                     start: dict | None = None, grid: bool = True, fixed=()) -> Fit:
    """``problem``'s model identified with ``effects`` by :class:`VariableProjection` (the
    estimator's ``fit_effects``, where ``fit_problem`` sends a study run's model with effects), with
    a warm start; the search's :class:`~.search.Fit`. ``refine``, ``max_evals``: the estimator's
    parameters (``refine`` off by default: the doctor polishes on the replays only in its ladder's
    steps); ``start``, ``grid``, ``fixed``: see
    :meth:`VariableProjection.fit_effects`."""
    est = VariableProjection(refine=refine, max_evals=max_evals)
    return est.fit_effects(problem, effects, start=start, grid=grid, fixed=fixed).fit_


def hidden_truth(problem: EffectsProblem, vessel) -> dict:
    """The effects' parameters of a simulated run as the truth vessel has them (its environment:
    current, wind, steering gear, constant forces), in the user's terms."""
    env = dict(zip(vessel.param_names, vessel.params))
    q = problem.scale
    return {"current_speed": env["current_speed"], "current_direction_deg": math.degrees(env["current_dir"]) % 360,
            "wind_speed": env["wind_speed"], "wind_direction_deg": math.degrees(env["wind_dir"]) % 360,
            "rudder_lag": env["rudder_lag"], "rudder_delay": env["rudder_delay"],
            "yaw_bias_Y": env["ext_Y"] / q[1], "yaw_bias_N": env["ext_N"] / q[2]}
