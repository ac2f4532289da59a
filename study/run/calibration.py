"""Are emcee's regression intervals calibrated? Over many noisy datasets of one simulated case, how
often the 90 % intervals of the reported parameters cover the truth, and how often the structure's
noise-free limit, per structure and regression likelihood
(``tests/run/test_regression_calibration.py``,
``benchmarks/bench_regression_calibration.py``).

The case is the study's own: the truth vessel simulated once through the training manoeuvres
(``study.run.pipeline.simulate_set``), then measured again and again with fresh noise
(``study.run.pipeline.measurement``, dataset ``i`` with the noise seeds of a run with ``seed=i``),
turned into rows by the structure and its post-processing (``study.identify.rows.prepare``;
diff_center's random split drawn per dataset as in a run). Only the measurement noise changes
between datasets: coverage over the sampling distribution of the noise, the trajectories fixed.

The posteriors are evaluated in closed form, where they are Gaussian:

- ``regression``: exactly what ``EmceeSampler.fit`` samples (``EmceeSampler.gaussian_regression``);
- ``regression_iid``: normal with mean and covariance of the iid likelihood at its most probable
  noise scale and the same weak prior (the noise scale's posterior is sharp for thousands of rows,
  so the Student-t marginal is normal to well within the binomial spread of a coverage count;
  labelled as an approximation).

Nomoto models report K, T, alpha: their intervals are the 5 % and 95 % quantiles of the physical
parameters of ``draws`` Gaussian draws of the regression coefficients, as ``study.identify.fit``
does with emcee's draws. The **noise-free limit** is the same likelihood on the noise-free records
with the same structure (and, for ``regression``, the noise mix fitted to the noisy dataset): the
gap between covering it and covering the truth is the structure's own bias (truncation), not
miscalibration.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

LIKELIHOODS = ("regression", "regression_iid")


@dataclass
class Case:
    """A simulated identification case: the run configuration's parts, the model, the noise-free
    records."""

    conf: dict
    model: object
    truth_vessel: object
    clean: list
    name: str = ""


def make_case(vessel: str, model: str, train: list, noise: str = "low_relative", sample_dt: float | None = None,
              sample_dt_LU: float | None = None, sim: dict | None = None, name: str = "") -> Case:
    """The case of ``vessel`` (config name) identified with ``model`` from the ``train``
    manoeuvres, measured with the ``noise`` config (optionally resampled at ``sample_dt`` s or
    ``sample_dt_LU`` L/U0). The default is 1 % of each channel's RMS (``low_relative``), the
    noise the README's calibration table was measured with; the project's default ``noise=low``
    (absolute sensor noise) came later."""
    from study.configuration.compose import read_config
    from study.identify.models import make_model
    from study.run.pipeline import simulate_set, vessels_for

    nz = dict(read_config("noise", noise))
    if sample_dt is not None:
        nz["sample_dt"] = float(sample_dt)
    if sample_dt_LU is not None:
        nz["sample_dt_LU"] = float(sample_dt_LU)
    conf = {"vessel": read_config("vessel", vessel), "depth": {}, "environment": {}, "noise": nz,
            "sim": dict(sim or {}), "maneuvers": {"train": list(train)}}
    truth, base = vessels_for(conf)
    mdl = make_model(read_config("model", model), base)
    clean = list(simulate_set(truth, conf["maneuvers"]["train"], conf, seed_base=0).values())
    return Case(conf, mdl, truth, clean, name or f"{vessel}/{model}")


def records(case: Case, seed: int, noise_free: bool = False) -> list:
    """The training records of dataset ``seed`` (the noise a run with this seed draws), or
    noise-free ones sampled
    alike."""
    from study.run.pipeline import measurement

    conf = case.conf
    if noise_free:
        # the relative kind at level 0: an absolute noise config (per sensor) has no level to zero
        conf = dict(conf, noise={**conf["noise"], "kind": "relative", "level": 0.0})
    return [measurement(conf, seed=seed * 7919 + i, vessel=case.truth_vessel).apply(df)
            for i, df in enumerate(case.clean)]


def _iid_posterior(X, y, prior_sd, s2=None):
    """Normal posterior of the iid likelihood at the noise scale ``s2`` (its most probable value
    when None)."""
    n, k = X.shape
    A = X.T @ X
    if s2 is None:
        ls, *_ = np.linalg.lstsq(X, y, rcond=None)
        s2 = float(np.sum((y - X @ ls) ** 2)) / max(n - k, 1)
    H = A / s2 + np.diag(1.0 / prior_sd ** 2)
    cov = np.linalg.inv(H)
    return cov @ (X.T @ y) / s2, cov, s2


def _reported(model, names, mean, cov, rng, draws: int, level: float):
    """{parameter: (estimate, low, high)} of the parameters a run reports (K, T, alpha for Nomoto
    models)."""
    q = (0.5 - level / 2, 0.5 + level / 2)
    if model.type == "nomoto":
        D = rng.multivariate_normal(mean, cov, size=draws, method="cholesky")
        ph = model.physical(dict(zip(names, D.T)))
        return {p: (float(np.median(v)), *map(float, np.quantile(v, q))) for p, v in ph.items()}
    z = stats.norm.ppf(q[1])
    sd = np.sqrt(np.diag(cov))
    return {n: (float(m), float(m - z * s), float(m + z * s)) for n, m, s in zip(names, mean, sd)}


def _limit(model, names, mean) -> dict:
    if model.type == "nomoto":
        return {k: float(v) for k, v in model.physical(dict(zip(names, mean))).items()}
    return dict(zip(names, map(float, mean)))


class _Whitening:
    """The fitted noise model as ``truncation_bias`` reads it off an estimator (``row_noise_``)."""

    def __init__(self, noise):
        self.row_noise_ = noise


def dataset_intervals(case: Case, structure, seed: int, likelihood: str = "regression", level: float = 0.9,
                      draws: int = 4000, correct: bool = True) -> list[dict]:
    """One dataset: per reported parameter its estimate, interval, truth, the structure's
    noise-free limit and ``bias_est``, the truncation bias the run estimates from its own noisy
    records (``study.identify.truncation``; its aim: ``limit - truth``)."""
    from study.identify.estimators.bayes import EmceeSampler
    from study.identify.fit import truncation_bias
    from study.identify.rows import prepare, row_errors, truncation_rows

    if likelihood not in LIKELIHOODS:
        raise ValueError(f"likelihood must be one of {LIKELIHOODS}, got {likelihood!r}")
    model = case.model
    ops = likelihood == "regression"
    recs, recs_clean = records(case, seed), records(case, seed, noise_free=True)  # each measured once
    noisy = prepare(model, structure, recs, seed=seed, operators=ops)
    clean = prepare(model, structure, recs_clean, seed=seed, operators=ops)
    truth = model.truth()[0]
    est = EmceeSampler(interval=level, correct_rows=correct)
    rng = np.random.default_rng(seed)
    trunc = truncation_rows(model, structure, recs)  # estimated from the noisy records only
    errs = row_errors(model, structure, recs, noisy, trunc, seed=seed) if ops and correct else {}
    errs_clean = (row_errors(model, structure, recs_clean, clean, seed=seed, n_probes=0)
                  if ops and correct else {})
    out = []
    for eq, pr in noisy.items():
        names = list(pr.X.columns)
        X, y = pr.X.to_numpy(), pr.y
        Xc, yc = clean[eq].X.to_numpy(), clean[eq].y
        sd0 = est._default_prior_sd(X, y)
        if ops:
            mean, cov, _, noise = est.gaussian_regression(X, y, pr.noise_operators, errors=errs.get(eq))
            q = None if noise is None else noise.q_raw
            lim = est.gaussian_regression(Xc, yc, clean[eq].noise_operators, q_raw=q, prior_sd=sd0,
                                          errors=errs_clean.get(eq))[0]
        else:
            mean, cov, s2 = _iid_posterior(X, y, sd0)
            lim = _iid_posterior(Xc, yc, sd0, s2)[0]
            noise = None
        # the run's own estimate of the structure's truncation bias (study.identify.truncation), at the estimate
        b = truncation_bias(_Whitening(noise), pr, trunc.get(eq), mean, names)
        biased = _limit(model, names, mean + np.array([b.get(n, np.nan) for n in names]))
        rep = _reported(model, names, mean, cov, rng, draws, level)
        limit = _limit(model, names, lim)
        for p, (m, lo, hi) in rep.items():
            if p in truth:
                out.append({"equation": eq, "name": p, "estimate": m, "ci_low": lo, "ci_high": hi,
                            "truth": float(truth[p]), "limit": limit[p], "seed": seed,
                            "bias_est": biased[p] - _limit(model, names, mean)[p]})
    return out


def coverage(case: Case, structure: str | dict, n: int = 60, likelihood: str = "regression", seed0: int = 1,
             level: float = 0.9, correct: bool = True) -> pd.DataFrame:
    """Intervals of ``n`` datasets (seeds ``seed0 .. seed0 + n - 1``), one row per dataset and
    parameter, with ``covers_truth``, ``covers_limit``."""
    from study.identify.structures import make_structure

    st = make_structure(structure)
    rows = []
    for s in range(seed0, seed0 + n):
        rows += dataset_intervals(case, st, s, likelihood, level, correct=correct)
    df = pd.DataFrame(rows)
    df["structure"], df["case"] = st.name, case.name
    df["likelihood"] = likelihood + ("" if correct or likelihood != "regression" else " (uncorrected)")
    df["covers_truth"] = (df["ci_low"] <= df["truth"]) & (df["truth"] <= df["ci_high"])
    df["covers_limit"] = (df["ci_low"] <= df["limit"]) & (df["limit"] <= df["ci_high"])
    return df


def summary(df: pd.DataFrame, by=("case", "structure", "likelihood")) -> pd.DataFrame:
    """Per group: intervals, coverage of the truth and of the noise-free limit (all parameters
    and the worst one), median interval width and median absolute error relative to the truth,
    the limit's bias in posterior sd (median |limit - truth| / (interval width / 3.29), 3.29 =
    the width of a 90 % normal interval in sd), the run's own estimate of it (``est_bias_sd``,
    from ``bias_est``), and ``sd_ratio``: the posterior sd (median interval width / 3.29) over
    the actual spread of the estimates over the datasets, the median over the parameters (1:
    calibrated; the spread of 60 estimates is known to +-9 %)."""
    z2 = 2.0 * stats.norm.ppf(0.95)
    d = df.assign(width=(df["ci_high"] - df["ci_low"]).abs() / df["truth"].abs(),
                  error=(df["estimate"] - df["truth"]).abs() / df["truth"].abs(),
                  limit_bias_sd=(df["limit"] - df["truth"]).abs() / ((df["ci_high"] - df["ci_low"]).abs() / z2),
                  est_bias_sd=df["bias_est"].abs() / ((df["ci_high"] - df["ci_low"]).abs() / z2))
    g = d.groupby(list(by))
    keys = list(by) + ["name"]
    per = d.groupby(keys)[["covers_truth", "covers_limit"]].mean()
    spread = d.groupby(keys).apply(lambda x: ((x["ci_high"] - x["ci_low"]).abs() / z2).median()
                                   / x["estimate"].std(), include_groups=False)
    return pd.DataFrame({
        "intervals": g.size(), "datasets": g["seed"].nunique(),
        "cover_truth": g["covers_truth"].mean(), "worst_truth": per["covers_truth"].groupby(list(by)).min(),
        "cover_limit": g["covers_limit"].mean(), "worst_limit": per["covers_limit"].groupby(list(by)).min(),
        "median_rel_width": g["width"].median(), "median_rel_error": g["error"].median(),
        "limit_bias_sd": g["limit_bias_sd"].median(), "est_bias_sd": g["est_bias_sd"].median(),
        "sd_ratio": spread.groupby(list(by)).median()}).reset_index()
