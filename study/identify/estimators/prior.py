"""Identification anchored to prior knowledge: the maximum a posteriori estimate under independent normal priors
on the coefficients (a generalised ridge toward the prior mean, each coefficient with its own width).

The prior (mean and standard deviation per column) comes from ``study.identify.priors`` (``prior.source`` in the
estimator config: the vessel config's published set, empirical regressions on the main particulars, or a
set offset from the truth); ``identify`` passes it to ``fit(X, y, prior=...)``.

The records enter as their least-squares estimate with its HAC (Newey-West) covariance: rows of a manoeuvre
sampled many times a second are far from independent, and counting every row as one would let any misfit,
model error included, overrule the prior (see :func:`gaussian_posterior`). Assumption labelled: the prior's
coefficients independent of each other.

What it reports per coefficient (``coef_std_``, ``coef_interval_``, ``identifiability_``): the posterior
standard deviation, the normal 90 % interval, and the ratio of posterior to prior standard deviation: near 0
when the records determine the coefficient, near 1 when they leave it where the prior put it.
"""
from __future__ import annotations

import numpy as np
from scipy import linalg, stats

from .base import Estimator
from .linear import check_regression

RHO_MAX = 0.999


def effective_rows(resid: np.ndarray) -> tuple[float, float]:
    """(effective number of independent rows, lag-one autocorrelation) of a residual series, AR(1) assumed."""
    a = np.asarray(resid, float) - float(np.mean(resid))
    den = float(np.dot(a, a))
    rho = float(np.dot(a[1:], a[:-1])) / den if den > 0 and len(a) > 2 else 0.0
    rho = float(np.clip(rho, 0.0, RHO_MAX))
    return max(1.0, len(a) * (1.0 - rho) / (1.0 + rho)), rho


def hac_lags(resid: np.ndarray, max_fraction: float = 0.05) -> int:
    """Bartlett-kernel lags of the HAC covariance: three times the first lag at which the residuals'
    autocorrelation falls below 0.1 in size (at least 3, at most ``max_fraction`` of the rows). Central
    differences of white noise are correlated at lag 2 only; a model error is correlated over many samples."""
    a = np.asarray(resid, float) - float(np.mean(resid))
    n = len(a)
    top = max(3, int(max_fraction * n))
    f = np.fft.rfft(a, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[:top + 1]
    acf = acf / acf[0] if acf[0] > 0 else acf
    below = np.nonzero(np.abs(acf[1:]) < 0.1)[0]
    first = int(below[0]) + 1 if len(below) else top
    return int(min(top, max(3, 3 * first)))


def gaussian_posterior(X: np.ndarray, y: np.ndarray, mean0: np.ndarray, sd0: np.ndarray):
    """(posterior mean, posterior covariance, diagnostics) of y = X theta + e under theta ~ N(mean0, sd0^2).

    The records' information is the least-squares estimate with its heteroskedasticity-and-autocorrelation-
    consistent covariance (Newey & West 1987, Bartlett kernel; statsmodels), combined with the normal prior as
    a Gaussian likelihood of theta: the "sandwich" posterior of Mueller (2013, Econometrica 81, 1805-1849),
    which stays honest when the rows are autocorrelated (positively: smoothed states and model error count
    for fewer rows; negatively: central differences of white noise cancel) or the model is misspecified.
    """
    import statsmodels.api as sm

    n, k = X.shape
    s = np.sqrt(np.mean(X * X, axis=0))
    s[~(s > 0)] = 1.0
    Z = X / s  # columns scaled: the coefficients' units differ by orders of magnitude
    ls, *_ = linalg.lstsq(Z, y, lapack_driver="gelsd")
    resid = y - Z @ ls
    lags = hac_lags(resid)
    ols = sm.OLS(y, Z).fit(cov_type="HAC", cov_kwds={"maxlags": lags})
    H = np.linalg.pinv(np.asarray(ols.cov_params()), hermitian=True)  # the data's precision of the scaled theta
    P0 = 1.0 / (sd0 * s) ** 2  # 0 where the prior is flat (sd0 = inf)
    A = H + np.diag(P0) + 1e-12 * np.trace(H) / k * np.eye(k)  # the jitter keeps a flat, rank-deficient case solvable
    c, low = linalg.cho_factor(A)
    w = linalg.cho_solve((c, low), H @ ls + P0 * (mean0 * s))
    cov_w = linalg.cho_solve((c, low), np.eye(k))
    m_eff, rho = effective_rows(resid)
    sigma = float(np.sqrt(resid @ resid / max(n - k, 1)))
    return w / s, cov_w / np.outer(s, s), {"rho": rho, "hac_lags": lags, "sigma": sigma, "rows_effective": m_eff}


class MapEstimator(Estimator):
    """Maximum a posteriori estimate under the run's prior (see the module docstring).

    Parameters
    ----------
    prior : dict
        ``{source: vessel|empirical|offset, sd: relative standard deviation, offset: for source offset}``;
        read by ``study.identify.fit.identify``, which hands the resolved prior to :meth:`fit`.
    interval : float
        level of the reported interval (normal, from the posterior covariance).
    """

    def __init__(self, prior: dict | None = None, interval: float = 0.9):  # noqa: D107 (prior: see class doc)
        self.prior = prior
        self.interval = interval

    def skip(self, model, structure):
        """Also skipped: an empirical prior for a model the regressions do not cover (MMG hulls only)."""
        skip, why = super().skip(model, structure)
        if skip:
            return skip, why
        src = (self.prior or {}).get("source")
        if src == "empirical" and not (getattr(model, "type", None) == "kind"
                                        and model.vessel.kind_name == "mmg"):
            return True, (f"prior.source=empirical: no empirical regressions for model '{model.name}' on a "
                          f"'{model.vessel.kind_name}' vessel (MMG hulls only); use prior.source=vessel or offset")
        return False, ""

    def fit(self, X, y, prior=None):
        Xa, ya, names = check_regression(X, y)
        k = Xa.shape[1]
        self._init_outputs(k)
        if prior is None:  # a flat prior: least squares with its HAC interval (identifiability undefined)
            mean0, sd0 = np.zeros(k), np.full(k, np.inf)
        else:
            mean0 = np.array([prior[n][0] for n in names], float)
            sd0 = np.array([prior[n][1] for n in names], float)
        mean, cov, diag = gaussian_posterior(Xa, ya, mean0, sd0)
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        z = stats.norm.ppf(0.5 + 0.5 * float(self.interval))
        self.coef_ = mean
        self.coef_std_ = sd
        self.coef_interval_ = np.column_stack([mean - z * sd, mean + z * sd])
        self.interval_level_ = float(self.interval)
        if prior is not None:
            self.prior_mean_, self.prior_sd_ = mean0, sd0
            self.identifiability_ = sd / sd0
        self.diagnostics_ = dict(diag)
        return self
