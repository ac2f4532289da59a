"""Can an emcee regression run's intervals be trusted? The verdict, from the run's own records only
(never from the truth), that the run reports as ``intervals_trusted`` with a one-line
``intervals_note``.

Only emcee's regression likelihood has intervals meant to cover the truth, so only it asks (its
:meth:`~study.identify.estimators.bayes.EmceeSampler.trust_verdict`); keeping the verdict here,
apart from the identification engine, means changing it changes the code fingerprint of emcee's runs
only. The checks, in order:

1. **The likelihood's own assumptions**: the independent-rows likelihood (``regression_iid``) is
   never calibrated; rows differenced and then cut (``diff_center``'s split, z-score cleaning) leave
   gaps the whitening cannot undo; the regressors' noise too large for a first-order removal
   (``study.identify.row_errors``).
2. **The records carry measurement noise**: a regression whose rows fit to within
   :data:`NOISE_FREE_GAP` of their variance (1 - R^2) in any equation has no noise the likelihood
   could model (noise-free simulated records): its residual is the simulation's and the structure's
   numerical error, and its intervals would measure that.
3. **The residual is the noise the likelihood models**: whitened by the fitted row-noise model, the
   rows' residual of a well-specified regression is white; a lag-1 or lag-2 autocorrelation beyond
   :data:`ACF_LIMIT` in any equation says the rows' errors are something else (no measurement noise
   at all, coloured noise, a term the model lacks), which the intervals do not cover.
4. **The structure's truncation** (``study.identify.truncation``): its estimated bias of each
   reported parameter, in posterior sd, against :data:`BIAS_LIMIT_SD`, or, where the likelihood
   removed it, against
   :data:`CORRECTED_LIMIT_SD`.
5. **The same coefficients everywhere in the records** (:func:`heterogeneity`): the whitened rows
   split into four groups by where they lie in the records' range (:func:`range_key`: the size of
   the fitted value of their neighbours), the coefficients fitted on each group apart. For a model
   that holds they agree within their own spread; a term the model lacks that its other terms nearly
   absorb leaves the residual white but is absorbed differently where the states are small and where
   they are large, so the groups' coefficients disagree (a Chow (1960) test across the regressors'
   range rather than across time): their chi-square's upper tail against :data:`HETEROGENEITY_P`.
6. **No neighbouring term the records ask for** (:func:`omitted_terms`): the model's own states'
   monomials up to :data:`NEIGHBOUR_DEGREE` that it lacks (``Model.candidates``, built by the same
   structure on the same rows), added to the whitened rows together; a robust Wald test of their
   coefficients (the score test for omitted variables, e.g. Wooldridge 2010, *Econometric Analysis
   of Cross Section and Panel Data*, 2nd ed., sec. 12.6), its upper tail against
   :data:`OMITTED_TERMS_P`. A missing term the others absorb alike over the whole range escapes
   check 5 but not this one when it is, or resembles, a monomial of the states.

The truncation limits' reasons are in :mod:`study.identify.truncation`'s docstring.

What the verdict still cannot see: a missing term unlike any monomial of the states and absorbed the
same way over the whole range of the records (the groups agree while every coefficient is biased),
and errors the records share (a sensor's bias, the facility). "Trusted" means trusted for the model
as given: the intervals cover the identification spread, and the check above catches a missing term
only where the records show it.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

__all__ = ["ACF_LIMIT", "BIAS_LIMIT_SD", "CORRECTED_LIMIT_SD", "HETEROGENEITY_GROUPS", "HETEROGENEITY_P",
           "NEIGHBOUR_DEGREE", "NOISE_FREE_GAP", "OMITTED_TERMS_P", "RANGE_KEY_ROWS", "heterogeneity", "omitted_terms", "range_key",
           "run_verdict", "verdict", "whiteness"]

#: the largest autocorrelation (lags 1 and 2) of the whitened residual a trusted run may show. Assumption
#: (labelled): an effect size, not a test (thousands of rows make any departure significant). Where the regressors
#: are smooth a residual autocorrelation rho inflates a coefficient's variance by about 1 + 2 rho, so 0.1 leaves a
#: 90 % interval covering about 87 %. Measured (KVLCC2's MMG hull, central rows, 0.005 L/U0): 0.003-0.02 with 1 %
#: white noise, -0.34 on noise-free records
ACF_LIMIT = 0.1

#: 1 - R^2 of an equation's rows below this: records without measurement noise. Assumption (labelled): measured
#: records carry sensor noise far above it (a fibre-optic gyro's 0.01 deg/s on yaw rates of 1 deg/s is 1e-2 of the
#: signal, and derivatives of the samples amplify it). Measured on the calibration models' central rows (KVLCC2's
#: MMG hull, the waterjet USV): 2e-8 to 4e-5 noise-free at 0.005 L/U0, at least 1.4e-2 with 1 % noise (1.1e-3 at
#: 0.05 L/U0, where noise-free rows reach 1.9e-3 from truncation alone, which checks 3 and 4 flag)
NOISE_FREE_GAP = 1e-4

#: the groups of rows (by the size of the fitted value) whose separately fitted coefficients :func:`heterogeneity`
#: compares
HETEROGENEITY_GROUPS = 4
#: the groups' coefficients disagree beyond their spread when their chi-square (chi2((groups - 1) p) for a model
#: that holds, p coefficients) has an upper tail below this. A test, not an effect size: the statistic is already in
#: units of the groups' own posterior spread, which is what an interval's coverage depends on; 0.1 % per equation
#: keeps false flags rare over a study's thousands of equations. What it measures on the two calibration models,
#: with and without a term, is in docs/studies/index.md (``scripts/probe_missing_term.py`` prints it)
HETEROGENEITY_P = 1e-3
#: rows on each side whose |fitted value| :func:`range_key` averages into a row's place in the records' range.
#: Assumption: few enough that the states barely move over them at a study's sampling, enough to average the
#: fitted value's noise down
RANGE_KEY_ROWS = 5

#: the degree of the states' monomials (``Model.candidates``) :func:`omitted_terms` tests the model against.
#: Assumption (labelled): the hull polynomials of the MMG (Yasukawa & Yoshimura 2015) and Abkowitz (1964) models
#: stop at the third degree, so a term a model of this kind lacks is most likely among the monomials up to it
NEIGHBOUR_DEGREE = 3
#: the neighbouring terms' joint Wald statistic (chi2(q) for a model that holds, q terms) has an upper tail below
#: this: the records ask for a term the model lacks. As :data:`HETEROGENEITY_P`, a test in units of the rows' own
#: spread, 0.1 % per equation. What it measures on the calibration models, with and without a term, is in
#: docs/studies/index.md (``scripts/probe_missing_term.py`` prints it)
OMITTED_TERMS_P = 1e-3

#: a reported parameter biased by more than this many posterior sd: the intervals are not trusted
BIAS_LIMIT_SD = 1.0
#: where the likelihood removed the truncation (study.identify.row_errors): the most it may remove and still be
#: trusted. Assumption (labelled): the estimate is within 2.5 % of the actual bias, so what is left stays below half a
#: posterior sd. Measured on the KT Mariner (study.run.calibration, noise-free limit minus truth after the correction):
#: 0.01 sd left of 1.55 sd (euler, 0.1 s, 1 % noise), 0.1 of 4.8 (euler, 1 s), 0.02 of 8.5 (euler, 0.1 s, the
#: standard training set with sensor noise, noise=low)
CORRECTED_LIMIT_SD = 20.0


def verdict(bias_sd: dict, structure_name: str, dropped_differences: int = 0, corrected: bool = False,
            reliability: float | None = None, eiv_refused: bool = False) -> tuple[bool, str]:
    """(trusted, one-line note) from the reported parameters' estimated truncation biases in
    posterior sd, the rows differenced then cut, and, where the likelihood removed the rows'
    errors (``corrected``, ``study.identify.row_errors``), whether it had to leave the
    regressors' noise in (``eiv_refused``: their smallest whitened ``reliability`` below
    ``row_errors.RELIABILITY_MIN``; see the module docstring)."""
    if dropped_differences:
        return False, (f"{structure_name}: {dropped_differences} differenced rows dropped (split/cleaning) leave "
                       "gaps, so the differencing cannot be undone and the regressors' noise biases the estimate: "
                       "intervals not calibrated; use euler/central/integral without split")
    if corrected and eiv_refused:
        rel = "" if reliability is None or not np.isfinite(reliability) else f" (reliability {reliability:.2f})"
        return False, (f"{structure_name}: the regressors' noise is too large a part of their whitened spread{rel} "
                       "for a first-order correction: not removed; intervals not calibrated (cannot tell)")
    finite = {n: v for n, v in bias_sd.items() if v is not None and np.isfinite(v)}
    if not finite:
        return True, f"{structure_name}: truncation bias not estimated (no stencil); intervals as modelled"
    worst = max(finite, key=lambda n: abs(finite[n]))
    b = abs(finite[worst])
    if corrected:
        if b > CORRECTED_LIMIT_SD:
            return False, (f"{structure_name} truncation of {b:.1f} posterior sd on {worst} removed, more than "
                           f"{CORRECTED_LIMIT_SD:g} sd: its estimate's error may exceed half a sd; intervals not "
                           "calibrated; sample finer or use central/integral")
        return True, (f"{structure_name} truncation of at most {b:.2f} posterior sd ({worst}) and the regressors' "
                      "noise removed: intervals trusted")
    if b > BIAS_LIMIT_SD:
        return False, (f"{structure_name} truncation biases {worst} by {b:.1f} posterior sd: intervals not "
                       "calibrated; sample finer or use central/integral")
    return True, f"{structure_name} truncation bias at most {b:.2f} posterior sd ({worst}): intervals trusted"


def range_key(fitted: np.ndarray, shared: int, rows: int = RANGE_KEY_ROWS) -> np.ndarray:
    """Where each row lies in the records' range, for :func:`heterogeneity`: the mean |fitted value|
    of the ``rows`` rows on each side of it beyond the ``shared`` nearest (fewer at the ends of the
    rows).

    ``shared`` is how far a row's noise reaches: the row-noise model's bandwidth plus one, since
    a row's regressors may hold the samples its neighbours' responses hold. A row's own fitted
    value carries its own noise, and the integral structure's rows share that noise with their
    response (both hold the samples at the window's two ends): groups sorted by it are selected
    on their noise, and their fits disagree where the model holds. The neighbours' values lie in
    the same part of the range but carry none of the row's noise."""
    f = np.abs(np.asarray(fitted, float))
    n = len(f)
    cum = np.concatenate([[0.0], np.cumsum(f)])
    i = np.arange(n)
    lo_a, lo_b = np.clip(i - shared - rows, 0, n), np.clip(i - shared, 0, n)
    hi_a, hi_b = np.clip(i + shared + 1, 0, n), np.clip(i + shared + 1 + rows, 0, n)
    total = cum[lo_b] - cum[lo_a] + cum[hi_b] - cum[hi_a]
    count = (lo_b - lo_a) + (hi_b - hi_a)
    return np.where(count > 0, total / np.maximum(count, 1), f)


def heterogeneity(Xw: np.ndarray, yw: np.ndarray, key: np.ndarray,
                  groups: int = HETEROGENEITY_GROUPS) -> tuple[float, float]:
    """(chi-square per degree of freedom, its upper tail) of the coefficients fitted apart on
    groups of the whitened rows: the rows ``Xw``, ``yw`` (whitened by the run's row-noise model)
    split into ``groups`` of equal size by ``|key|`` (where each row lies in the records' range:
    :func:`range_key`), least squares on each, and the chi-square of the groups' estimates about
    their precision-weighted mean, sum_g (b_g - b)' P_g (b_g - b) with P_g the group's sandwich
    precision, on (groups - 1) p degrees of freedom. About 1 and its tail uniform where the model
    holds; NaNs when a group has no more rows than coefficients or no residual."""
    Xw, yw = np.asarray(Xw, float), np.asarray(yw, float)
    p = Xw.shape[1]
    nan = (float("nan"), float("nan"))
    parts = np.array_split(np.argsort(np.abs(np.asarray(key, float)), kind="stable"), groups)
    est, prec = [], []
    for idx in parts:
        A, b = Xw[idx], yw[idx]
        if len(idx) <= p:
            return nan
        beta = np.linalg.lstsq(A, b, rcond=None)[0]
        r = b - A @ beta
        if not float(r @ r) > 0:
            return nan
        # the sandwich (HC1: White 1980) precision, as the posterior's own: rows whose residual's size varies with
        # the states would make the plain least-squares precision overstate the groups' disagreement
        meat = (A * (r ** 2)[:, None]).T @ A * (len(idx) / (len(idx) - p))
        AtA = A.T @ A
        try:
            prec.append(AtA @ np.linalg.solve(meat, AtA))
        except np.linalg.LinAlgError:
            return nan
        est.append(beta)
    try:
        pooled = np.linalg.solve(sum(prec), sum(P @ b for P, b in zip(prec, est)))
    except np.linalg.LinAlgError:
        return nan
    chi2 = sum(float((b - pooled) @ P @ (b - pooled)) for P, b in zip(prec, est))
    dof = (groups - 1) * p
    return chi2 / dof, float(stats.chi2.sf(chi2, dof))


def _robust_cov(A: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The sandwich (HC1: White 1980) covariance of least squares on the rows ``A`` with residual
    ``r``."""
    n, p = A.shape
    bread = np.linalg.pinv(A.T @ A)
    meat = (A * (r ** 2)[:, None]).T @ A * (n / max(n - p, 1))
    return bread @ meat @ bread


def omitted_terms(Xw: np.ndarray, Zw: np.ndarray, yw: np.ndarray, names=None) -> tuple[float, float, str]:
    """(Wald statistic per degree of freedom, its upper tail, the term that alone explains most
    of the residual) of the neighbouring terms ``Zw`` added to the model's whitened rows ``Xw``
    (target ``yw``): least squares on ``[Xw, Zw]``, the sandwich covariance of the added
    coefficients, ``b' V^-1 b`` on q degrees of freedom (q the rank of ``Zw`` beyond ``Xw``).
    About 1 and its tail uniform where the model holds. ``names``: of ``Zw``'s columns, for the
    third element (empty without). NaNs when there is no added column or no residual."""
    Xw, Zw, yw = np.asarray(Xw, float), np.asarray(Zw, float), np.asarray(yw, float)
    nan = (float("nan"), float("nan"), "")
    if Zw.ndim != 2 or Zw.shape[1] == 0 or len(yw) <= Xw.shape[1] + Zw.shape[1]:
        return nan
    # the columns on one scale, so that the rank and the pseudo-inverse see their directions, not their units
    A = np.column_stack([Xw, Zw])
    scale = np.sqrt(np.mean(A ** 2, axis=0))
    A = A / np.where(scale > 0, scale, 1.0)
    k = Xw.shape[1]
    beta = np.linalg.lstsq(A, yw, rcond=None)[0]
    r = yw - A @ beta
    if not float(r @ r) > 0:
        return nan
    b, V = beta[k:], _robust_cov(A, r)[k:, k:]
    q = int(np.linalg.matrix_rank(A)) - int(np.linalg.matrix_rank(A[:, :k]))
    if q <= 0:
        return nan
    wald = float(b @ np.linalg.pinv(V, hermitian=True) @ b)
    # the single term that explains most of what the model leaves: each added alone, its t statistic
    r0 = yw - A[:, :k] @ np.linalg.lstsq(A[:, :k], yw, rcond=None)[0]
    best, top = -1.0, ""
    for j in range(Zw.shape[1]):
        Aj = np.column_stack([A[:, :k], A[:, k + j]])
        bj = np.linalg.lstsq(Aj, r0, rcond=None)[0]
        rj = r0 - Aj @ bj
        vj = _robust_cov(Aj, rj)[-1, -1]
        t = abs(bj[-1]) / np.sqrt(vj) if vj > 0 else 0.0
        if t > best:
            best, top = t, (str(names[j]) if names is not None else "")
    return wald / q, float(stats.chi2.sf(wald, q)), top


def _worst(metrics: dict, suffix: str, smallest: bool = False):
    """(equation, value) of the ``est_<equation><suffix>`` diagnostic largest in size
    (``smallest``: the smallest), or None when none was reported."""
    found = [(k[len("est_"):-len(suffix)], float(v)) for k, v in metrics.items()
             if k.startswith("est_") and k.endswith(suffix) and isinstance(v, (int, float)) and np.isfinite(v)]
    if not found:
        return None
    return (min if smallest else max)(found, key=lambda kv: abs(kv[1]))


def whiteness(metrics: dict) -> tuple[str, str, float] | None:
    """(equation, lag, autocorrelation) of the whitened residual's largest autocorrelation at lag
    1 or 2 over the equations (the ``est_<equation>_whitened_acf<lag>`` diagnostics), or None
    when none was reported."""
    found = [(k[len("est_"):].rsplit("_whitened_acf", 1), float(v)) for k, v in metrics.items()
             if k.startswith("est_") and "_whitened_acf" in k and isinstance(v, (int, float)) and np.isfinite(v)]
    if not found:
        return None
    (eq, lag), v = max(found, key=lambda kv: abs(kv[1]))
    return eq, lag, v


def run_verdict(likelihood: str, structure_name: str, bias_sd: dict, dropped_differences: int, corrected: bool,
                metrics: dict) -> tuple[bool, str]:
    """(trusted, note) of a run: :func:`verdict` with what the run's equations reported
    (``metrics``: the ``est_<equation>_<diagnostic>`` entries of the results table) and the
    likelihood's own limit."""
    if likelihood == "regression_iid":
        return False, ("likelihood regression_iid counts the rows as independent: intervals not calibrated "
                       "(8-150 times the actual spread measured); use likelihood regression")
    rel = [v for k, v in metrics.items() if k.startswith("est_") and k.endswith("_eiv_reliability_min")]
    refused = any(v == 0.0 for k, v in metrics.items() if k.startswith("est_") and k.endswith("_eiv_corrected"))
    trusted, note = verdict(bias_sd, structure_name, dropped_differences, corrected, min(rel) if rel else None,
                            refused)
    gaps = [(k[len("fit_r2_"):], 1.0 - float(v)) for k, v in metrics.items()
            if k.startswith("fit_r2_") and isinstance(v, (int, float)) and np.isfinite(v)]
    if trusted and gaps and min(g for _, g in gaps) < NOISE_FREE_GAP:
        eq, gap = min(gaps, key=lambda kv: kv[1])
        return False, (f"{structure_name}: the rows of equation {eq} fit to within {gap:.1e} of their variance "
                       f"(1 - R^2 below {NOISE_FREE_GAP:g}): the records carry no measurement noise the likelihood "
                       "could model, and the intervals would measure numerical error: not calibrated (cannot tell)")
    white = whiteness(metrics)
    if trusted and white is not None and abs(white[2]) > ACF_LIMIT:
        eq, lag, v = white
        return False, (f"{structure_name}: the whitened residual is not white (lag-{lag} autocorrelation {v:+.2f} in "
                       f"equation {eq}, beyond {ACF_LIMIT:g}): the rows' errors are not the measurement noise the "
                       "likelihood models (no noise, coloured noise or a term the model lacks); intervals not "
                       "calibrated")
    split = _worst(metrics, "_heterogeneity_p", smallest=True)
    if trusted and split is not None and split[1] < HETEROGENEITY_P:
        eq, tail = split
        per_dof = metrics.get(f"est_{eq}_heterogeneity", float("nan"))
        return False, (f"{structure_name}: the coefficients fitted apart where the states are small and where they "
                       f"are large disagree (chi-square {per_dof:.2f} per degree of freedom in equation {eq}, upper "
                       f"tail {tail:.1e}, below {HETEROGENEITY_P:g}): the model lacks a term its others absorb; "
                       "intervals not calibrated")
    missing = _worst(metrics, "_omitted_terms_p", smallest=True)
    if trusted and missing is not None and missing[1] < OMITTED_TERMS_P:
        eq, tail = missing
        per_dof = metrics.get(f"est_{eq}_omitted_terms", float("nan"))
        top = metrics.get(f"est_{eq}_omitted_terms_top") or "?"
        return False, (f"{structure_name}: the records ask for a term the model lacks (the states' monomials up to "
                       f"degree {NEIGHBOUR_DEGREE} it leaves out explain its residual: Wald {per_dof:.2f} per degree "
                       f"of freedom in equation {eq}, upper tail {tail:.1e}, below {OMITTED_TERMS_P:g}; alone, {top} "
                       "explains most, or a term these records cannot tell from it): intervals not calibrated")
    return trusted, note
