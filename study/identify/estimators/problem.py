"""The regression problem an estimator is handed (:meth:`.base.Estimator.fit_problem`).

One equation of a model, ``y = X theta + e``, with what the run knows about it: the prior of its
coefficients and, for an estimator that models the rows' noise, the structure's noise operators and
the rows' errors. The output-error problem is
:class:`study.identify.output_error.OutputErrorProblem`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class RegressionProblem:
    """One equation's regression rows and what comes with them.

    Attributes
    ----------
    X : pandas.DataFrame
        Training rows; the column names are the regression coefficients' names.
    y : numpy.ndarray
        The target, one value per row.
    prior : dict or None
        ``{column: (mean, sd)}`` for every column, or None (no prior).
    noise_operators : study.identify.row_noise.RowOperators or None
        The structure's noise operators of the training rows.
    row_errors : study.identify.row_errors.RowErrors or None
        The rows' truncation errors and the probes of the regressors' noise.
    equation : str
        The equation's name, for messages.
    neighbours : pandas.DataFrame or None
        Terms the model lacks (its states' monomials, ``Model.candidates``), built by the same
        structure on the same training rows: what an estimator that checks its model
        (``checks_omitted_terms``) tests it against.
    """

    X: pd.DataFrame
    y: np.ndarray
    prior: dict | None = None
    noise_operators: object = None
    row_errors: object = None
    equation: str = ""
    neighbours: pd.DataFrame | None = None
    problem_type: ClassVar[str] = "regression"

    @property
    def names(self) -> list:
        return list(self.X.columns)

    def missing_prior(self) -> list:
        """The columns a prior has no value for (empty without a prior)."""
        return [] if self.prior is None else [n for n in self.names if n not in self.prior]
