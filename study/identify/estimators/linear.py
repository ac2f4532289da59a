"""Linear least-squares estimators: ordinary least squares (more to come in this module: ridge, lasso)."""
from __future__ import annotations

import numpy as np
from scipy import linalg

from .base import Estimator, as_arrays


class LeastSquares(Estimator):
    """Ordinary least squares without intercept (the regressors carry every term of the model).

    Solved by LAPACK's gelsd (SVD), which stays defined when the regressors are nearly collinear.

    Parameters
    ----------
    rcond : float or None
        Relative cut-off for small singular values (None: machine precision times the larger dimension).
    """

    def __init__(self, rcond: float | None = None):
        self.rcond = rcond

    def fit(self, X, y):
        X, y, _ = as_arrays(X, y)
        self._init_outputs(X.shape[1])
        coef, _, rank, sv = linalg.lstsq(X, y, cond=self.rcond, lapack_driver="gelsd")
        self.coef_ = coef
        self.rank_ = int(rank)
        self.singular_values_ = sv
        self.diagnostics_ = {"rank": int(rank)}
        return self
