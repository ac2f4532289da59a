"""The contract every estimator follows (scikit-learn style; see
``study/identify/estimators/__init__.py``).

- ``__init__`` only stores hyper-parameters (``get_params`` / ``clone`` round-trip); nothing
  data-dependent.
- ``fit(X, y)`` (regression: ``y = X theta + e``, no intercept in the model) learns and returns
  ``self``. ``X`` is an (n, k) array or a DataFrame whose column names are the parameter names.
- ``fit_output_error(problem)`` (only estimators that simulate): ``problem`` is a
  :class:`study.identify.output_error.OutputErrorProblem`; learns the same attributes.
- ``fit_effects(problem, effects)`` (only estimators of models with effects): ``problem`` is a
  ``study.identify.with_effects.EffectsProblem``.

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
    an estimator under a prior (``fit(X, y, prior={column: (mean, sd)})``): the prior and the ratio
    of posterior to prior standard deviation (near 0: the records determine the coefficient; near 1:
    the prior does).
``selected_`` (k,) bool — optional
    terms kept by a selecting estimator (lasso, sindy).
``diagnostics_`` dict
    scalar figures worth a column in the results table (regularisation chosen, rank, acceptance...).
``artefacts_`` dict
    name -> ``pandas.DataFrame`` (saved as CSV) or ``bytes`` (saved as is): curves and chains that
    the figures are rebuilt from (L-curve, online convergence, emcee chain).

Class attributes declare what an estimator can do (the base class gives every default):

``problem_types``
    subset of ``{"regression", "output_error", "effects"}``; ``fit_output_error`` exists for the
    second, ``fit_effects(problem, effects)`` for the third (a force model with ``model.effects``:
    an ``study.identify.with_effects.EffectsProblem`` whose rows change with the effects' nonlinear
    parameters;
    ``study.identify.with_effects.estimator.VariableProjection``).
``accepts_prior``
    ``fit`` takes ``prior={column: (mean, sd)}``.
``models_row_noise``
    ``fit`` takes ``noise_operators`` (``study.identify.row_noise.RowOperators``) and ``row_errors``
    (``study.identify.row_errors.RowErrors``), and sets ``row_noise_`` (the fitted noise model or
    None). Whether one instance wants them (its likelihood) is
    :attr:`Estimator.uses_noise_operators` and
    :attr:`Estimator.uses_row_errors`.
``checks_omitted_terms``
    ``fit`` takes ``neighbours``: columns of terms the model lacks, on the same rows (its trust
    verdict tests the model against them, ``study.identify.trust.omitted_terms``).
``reports_progress``
    ``fit`` (and ``fit_output_error``) take ``progress``.

The engine (``study.identify.fit``) calls one method, :meth:`Estimator.fit_problem`, with a
:class:`.problem.RegressionProblem`, an output-error problem or a model with effects (each names its
``problem_type``); it checks the problem once and hands ``fit`` only what the declarations say. A
contract test checks each declaration against the signatures. ``skip(model, structure)`` returns
``(True, reason)`` for a pairing that makes no sense (benchopt's skip hook); the run is then
recorded as 'skipped' with the reason, never raised. ``trust_verdict`` judges a regression run's
intervals (None: the estimator gives no verdict).
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np


_NO_TARGET = object()  # as_arrays(X) for predict: no target asked for (None passed for one is an error)


def as_arrays(X, y=_NO_TARGET):
    """(X as float array, y as float array or None, column names) from arrays or a DataFrame,
    refused with scikit-learn's messages where its conventions name one (sparse, complex, empty,
    missing or 2-D targets)."""
    if hasattr(X, "tocsr") or hasattr(X, "toarray"):
        raise TypeError("sparse input is not supported: expected a dense 2-D array of regressors (X.toarray())")
    names = [str(c) for c in X.columns] if hasattr(X, "columns") else None
    Xa = np.asarray(X)
    yc = None if y is None or y is _NO_TARGET else np.asarray(y)
    if np.iscomplexobj(Xa) or (yc is not None and np.iscomplexobj(yc)):
        raise ValueError("Complex data not supported: expected real regressors and targets")
    Xa = Xa.astype(float)
    if Xa.ndim != 2:
        raise ValueError(f"X must be 2-D (samples x regressors), got shape {Xa.shape}: Reshape your data with "
                         "X.reshape(-1, 1) for one regressor or X.reshape(1, -1) for one sample")
    if Xa.shape[0] == 0:
        raise ValueError(f"Found array with 0 sample(s) (shape={Xa.shape}) while a minimum of 1 is required.")
    if Xa.shape[1] == 0:
        raise ValueError(f"Found array with 0 feature(s) (shape={Xa.shape}) while a minimum of 1 is required.")
    if names is None:
        names = [f"x{i}" for i in range(Xa.shape[1])]
    if y is None:
        raise ValueError("this estimator requires y to be passed, but the target y is None")
    ya = None
    if y is not _NO_TARGET:
        ya = yc.astype(float)
        if ya.ndim == 2 and ya.shape[1] == 1:
            import warnings

            from sklearn.exceptions import DataConversionWarning  # only here: scikit-learn costs a second to import

            warnings.warn("A column-vector y was passed when a 1d array was expected: y.ravel() used",
                          DataConversionWarning, stacklevel=3)
        elif ya.ndim != 1:
            raise ValueError(f"y should be a 1d array (one target), got shape {ya.shape}")
        ya = ya.ravel()
        if ya.shape[0] != Xa.shape[0]:
            raise ValueError(f"X has {Xa.shape[0]} rows but y has {ya.shape[0]}")
    if not (np.all(np.isfinite(Xa)) and (ya is None or np.all(np.isfinite(ya)))):
        raise ValueError("X and y must be finite (a sample structure left NaN/inf in the regression)")
    return Xa, ya, names


class Estimator:
    """Base class: capabilities, the skip hook, and ``predict``. Subclasses implement ``fit``.

    scikit-learn's parameter protocol (``get_params``/``set_params``, so that
    ``sklearn.base.clone`` works) and ``score`` are scikit-learn's own (``BaseEstimator``,
    ``RegressorMixin``), called on first use rather than inherited: importing scikit-learn costs
    about 1 s of CPU (it imports scipy.stats), which every fresh worker would pay before its
    first run; runs by ls, lssvm, the SVR QPs, DE and emcee never need it."""

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

    #: scikit-learn before 1.6 reads the estimator type from this attribute, later versions from the tags
    _estimator_type: ClassVar[str] = "regressor"

    def __sklearn_tags__(self):
        """scikit-learn's tags (1.6 and later: ``is_regressor``, ``cross_val_score`` and
        ``check_estimator`` ask for them): a regressor of a dense, finite, 2-D ``X`` and a 1-D
        ``y``, as :func:`as_arrays` requires."""
        from sklearn.utils import InputTags, RegressorTags, Tags, TargetTags

        return Tags(estimator_type="regressor", target_tags=TargetTags(required=True, single_output=True),
                    regressor_tags=RegressorTags(), input_tags=InputTags(two_d_array=True, allow_nan=False,
                                                                         sparse=False))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in self.get_params(deep=False).items())})"

    problem_types: ClassVar[frozenset] = frozenset({"regression"})
    #: ``fit`` takes ``prior={column: (mean, sd)}``
    accepts_prior: ClassVar[bool] = False
    #: ``fit`` takes ``noise_operators`` and ``row_errors`` and sets ``row_noise_``
    models_row_noise: ClassVar[bool] = False
    #: ``fit`` takes ``neighbours`` (terms the model lacks, on the same rows) and tests the model against them
    checks_omitted_terms: ClassVar[bool] = False
    #: ``fit`` and ``fit_output_error`` take ``progress``
    reports_progress: ClassVar[bool] = False

    @property
    def uses_noise_operators(self) -> bool:
        """Whether this instance's ``fit`` wants the structure's noise operators
        (``models_row_noise`` only)."""
        return False

    @property
    def uses_row_errors(self) -> bool:
        """Whether this instance's ``fit`` wants the rows' errors removed (``models_row_noise``
        only)."""
        return False

    @property
    def row_error_probes(self) -> int | None:
        """Noisy copies of the records the regressors' noise is measured with (None: the engine's
        default)."""
        return None

    def fit_problem(self, problem, progress: bool = False):
        """Fit a problem of one of the ``problem_types`` (its ``problem_type``): a
        :class:`.problem.RegressionProblem`, an output-error problem or a model with effects: the
        engine's one
        entry.

        The problem is checked against the declared capabilities, then ``fit``
        (``fit_output_error``, ``fit_effects``) gets the rows and what the estimator declares it
        takes. Returns ``self``."""
        kind = getattr(problem, "problem_type", "output_error")
        if kind not in self.problem_types:
            raise NotImplementedError(f"{type(self).__name__} does not fit {kind.replace('_', '-')} problems")
        kwargs = {"progress": bool(progress)} if self.reports_progress else {}
        if kind == "output_error":
            return self.fit_output_error(problem, **kwargs)
        if kind == "effects":
            return self.fit_effects(problem.problem, effects=problem.effects, **kwargs)
        kwargs.update(self._problem_inputs(problem))
        return self.fit(problem.X, problem.y, **kwargs)

    def _problem_inputs(self, problem) -> dict:
        """The keyword arguments of ``fit`` a regression problem supplies, refused where not
        declared."""
        out = {}
        if problem.prior is not None:
            missing = problem.missing_prior()
            if missing:
                raise ValueError(f"equation {problem.equation}: the prior has no value for {missing}")
            if not self.accepts_prior:
                raise ValueError(f"{type(self).__name__} takes no prior (accepts_prior is False)")
            out["prior"] = problem.prior
        for name in ("noise_operators", "row_errors"):
            value = getattr(problem, name)
            if value is None:
                continue
            if not self.models_row_noise:
                raise ValueError(f"{type(self).__name__} does not model the rows' noise: no {name} for it")
            out[name] = value
        if problem.neighbours is not None:
            if not self.checks_omitted_terms:
                raise ValueError(f"{type(self).__name__} does not check for omitted terms: no neighbours for it")
            out["neighbours"] = problem.neighbours
        return out

    def trust_verdict(self, structure_name: str, bias_sd: dict, dropped_differences: int, corrected: bool,
                      metrics: dict) -> tuple[bool, str] | None:
        """``(trusted, note)`` of a regression run's intervals, or None: this estimator gives no
        verdict."""
        return None

    def skip(self, model, structure) -> tuple[bool, str]:
        """``(True, reason)`` when this estimator cannot be used with this model and sample
        structure."""
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

    def fit_effects(self, problem, effects=()):  # pragma: no cover - overridden by estimators of effects
        raise NotImplementedError(f"{type(self).__name__} does not fit models with effects")

    def predict(self, X):
        if not hasattr(self, "coef_"):
            from sklearn.exceptions import NotFittedError

            raise NotFittedError(f"This {type(self).__name__} instance is not fitted yet: call fit first")
        Xa, _, _ = as_arrays(X)
        if Xa.shape[1] != len(np.ravel(self.coef_)):
            raise ValueError(f"X has {Xa.shape[1]} features, but {type(self).__name__} is expecting "
                             f"{len(np.ravel(self.coef_))} features as input")
        return Xa @ self.coef_ + getattr(self, "intercept_", 0.0)

    def _init_outputs(self, k: int) -> None:
        """Reset the optional learned attributes before a fit (so a refit leaves no stale ones)."""
        self.n_features_in_ = int(k)
        self.intercept_ = 0.0
        self.diagnostics_ = {}
        self.artefacts_ = {}
        for a in ("coef_std_", "coef_interval_", "interval_level_", "samples_", "selected_", "prior_mean_",
                  "prior_sd_", "identifiability_"):
            if hasattr(self, a):
                delattr(self, a)
