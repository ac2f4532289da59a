"""Linear least-squares estimators: ordinary least squares, ridge (contiguous K-fold CV) and lasso
(LassoCV).

Also the small helpers the other estimator modules share: column standardisation without centring
(the regressions have no intercept) and the R factor of ``[Z, y]`` from which every ridge-type
solution and its residual norm follow stably (no normal equations).
"""
from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy import linalg

from .base import Estimator, as_arrays


# ----------------------------------------------------------------------------------------------- helpers
def check_regression(X, y):
    """``as_arrays`` plus the checks every estimator needs: at least 2 samples and 1 regressor."""
    Xa, ya, names = as_arrays(X, y)
    if ya is None:
        raise ValueError("y is required")
    if Xa.shape[0] < 2 or Xa.shape[1] < 1:
        raise ValueError(f"n_samples = {Xa.shape[0]}: need at least 2 samples and 1 regressor, got X of shape "
                         f"{Xa.shape}")
    return Xa, ya, names


def column_scale(X) -> np.ndarray:
    """Root mean square of each column (1 for an all-zero column).

    The regressions have no intercept, so columns are scaled but never centred: ``Z = X / s`` has
    unit mean square per column, and a coefficient on ``Z`` is ``b_j = theta_j * s_j``.
    """
    s = np.sqrt(np.mean(X * X, axis=0))
    s[~(s > 0)] = 1.0
    return s


def rms(y) -> float:
    v = float(np.sqrt(np.mean(np.asarray(y) ** 2)))
    return v if v > 0 else 1.0


def r_factor(Z, y, block: int = 2048) -> np.ndarray:
    """Upper-triangular ``R`` ((k+1) x (k+1)) of the QR factorisation of ``[Z, y]``.

    ``[Z, y] = Q R`` gives, for any coefficient vector ``w``: ``||y - Z w|| = ||R @ [-w, 1]||``; the
    leading k x k block is the R of Z, column k holds ``Q^T y`` and ``R[k, k]**2`` is the
    least-squares residual. Computed blockwise (tall-skinny QR: QR of each block, then of the
    stacked R's), which is both faster (cache) and as stable as one Householder QR. Rows of zeros
    are appended when n < k + 1.
    """
    A = np.column_stack([Z, y])
    m = A.shape[1]
    if A.shape[0] > block:
        parts = [linalg.qr(A[i:i + block], mode="r", check_finite=False)[0] for i in range(0, A.shape[0], block)]
        A = np.vstack(parts)
    R = linalg.qr(A, mode="r", check_finite=False)[0]
    if R.shape[0] < m:
        R = np.vstack([R, np.zeros((m - R.shape[0], m))])
    return R[:m]


def ridge_path(R: np.ndarray, lams) -> np.ndarray:
    """Ridge coefficients (k x len(lams)) of ``min ||y - Z w||^2 + lam ||w||^2`` from ``R =
    r_factor(Z, y)``."""
    k = R.shape[1] - 1
    U, s, Vt = linalg.svd(R[:k, :k], check_finite=False)
    c = U.T @ R[:k, k]
    lams = np.atleast_1d(np.asarray(lams, dtype=float))
    f = s[:, None] / (s[:, None] ** 2 + lams[None, :])  # filter factors / s
    return Vt.T @ (f * c[:, None])


def contiguous_folds(n: int, n_splits: int):
    """Contiguous K-fold splits (sklearn ``KFold`` without shuffling) as lists of validation index
    arrays.

    Samples of a manoeuvre are strongly autocorrelated: a held-out sample is nearly a copy of its
    neighbours, so shuffled folds (or leave-one-out) reward fitting the noise. Contiguous blocks
    hold out whole stretches.
    """
    n_splits = int(min(n_splits, n))
    if n_splits < 2:
        raise ValueError(f"cross-validation needs at least 2 folds and 2 samples (n = {n}, folds = {n_splits})")
    from sklearn.model_selection import KFold  # imported on use: see base.Estimator

    return [val for _, val in KFold(n_splits=n_splits, shuffle=False).split(np.empty((n, 1)))]


