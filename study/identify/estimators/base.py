"""The contract every estimator follows (scikit-learn style; see ``study/identify/estimators/__init__.py``).

- ``__init__`` only stores hyper-parameters (``get_params`` / ``clone`` round-trip); nothing data-dependent.
- ``fit(X, y)`` (regression: ``y = X theta + e``, no intercept in the model) learns and returns ``self``.
  ``X`` is an (n, k) array or a DataFrame whose column names are the parameter names.
- ``fit_output_error(problem)`` (only estimators that simulate): ``problem`` is a
  :class:`study.identify.output_error.OutputErrorProblem`; learns the same attributes.

Learned attributes (trailing underscore):

``coef_`` (k,)
    the estimate, in the units of the columns of ``X`` (or of ``problem.names``).
``intercept_`` float
    0.0 for estimators without one.
``coef_std_`` (k,), ``coef_interval_`` (k, 2), ``interval_level_`` float — optional
    a standard deviation and an interval (credible or confidence, at ``interval_level_``, e.g. 0.9).
``samples_`` (m, k) — optional
    draws from a posterior (emcee); the model turns them into intervals of derived parameters.
``prior_mean_``, ``prior_sd_``, ``identifiability_`` (k,) — optional
    an estimator under a prior (``fit(X, y, prior={column: (mean, sd)})``): the prior and the ratio of posterior
    to prior standard deviation (near 0: the records determine the coefficient; near 1: the prior does).
``selected_`` (k,) bool — optional
    terms kept by a selecting estimator (lasso, sindy).
``diagnostics_`` dict
    scalar figures worth a column in the results table (regularisation chosen, rank, acceptance...).
``artefacts_`` dict
    name -> ``pandas.DataFrame`` (saved as CSV) or ``bytes`` (saved as is): curves and chains that the figures
    are rebuilt from (L-curve, online convergence, emcee chain).

Class attributes say what an estimator can do: ``problem_types`` (subset of ``{"regression",
"output_error"}``). ``skip(model, structure)`` returns ``(True, reason)`` for a pairing that makes no sense
(benchopt's skip hook); the run is then recorded as 'skipped' with the reason, never raised.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np


def as_arrays(X, y=None):
    """(X as float array, y as float array or None, column names) from arrays or a DataFrame."""
    names = [str(c) for c in X.columns] if hasattr(X, "columns") else None
    Xa = np.asarray(X, dtype=float)
    if Xa.ndim != 2:
        raise ValueError(f"X must be 2-D (samples x regressors), got shape {Xa.shape}")
    if names is None:
        names = [f"x{i}" for i in range(Xa.shape[1])]
    ya = None
    if y is not None:
        ya = np.asarray(y, dtype=float).ravel()
        if ya.shape[0] != Xa.shape[0]:
            raise ValueError(f"X has {Xa.shape[0]} rows but y has {ya.shape[0]}")
    if not (np.all(np.isfinite(Xa)) and (ya is None or np.all(np.isfinite(ya)))):
        raise ValueError("X and y must be finite (a sample structure left NaN/inf in the regression)")
    return Xa, ya, names


class Estimator:
    """Base class: capabilities, the skip hook, and ``predict``. Subclasses implement ``fit``.

    scikit-learn's parameter protocol (``get_params``/``set_params``, so that ``sklearn.base.clone`` works) and
    ``score`` are scikit-learn's own (``BaseEstimator``, ``RegressorMixin``), called on first use rather than
    inherited: importing scikit-learn costs about 1 s of CPU (it imports scipy.stats), which every fresh worker
    would pay before its first run; runs by ls, lssvm, the SVR QPs, DE and emcee never need it."""

    @classmethod
    def _get_param_names(cls):
        from sklearn.base import BaseEstimator

        return BaseEstimator._get_param_names.__func__(cls)

    def get_params(self, deep: bool = True) -> dict:
        from sklearn.base import BaseEstimator

        return BaseEstimator.get_params(self, deep=deep)

    def set_params(self, **params):
        from sklearn.base import BaseEstimator

        return BaseEstimator.set_params(self, **params)

    def score(self, X, y, sample_weight=None) -> float:
        from sklearn.base import RegressorMixin

        return RegressorMixin.score(self, X, y, sample_weight=sample_weight)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in self.get_params(deep=False).items())})"

    problem_types: ClassVar[frozenset] = frozenset({"regression"})

    def skip(self, model, structure) -> tuple[bool, str]:
        """``(True, reason)`` when this estimator cannot be used with this model and sample structure."""
        kind = "output_error" if structure.simulates else "regression"
        if kind not in self.problem_types:
            what = ("simulates the model through the record (output error)" if kind == "output_error"
                    else "builds a regression from samples")
            can = " and ".join(sorted(self.problem_types))
            return True, (f"estimator '{type(self).__name__}' does {can} only; structure "
                          f"'{structure.name}' {what}")
        return False, ""

    def fit_output_error(self, problem):  # pragma: no cover - overridden by estimators that simulate
        raise NotImplementedError(f"{type(self).__name__} does not fit output-error problems")

    def predict(self, X):
        Xa = np.asarray(X, dtype=float)
        return Xa @ self.coef_ + getattr(self, "intercept_", 0.0)

    def _init_outputs(self, k: int) -> None:
        """Reset the optional learned attributes before a fit (so a refit leaves no stale ones)."""
        self.intercept_ = 0.0
        self.diagnostics_ = {}
        self.artefacts_ = {}
        for a in ("coef_std_", "coef_interval_", "interval_level_", "samples_", "selected_", "prior_mean_",
                  "prior_sd_", "identifiability_"):
            if hasattr(self, a):
                delattr(self, a)
