"""Identification anchored to prior knowledge: the maximum a posteriori estimate under independent
normal priors on the coefficients (a generalised ridge toward the prior mean, each coefficient with
its own width).

The prior (mean and standard deviation per column) comes from ``study.identify.priors``
(``prior.source`` in the estimator config: the vessel config's published set, empirical regressions
on the main particulars, or a set offset from the truth); ``identify`` passes it to ``fit(X, y,
prior=...)``.

The records enter as their least-squares estimate with its batch-means (block cluster-robust)
covariance: rows of a manoeuvre sampled many times a second are far from independent, and counting
every row as one would let any misfit, model error included, overrule the prior, while a short-lag
HAC kernel misses the cancellation of differentiated noise and undervalues the records several times
over (see :func:`data_covariance`). Assumption labelled: the prior's coefficients independent of
each other.

What it reports per coefficient (``coef_std_``, ``coef_interval_``, ``identifiability_``): the
posterior standard deviation, the normal 90 % interval, and the ratio of posterior to prior standard
deviation: near 0 when the records determine the coefficient, near 1 when they leave it where the
prior put it. A prior the records contradict beyond its stated width is widened by the evidence
(``prior_widening``, :func:`prior_widening`).
"""
from __future__ import annotations

import numpy as np
from scipy import linalg, stats

from .base import Estimator
from .linear import check_regression

RHO_MAX = 0.999


def effective_rows(resid: np.ndarray) -> tuple[float, float]:
    """(effective number of independent rows, lag-one autocorrelation) of a residual series,
    AR(1) assumed."""
    a = np.asarray(resid, float) - float(np.mean(resid))
    den = float(np.dot(a, a))
    rho = float(np.dot(a[1:], a[:-1])) / den if den > 0 and len(a) > 2 else 0.0
    rho = float(np.clip(rho, 0.0, RHO_MAX))
    return max(1.0, len(a) * (1.0 - rho) / (1.0 + rho)), rho


#: the records' rows are cut into this many consecutive blocks (at least 3 per coefficient) for the covariance
DATA_BLOCKS = 30


