"""Estimators with the scikit-learn contract: ``__init__`` stores hyper-parameters, ``fit(X, y)`` returns
self and sets ``coef_``. This issue has ordinary least squares; the others join the registry next.
"""
from __future__ import annotations

import numpy as np
from scipy import linalg
from sklearn.base import BaseEstimator, RegressorMixin


class LeastSquares(RegressorMixin, BaseEstimator):
    """Ordinary least squares without intercept (the regressors carry every term of the model).

    Solved by LAPACK's gelsd (SVD), which stays defined when the regressors are nearly collinear.
    """

    def __init__(self, rcond: float | None = None):
        self.rcond = rcond

    def fit(self, X, y):
        X = np.asarray(X, float)
        y = np.asarray(y, float)
        coef, _, rank, sv = linalg.lstsq(X, y, cond=self.rcond, lapack_driver="gelsd")
        self.coef_ = coef
        self.rank_ = int(rank)
        self.singular_values_ = sv
        return self

    def predict(self, X):
        return np.asarray(X, float) @ self.coef_


ESTIMATORS = {"ls": LeastSquares}


def make_estimator(name: str, **params):
    if name not in ESTIMATORS:
        raise ValueError(f"unknown estimator '{name}'; known: {sorted(ESTIMATORS)}")
    return ESTIMATORS[name](**params)
