"""Sparse regression among the given regressors: SINDy's sequentially thresholded least squares
(pysindy)."""
from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from .base import Estimator
from .linear import check_regression, column_scale, contiguous_folds, rms


class SINDy(Estimator):
    """Sparse identification (SINDy; Brunton, Proctor & Kutz 2016, PNAS) by pysindy's optimizers on
    the regressors.

    The library is the columns of X (the lead adds candidate terms there); the optimizer selects
    among them. ``STLSQ`` (sequentially thresholded least squares, Brunton et al. 2016) by default,
    ``SR3`` (sparse relaxed regularised regression, Zheng et al. 2019; L0 penalty ``threshold^2 /
    2``) as an option. pysindy's final unbiasing step re-estimates the kept terms by least squares
    (``unbias=True``).

    Scaling: columns *and* y are divided by their root mean square inside ``fit`` (not centred; no
    intercept) and the coefficients mapped back. The threshold is therefore relative: term j is
    dropped when ``|theta_j| * rms(x_j) < threshold * rms(y)``, i.e. when its standardised
    contribution is below that fraction of y. The STLSQ ridge ``alpha`` is relative too (multiplied
    by n: compared with the eigenvalues of ``Z^T Z / n``).

    Threshold rule (``threshold='cv'``): each value of ``thresholds`` is scored by contiguous K-fold
    cross-validation (``KFold`` without shuffling, against the autocorrelation of manoeuvre
    samples). ``select='min'`` (default): the smallest mean validation error; ties (equal errors,
    i.e. thresholds that keep the same terms) go to the larger threshold. ``select='1se'``: the
    largest threshold whose mean validation error is within one standard error of the best (Breiman
    et al. 1984; Hastie, Tibshirani & Friedman 2009 sec. 7.10), the sparsest model the folds cannot
    tell from the best. With contiguous folds the fold-to-fold spread is large (different
    manoeuvres), so '1se' is aggressive: on noise-free ship regressions it drops true terms
    contributing 0.2-0.7 % of y (USV N'vrr, N'vvr, measured), which 'min' keeps. Even a 1 %
    tolerance on 'min' drops the linear r of a noisy nonlinear Nomoto model (r and r^3 collinear,
    0.35 % worse without r), leaving T undefined. A number fixes the threshold.

    Parameters
    ----------
    threshold : 'cv' or float
        Relative threshold, or cross-validated over ``thresholds``.
    thresholds : list of float
        Candidates for 'cv'.
    n_splits : int
        Contiguous folds for 'cv'.
    select : 'min' | '1se'
        How 'cv' picks among the thresholds.
    optimizer : 'stlsq' | 'sr3'
    alpha : float
        Relative ridge of STLSQ's inner regressions (tiny by default: plain thresholded least
        squares, with just enough ridge to keep the solve defined on collinear columns).
    max_iter : int
        Optimizer iterations.
    """

    def __init__(self, threshold="cv", thresholds=(0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2),
                 n_splits: int = 5, select: str = "min", optimizer: str = "stlsq", alpha: float = 1.0e-8,
                 max_iter: int = 20):
        self.threshold = threshold
        self.thresholds = thresholds
        self.n_splits = n_splits
        self.select = select
        self.optimizer = optimizer
        self.alpha = alpha
        self.max_iter = max_iter

    def _optimizer(self, threshold, n, k):
        import pysindy as ps

        if self.optimizer == "stlsq":
            # initial_guess: STLSQ's first iteration regresses on every column anyway, so the initial guess
            # only enters its history; giving one skips pysindy's initial lstsq (an SVD, half the fit time)
            return ps.STLSQ(threshold=float(threshold), alpha=float(self.alpha) * n, max_iter=int(self.max_iter),
                            normalize_columns=False, unbias=True, initial_guess=np.zeros((1, k)))
        if self.optimizer == "sr3":
            return ps.SR3(reg_weight_lam=float(threshold) ** 2 / 2, regularizer="L0", max_iter=int(self.max_iter),
                          normalize_columns=False, unbias=True)
        raise ValueError(f"optimizer must be 'stlsq' or 'sr3', got {self.optimizer!r}")

    def _fit_one(self, Z, y, threshold):
        opt = self._optimizer(threshold, *Z.shape)
        with warnings.catch_warnings():
            # "eliminated all coefficients" is an outcome here (a too-large candidate threshold), not an error
            warnings.filterwarnings("ignore", message="Sparsity parameter is too big")
            opt.fit(Z, y)
        self.n_iter_ = max(1, len(getattr(opt, "history_", []) or []))  # iterations of the last fit made
        coef = np.asarray(opt.coef_, dtype=float)
        if coef.shape != (1, Z.shape[1]):  # pysindy returns (n_targets, n_features)
            raise RuntimeError(f"unexpected pysindy coef_ shape {coef.shape}")
        return coef[0]

    def fit(self, X, y):
        X, y, _ = check_regression(X, y)
        n, k = X.shape
        self._init_outputs(k)
        s, sy = column_scale(X), rms(y)
        Z, ys = X / s, y / sy
        table = None
        if isinstance(self.threshold, str):
            if self.threshold != "cv":
                raise ValueError(f"threshold must be 'cv' or a number, got {self.threshold!r}")
            if self.select not in ("min", "1se"):
                raise ValueError(f"select must be 'min' or '1se', got {self.select!r}")
            cands = np.sort(np.asarray(self.thresholds, dtype=float))
            if cands.size == 0 or np.any(cands < 0):
                raise ValueError(f"thresholds must be non-negative numbers, got {self.thresholds}")
            folds = contiguous_folds(n, self.n_splits)
            err = np.zeros((cands.size, len(folds)))
            for f, val in enumerate(folds):
                train = np.ones(n, dtype=bool)
                train[val] = False
                for i, th in enumerate(cands):
                    b = self._fit_one(Z[train], ys[train], th)
                    err[i, f] = np.mean((ys[val] - Z[val] @ b) ** 2)
            mean = err.mean(axis=1)
            se = err.std(axis=1, ddof=1) / np.sqrt(len(folds))
            best = int(np.argmin(mean))
            bound = mean[best] + se[best] if self.select == "1se" else mean[best] * (1 + 1e-9)
            ok = np.nonzero(mean <= bound)[0]
            threshold = float(cands[ok.max()])
            table = pd.DataFrame({"threshold": cands, "cv_mse": mean, "cv_se": se})
        else:
            threshold = float(self.threshold)
            if not threshold >= 0:
                raise ValueError(f"threshold must be >= 0, got {self.threshold}")
        b = self._fit_one(Z, ys, threshold)
        self.coef_ = b * sy / s
        self.selected_ = b != 0.0
        self.threshold_ = threshold
        self.diagnostics_ = {"threshold": threshold, "n_selected": int(self.selected_.sum())}
        if table is not None:
            self.artefacts_ = {"cv": table}
        return self