def data_blocks(n: int, k: int) -> int:
    """Number of consecutive blocks for :func:`data_covariance`: 30, at least three per
    coefficient, at most one per five rows."""
    return int(max(2, min(max(DATA_BLOCKS, 3 * k), n // 5)))


def data_covariance(Z: np.ndarray, y: np.ndarray):
    """(least-squares estimate, its covariance, number of blocks) of ``y = Z theta + e``, rows in
    time order.

    The covariance is the cluster-robust sandwich with the rows cut into consecutive blocks ("batch
    means"; statsmodels' ``cov_type='cluster'``): the score summed over a block keeps every
    correlation inside it, of either sign and of any length up to the block's. Why not a Newey-West
    (Bartlett) kernel: central differences of white noise are correlated at lag 2 with coefficient
    -0.5 and cancel almost exactly when summed, which a down-weighted kernel cannot see; with it the
    standard errors of simulated KCS and KVLCC2 MMG hulls (8 seeds, 1 % noise) were 7-9 times the
    actual spread of the estimates over seeds. With 30 blocks they are 1.1-1.3 times (KVLCC2 1.08,
    KCS 1.31; 15 blocks 1.24, 100 blocks 1.56, 300 blocks 2.36 on KCS: each block boundary adds a
    term that a whole record does not have, so more blocks overstate the variance). Blocks as long
    as a few tens of seconds also keep the slow correlation of a model error, which then counts for
    few rows.
    """
    import statsmodels.api as sm

    n, k = Z.shape
    G = data_blocks(n, k)
    groups = np.minimum(np.arange(n) * G // n, G - 1)
    ols = sm.OLS(y, Z).fit(cov_type="cluster", cov_kwds={"groups": groups})
    return np.asarray(ols.params, float), np.asarray(ols.cov_params(), float), G


#: eigenvalues of the records' covariance below this share of its largest count as zero (a direction the records do
#: not determine), not as a precision: a block-robust covariance has rank at most blocks - 1, and the rounding left in
#: its null space (seen at -1.2e-15 of the largest on one BLAS kernel) would otherwise be inverted into a huge precision
#: of either sign. Assumption: no direction the records determine is 1e12 times less variable than the best one.
PRECISION_RTOL = 1e-12

#: the widest the records may make a prior (empirical Bayes, :func:`prior_widening`), in multiples of its stated sd
PRIOR_SCALE_MAX = 1e6  # effectively unbounded: records may discard a prior they flatly contradict


def prior_widening(d: np.ndarray, V: np.ndarray, sd0: np.ndarray, top: float = PRIOR_SCALE_MAX) -> float:
    """The factor ``tau >= 1`` on the prior's standard deviations that makes the records'
    least-squares estimate most likely (type-II maximum likelihood, "empirical Bayes"): ``d = ls -
    mean0 ~ N(0, V + tau^2 diag(sd0^2))``.

    Why: a prior is somebody's claim (a published set from another basin, a regression over other
    hulls, a derived linearisation). Where the records contradict it beyond its stated width,
    keeping it at that width drags the well-determined coefficients towards a wrong value; the
    evidence widens it instead. Never narrower than stated (``tau >= 1``): the records cannot make
    prior knowledge more certain than its source says. Coefficients with a flat prior (``sd0 =
    inf``) take no part.
    """
    from scipy.optimize import minimize_scalar

    keep = np.isfinite(sd0)
    if not keep.any():
        return 1.0
    d, V, s2 = d[keep], V[np.ix_(keep, keep)], sd0[keep] ** 2

    def nll(log_tau):
        C = V + np.exp(2.0 * log_tau) * np.diag(s2)
        try:
            c = linalg.cho_factor(C)
        except linalg.LinAlgError:
            return np.inf
        return float(np.sum(np.log(np.diag(c[0]))) + 0.5 * d @ linalg.cho_solve(c, d))

    r = minimize_scalar(nll, bounds=(0.0, float(np.log(top))), method="bounded", options={"xatol": 1e-3})
    return float(np.exp(r.x)) if np.isfinite(r.fun) and nll(r.x) < nll(0.0) else 1.0


def gaussian_posterior(X: np.ndarray, y: np.ndarray, mean0: np.ndarray, sd0: np.ndarray, widen: bool = True,
                       eiv=None):
    """(posterior mean, posterior covariance, diagnostics) of y = X theta + e under theta ~ N(mean0,
    sd0^2).

    The records' information is the least-squares estimate with its block cluster-robust covariance
    (:func:`data_covariance`), combined with the normal prior as a Gaussian likelihood of theta: the
    "sandwich" posterior of Mueller (2013, Econometrica 81, 1805-1849), which stays honest when the
    rows are autocorrelated (positively: smoothed states and model error count for fewer rows;
    negatively: central differences of white noise cancel) or the model is misspecified. With
    ``widen`` the prior's standard deviations are first scaled by :func:`prior_widening` (1 when the
    records agree with the prior; reported as ``prior_widening``). ``eiv``: the errors-in-variables
    terms of the rows (``study.identify.row_errors.Correction``): the records' estimate is then the
    corrected least-squares one (:func:`corrected_least_squares`).
    """
    n, k = X.shape
    s = np.sqrt(np.mean(X * X, axis=0))
    s[~(s > 0)] = 1.0
    Z = X / s  # columns scaled: the coefficients' units differ by orders of magnitude
    ls, cov_ls, blocks = data_covariance(Z, y)
    eiv_diag = {}
    if eiv is not None:
        fit, eiv_diag = corrected_least_squares(Z, y, ls, eiv, s)
        if fit is not None:
            ls, cov_ls = fit
    resid = y - Z @ ls
    H = np.linalg.pinv(cov_ls, rcond=PRECISION_RTOL, hermitian=True)  # the data's precision of the scaled theta
    tau = prior_widening(ls - mean0 * s, cov_ls, sd0 * s) if widen else 1.0
    P0 = 1.0 / (tau * sd0 * s) ** 2  # 0 where the prior is flat (sd0 = inf)
    A = H + np.diag(P0) + 1e-12 * np.trace(H) / k * np.eye(k)  # the jitter keeps a flat, rank-deficient case solvable
    c, low = linalg.cho_factor(A)
    w = linalg.cho_solve((c, low), H @ ls + P0 * (mean0 * s))
    cov_w = linalg.cho_solve((c, low), np.eye(k))
    m_eff, rho = effective_rows(resid)
    sigma = float(np.sqrt(resid @ resid / max(n - k, 1)))
    return w / s, cov_w / np.outer(s, s), {"rho": rho, "data_blocks": blocks, "sigma": sigma,
                                            "rows_effective": m_eff, "prior_widening": tau, **eiv_diag}


def corrected_least_squares(Z: np.ndarray, y: np.ndarray, ls: np.ndarray, eiv, s: np.ndarray):
    """(estimate, covariance, diagnostics) of the corrected least squares of rows ``Z`` (columns
    scaled by ``s``) whose regressors are noisy: ``(Z'Z - M) theta = Z'y - g``
    (``study.identify.row_errors``: Fuller 1987 Sec. 2.2). Its covariance is the block
    cluster-robust sandwich of the corrected score, each block's ``Z_b' (y_b - Z_b theta) - (n_b
    / n) (g - M theta)`` at the corrected estimate (the blocks of :func:`data_covariance`, with
    statsmodels' small-sample factor), plus the probes' Monte Carlo error. Why not the
    least-squares sandwich: its residuals at the biased estimate carry the bias as a slow misfit,
    which the blocks count as correlated noise (measured on synthetic rows of reliability 0.86:
    2.6 times the actual spread). ``eiv_reliability_min``: the smallest eigenvalue of ``H^-1/2 (H
    - M) H^-1/2`` (1: the regressors' noise negligible; near 0 or below: the noise is the signal,
    and the first-order correction is no longer valid; below ``row_errors.RELIABILITY_MIN`` it is
    not made: None)."""
    from ..row_errors import RELIABILITY_MIN

    M, g = eiv.M / np.outer(s, s), eiv.g / s
    n, k = Z.shape
    H = Z.T @ Z
    A = H - M
    rel = float(linalg.eigvalsh(A, H)[0])  # the generalised eigenvalues of (A, H): those of H^-1/2 A H^-1/2
    diag = {"eiv_reliability_min": rel, "eiv_corrected": 0.0}
    if not rel >= RELIABILITY_MIN:  # the noise is no small perturbation: no correction (the run is flagged)
        return None, diag
    Ai = linalg.inv(A)
    theta = Ai @ (Z.T @ y - g)
    G = data_blocks(n, k)
    groups = np.minimum(np.arange(n) * G // n, G - 1)
    resid = y - Z @ theta
    psi = np.zeros((G, k))
    np.add.at(psi, groups, Z * resid[:, None])
    psi -= np.bincount(groups, minlength=G)[:, None] / n * (g - M @ theta)
    meat = psi.T @ psi * (G / (G - 1.0)) * ((n - 1.0) / max(n - k, 1))
    cov = Ai @ meat @ Ai
    mc = eiv.mc_covariance(theta / s) / np.outer(s, s)  # theta unscaled (Z = X / s), then in the scaled coordinates
    cov = cov + Ai @ mc @ Ai
    diag["eiv_corrected"] = 1.0
    diag["eiv_shift_sd_max"] = float(np.max(np.abs(theta - ls) / np.sqrt(np.diag(cov))))
    return (theta, 0.5 * (cov + cov.T)), diag


def gls_posterior(X: np.ndarray, y: np.ndarray, operators, mean0: np.ndarray, sd0: np.ndarray,
                  q_raw: np.ndarray | None = None, errors=None):
    """(posterior mean, covariance, diagnostics, noise model) of ``y = X theta + e`` under
    ``theta ~ N(mean0, sd0^2)``, with the rows' noise modelled by the structure's operators
    (``study.identify.row_noise``, ``operators`` a ``RowOperators``): the noise model fitted by
    maximum likelihood (or ``q_raw`` taken as given), the rows whitened, and the MAP estimator's
    sandwich posterior (:func:`gaussian_posterior`, prior not widened) of the whitened rows.
    ``errors``: the rows' truncation and the regressors' noise
    (``study.identify.row_errors.RowErrors``), removed: the truncation from the rows before the
    noise model is fitted, the regressors' noise by corrected least squares on the whitened rows."""
    from ..row_errors import eiv_terms
    from ..row_noise import RowNoise

    X, y = np.asarray(X, float), np.asarray(y, float)
    k = X.shape[1]
    if errors is not None:
        X, y = errors.corrected(X, y)
    if operators.centred:  # the centring's constant: a free intercept (see RowOperators)
        X = np.column_stack([X, np.ones(len(y))])
        mean0, sd0 = np.r_[mean0, 0.0], np.r_[sd0, np.inf]
    noise = RowNoise(operators.operators)
    noise = noise.fit(X, y) if q_raw is None else noise.use(q_raw)
    Xw, yw = noise.whiten(X), noise.whiten(y)
    eiv = eiv_terms(errors, noise.whiten, exact=Xw[:, k:] if X.shape[1] > k else None)
    mean, cov, diag = gaussian_posterior(Xw, yw, mean0, sd0, widen=False, eiv=eiv)
    resid = y - X @ mean
    rw = yw - Xw @ mean
    rw = rw - rw.mean()
    acf = [float(rw[j:] @ rw[:-j] / (rw @ rw)) if rw @ rw > 0 else 0.0 for j in (1, 2)]
    mean, cov = mean[:k], cov[:k, :k]
    diag = {"whitened": 1.0, "sigma": float(np.sqrt(np.mean(resid ** 2))), "data_blocks": diag["data_blocks"],
            "noise_bandwidth": float(noise.b), "noise_evaluations": float(noise.evaluations_),
            # autocorrelation left in the whitened residual at lags 1 and 2 (near 0 when the model holds)
            "whitened_acf1": acf[0], "whitened_acf2": acf[1],
            "truncation_corrected": float(errors is not None and errors.trunc_y is not None),
            **{k_: diag[k_] for k_ in ("eiv_reliability_min", "eiv_corrected", "eiv_shift_sd_max") if k_ in diag},
            **{f"noise_Q{i}{j}": float(noise.Q[i, j]) for i in range(noise.m) for j in range(i, noise.m)}}
    return mean, cov, diag, noise



class MapEstimator(Estimator):
    """Maximum a posteriori estimate under the run's prior (see the module docstring).

    Parameters
    ----------
    prior : dict
        ``{source: vessel|empirical|offset, sd: relative standard deviation, offset: for source
        offset}``; read by ``study.identify.fit.identify``, which hands the resolved prior to
        :meth:`fit`.
    interval : float
        level of the reported interval (normal, from the posterior covariance).
    widen_prior : bool
        let the records widen a prior they contradict (:func:`prior_widening`); the factor is
        reported as the diagnostic ``prior_widening`` and the identifiability is measured against
        the widened prior.
    """

    accepts_prior = True

    def __init__(self, prior: dict | None = None, interval: float = 0.9,
                 widen_prior: bool = True):  # noqa: D107 (prior: see class doc)
        self.prior = prior
        self.interval = interval
        self.widen_prior = widen_prior

    def skip(self, model, structure):
        """Also skipped: an empirical prior for a model the regressions do not cover (MMG hulls
        only)."""
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
        if prior is None:  # a flat prior: least squares with its block-robust interval (identifiability undefined)
            mean0, sd0 = np.zeros(k), np.full(k, np.inf)
        else:
            mean0 = np.array([prior[n][0] for n in names], float)
            sd0 = np.array([prior[n][1] for n in names], float)
        mean, cov, diag = gaussian_posterior(Xa, ya, mean0, sd0, widen=bool(self.widen_prior))
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        z = stats.norm.ppf(0.5 + 0.5 * float(self.interval))
        self.coef_ = mean
        self.coef_std_ = sd
        self.coef_interval_ = np.column_stack([mean - z * sd, mean + z * sd])
        self.interval_level_ = float(self.interval)
        if prior is not None:
            self.prior_mean_, self.prior_sd_ = mean0, sd0
            self.identifiability_ = sd / (diag["prior_widening"] * sd0)
        self.diagnostics_ = dict(diag)
        return self