def log_grid(spec, name: str) -> np.ndarray:
    """``[lo, hi, num]`` -> ``logspace(log10 lo, log10 hi, num)``; a single number -> that value
    alone."""
    if np.isscalar(spec):
        v = float(spec)
        if not v > 0:
            raise ValueError(f"{name} must be > 0, got {spec}")
        return np.array([v])
    spec = list(spec)
    if len(spec) != 3 or not (float(spec[0]) > 0 and float(spec[1]) >= float(spec[0]) and int(spec[2]) >= 1):
        raise ValueError(f"{name} must be a number or [lo, hi, num] with 0 < lo <= hi, num >= 1; got {spec}")
    return np.logspace(np.log10(float(spec[0])), np.log10(float(spec[1])), int(spec[2]))


# ---------------------------------------------------------------------------------------------- estimators
class LeastSquares(Estimator):
    """Ordinary least squares without intercept (the regressors carry every term of the model).

    Solved by LAPACK's gelsd (SVD), which stays defined when the regressors are nearly collinear.

    Parameters
    ----------
    rcond : float or None
        Relative cut-off for small singular values (None: machine precision times the larger
        dimension).
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


class Ridge(Estimator):
    """Ridge regression (Hoerl & Kennard 1970) without intercept, lambda by contiguous K-fold
    cross-validation.

    Columns are standardised inside ``fit`` (divided by their root mean square, not centred: there
    is no intercept), the ridge problem ``min (1/n)||y - Z b||^2 + alpha ||b||^2`` is solved on them
    and the coefficients are mapped back (``theta = b / s``). ``alpha`` is therefore relative: it is
    compared with the eigenvalues of ``Z^T Z / n`` (trace k), whatever the units of X and y.

    Cross-validation: contiguous folds (``KFold`` without shuffling). Samples of a manoeuvre are
    strongly autocorrelated, so leave-one-out / GCV (sklearn ``RidgeCV``'s efficient mode) sees each
    held-out sample's neighbours in the training set and picks too little regularisation; contiguous
    blocks hold out whole stretches of manoeuvre. The lowest mean validation error wins.

    Why not ``sklearn.linear_model.RidgeCV(cv=KFold(5))``: with a ``cv`` it refits every alpha on
    every fold through ``GridSearchCV`` (1.6 s on 16,800 x 11 for 61 alphas, measured). Here the
    whole path of every fold comes from the R factors of the folds (one tall-skinny QR pass over the
    data, then k x k SVDs), a few milliseconds, and validation errors are norms of small matrices
    (no cancellation on noise-free data).

    Parameters
    ----------
    alphas : [lo, hi, num] or float
        Relative ridge parameters, ``logspace(lo, hi, num)``; a single number fixes alpha (no CV).
    n_splits : int
        Number of contiguous folds.
    """

    def __init__(self, alphas=(1.0e-12, 1.0e2, 57), n_splits: int = 5):
        self.alphas = alphas
        self.n_splits = n_splits

    def fit(self, X, y):
        X, y, _ = check_regression(X, y)
        n, k = X.shape
        self._init_outputs(k)
        alphas = log_grid(self.alphas, "alphas")
        s = column_scale(X)
        Z = X / s
        if alphas.size == 1:
            alpha, cv_mse = float(alphas[0]), np.full(1, np.nan)
        else:
            folds = contiguous_folds(n, self.n_splits)
            Rf = [r_factor(Z[idx], y[idx]) for idx in folds]
            cv_sse = np.zeros(alphas.size)
            for f, idx in enumerate(folds):
                n_train = n - idx.size
                R_train = r_factor(np.vstack([Rf[g] for g in range(len(folds)) if g != f])[:, :k],
                                   np.concatenate([Rf[g][:, k] for g in range(len(folds)) if g != f]))
                B = ridge_path(R_train, alphas * n_train)
                resid = Rf[f] @ np.vstack([-B, np.ones((1, alphas.size))])
                cv_sse += np.sum(resid ** 2, axis=0)
            cv_mse = cv_sse / n
            i = int(np.argmin(cv_mse))
            alpha = float(alphas[i])
        b = ridge_path(r_factor(Z, y), alpha * n)[:, 0]
        self.coef_ = b / s
        self.alpha_ = alpha
        self.diagnostics_ = {"alpha": alpha, "lambda": alpha * n}
        if alphas.size > 1:
            self.artefacts_ = {"cv": pd.DataFrame({"alpha": alphas, "cv_mse": cv_mse})}
        return self


class Lasso(Estimator):
    """Lasso (Tibshirani 1996) by scikit-learn's ``LassoCV``, as Song et al. (2025, eqs. 11-12).

    10-fold cross-validation (contiguous folds: ``KFold`` without shuffling, sklearn's default for
    ``cv=10``) over ``alphas`` log-spaced in 1e-6..1e6 like the seed, no intercept. Columns *and* y
    are standardised inside ``fit`` (divided by their root mean square, not centred), so alpha is
    relative: sklearn's objective ``(1/2n)||y - Z b||^2 + alpha ||b||_1`` on unit-mean-square data,
    where every coefficient is zero above ``max|Z^T y|/n <= 1`` (the upper half of the seed's range
    selects nothing). Coefficients are mapped back to the units of X and y. The seed's own lambda
    multiplies a *sum* of squares: lambda_seed = 2 n alpha.

    ``selected_`` marks the nonzero terms; ``refit=True`` re-estimates the selected terms by least
    squares (the relaxed lasso of Meinshausen 2007 at relaxation 0), which removes the shrinkage of
    the kept ones.

    Coordinate descent on strongly collinear columns is slow at the small-alpha end of the path: the
    default ``max_iter`` / ``tol`` let every alpha converge (no ConvergenceWarning on the benchmark
    data); if one still does not, the warning is caught and reported as ``diagnostics_['converged']
    = 0``.

    Parameters
    ----------
    alphas : [lo, hi, num]
        Relative regularisation grid (log-spaced).
    cv : int
        Number of contiguous folds.
    refit : bool
        Least squares on the selected terms (relaxed lasso).
    max_iter, tol : coordinate-descent limits (sklearn's meaning; tol relative to ||y||^2 / n).
    """

    def __init__(self, alphas=(1.0e-6, 1.0e6, 121), cv: int = 10, refit: bool = False,
                 max_iter: int = 100_000, tol: float = 1.0e-7):
        self.alphas = alphas
        self.cv = cv
        self.refit = refit
        self.max_iter = max_iter
        self.tol = tol

    def fit(self, X, y):
        X, y, _ = check_regression(X, y)
        n, k = X.shape
        self._init_outputs(k)
        alphas = log_grid(self.alphas, "alphas")
        s, sy = column_scale(X), rms(y)
        Z, ys = X / s, y / sy
        from sklearn.exceptions import ConvergenceWarning  # imported on use: see base.Estimator
        from sklearn.linear_model import LassoCV
        from sklearn.model_selection import KFold

        n_splits = int(min(self.cv, n))
        model = LassoCV(alphas=alphas[::-1], cv=KFold(n_splits=n_splits, shuffle=False), fit_intercept=False,
                        max_iter=self.max_iter, tol=self.tol, precompute=True)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            model.fit(Z, ys)
        converged = True
        for w in caught:  # keep the convergence verdict as a diagnostic, pass any other warning on
            if issubclass(w.category, ConvergenceWarning):
                converged = False
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        self.n_iter_ = int(np.max(model.n_iter_))  # coordinate-descent iterations of the final fit
        b = np.asarray(model.coef_, dtype=float)
        selected = b != 0.0
        if self.refit and selected.any():
            b = np.zeros(k)
            b[selected] = linalg.lstsq(Z[:, selected], ys, lapack_driver="gelsd")[0]
        self.coef_ = b * sy / s
        self.selected_ = selected
        self.alpha_ = float(model.alpha_)
        self.diagnostics_ = {"lambda": float(model.alpha_), "n_selected": int(selected.sum()),
                             "converged": int(converged)}
        self.artefacts_ = {"cv": pd.DataFrame({"alpha": model.alphas_, "cv_mse": model.mse_path_.mean(axis=1)})}
        return self
