"""Identify a model from records: the regression or the output-error problem, the estimator, and the
per-parameter and multicollinearity results of one run.

``identify(model, structure, estimator_cfg, records)`` is what a study run (``study.run.pipeline``)
and the model doctor call; it returns an :class:`Identification` (estimates in the model's physical
parameters, parameter rows for the results table, scalar metrics, artefact files). It fits the run's
problem (:func:`fit_regression`: one :class:`~study.identify.estimators.problem.RegressionProblem`
per equation; or :func:`fit_output_error`) through the estimator's one entry,
``Estimator.fit_problem``, then makes the rows (:func:`parameter_rows`), the errors against the
truth (:func:`drift_metrics`) and the posterior draws (:func:`posterior_draws`). ``make_problem``
builds a run's output-error problem (``study.identify.output_error``) around the equation-error
estimate. The rows themselves are built in :mod:`study.identify.rows`.
"""
from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .estimators import make_estimator
from .estimators.problem import RegressionProblem
from .priors import prior_for
from .rows import Prepared, prepare, regression_rows, row_errors, same_rows_as_central, term_scales, truncation_rows
from .trust import NEIGHBOUR_DEGREE

logger = logging.getLogger(__name__)

#: interval reported from posterior draws (emcee): the central 90 %
INTERVAL = (0.05, 0.95)
#: posterior draws kept for the posterior-predictive bands of the validation manoeuvres
MAX_DRAWS = 200


@dataclass
class Identification:
    estimates: dict  # physical name -> value
    params: list  # rows for the results table
    metrics: dict
    artefacts: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    draws: dict = field(default_factory=dict)  # physical name -> posterior draws (emcee), at most MAX_DRAWS
    vessel: object = None  # the identified model's simulation vessel when the fit makes its own (effects)
    replay: object = None  # replay(df, meta, name) -> DataFrame or None: the fit's own replay of a record, if any


#: the estimator of a model with effects (``conf/estimator/variable_projection.yaml``): what :func:`estimator_for`
#: gives such a model whatever estimator the run names
EFFECTS_ESTIMATOR = {"name": "variable_projection",
                     "_target_": "study.identify.with_effects.estimator.VariableProjection",
                     "params": {"refine": True, "max_evals": 100}}


def problem_type(model, structure) -> str:
    """The problem a run of ``model`` with ``structure`` poses: ``"effects"`` (a model with
    ``model.effects``), ``"output_error"`` (a structure that simulates) or ``"regression"``."""
    if getattr(model, "effects", ()):
        return "effects"
    return "output_error" if structure.simulates else "regression"


def estimator_for(model, estimator_cfg: dict) -> dict:
    """The estimator config a run of ``model`` is identified with: ``estimator_cfg``, except for
    a model with effects, which only variable projection identifies (:data:`EFFECTS_ESTIMATOR`,
    unless ``estimator_cfg`` is already an estimator of that problem type). The run's
    configuration, and so its run id, keeps the estimator it names."""
    if not getattr(model, "effects", ()):
        return estimator_cfg
    if "effects" in make_estimator(estimator_cfg).problem_types:
        return estimator_cfg
    return EFFECTS_ESTIMATOR


def _csv_bytes(df: pd.DataFrame) -> bytes:
    return df.to_csv(index=False, float_format="%.10g").encode("utf-8")


@dataclass
class _Fit:
    """What the fit of a run's problem hands on to its parameter rows: ``coef_rows`` (equation,
    name, estimate, extras) in the order reported, scalar metrics, artefact files, timings,
    posterior draws per name, the truncation bias in posterior sd per reported parameter, and the
    central-difference rows when the fit built them (:func:`term_scales` reuses them)."""

    coef_rows: list = field(default_factory=list)
    metrics: dict = field(default_factory=dict)
    artefacts: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    samples: dict = field(default_factory=dict)
    bias_sd: dict = field(default_factory=dict)
    central_rows: dict | None = None
    truth: dict = field(default_factory=dict)  # {name: (truth or None, truth kind)} of rows the model's truth lacks
    vessel: object = None
    replay: object = None


def identify(model, structure, estimator_cfg: dict, records, seed: int = 0, progress: bool = False,
             truth_vessel=None) -> Identification:
    """Identify ``model`` from ``records`` with the structure and the estimator config (see module
    doc).

    ``truth_vessel``: the vessel a simulated run's records come from; its environment is the
    truth of a model's effects (None: no truth for them)."""
    truth, truth_how, exact = model.truth()
    kind = problem_type(model, structure)
    est_cfg = estimator_for(model, estimator_cfg)
    if kind == "effects":
        fit = fit_effects(model, structure, est_cfg, records, seed=seed, progress=progress, truth_vessel=truth_vessel)
    else:
        fit_problem = fit_output_error if kind == "output_error" else fit_regression
        fit = fit_problem(model, structure, est_cfg, records, seed=seed, progress=progress)
    # parameter rows with truth and drift; each error also scaled by its term's weight in the equation
    scales = term_scales(model, records, rows=fit.central_rows) if truth else {}
    truth_kind = "exact" if exact else truth_how.split(":")[0]
    params = parameter_rows(fit.coef_rows, truth, truth_kind, fit.bias_sd, scales, fit.truth)
    truth = {**truth, **{n: t for n, (t, _) in fit.truth.items() if t is not None}}
    metrics = fit.metrics
    metrics.update(drift_metrics(params, truth))
    metrics["truth_exact"] = float(bool(exact))
    metrics["n_params"] = len([p for p in params if p["name"] in truth])
    estimates = {p["name"]: p["estimate"] for p in params if p["name"] in truth}
    draws = posterior_draws(model, structure, fit.samples, estimates)
    return Identification(estimates, params, metrics, fit.artefacts, fit.timings, draws, fit.vessel, fit.replay)


def fit_effects(model, structure, estimator_cfg: dict, records, seed: int = 0, progress: bool = False,
                truth_vessel=None) -> _Fit:
    """The estimator's fit of a model with effects (problem type ``"effects"``: variable
    projection, ``study.identify.with_effects``): the free coefficients and the effects'
    parameters, the estimator's diagnostics (``training_error``, ``effect_evaluations``), the
    identified model's vessel and replay. The effects' parameters are rows of truth kind ``hidden
    effect``, their truth that of ``truth_vessel``'s environment (None without it); a coefficient
    an effect frees has the truth vessel's value (the model's vessel's without it)."""
    from .with_effects.estimator import ModelWithEffects, hidden_truth
    from .with_effects.problem import EffectsProblem

    fit = _Fit()
    t0 = time.perf_counter()
    pb = EffectsProblem(model.vessel.cfg, model.cfg, records, structure)
    est = make_estimator(estimator_cfg)
    est.fit_problem(ModelWithEffects(pb, tuple(model.effects)), progress=progress)
    fit.timings["fit"] = time.perf_counter() - t0
    fit.metrics.update(est.diagnostics_ or {})  # named as the doctor names them: training_error, ...
    own = model.truth()[0]
    ref = truth_vessel if truth_vessel is not None else model.vessel
    pnames = list(ref.param_names)
    hidden = hidden_truth(pb, truth_vessel) if truth_vessel is not None else {}
    for n, v in zip(est.names_, est.coef_):
        eq = est.equations_[n]
        fit.coef_rows.append((eq, n, float(v), _intervals(est, est.names_.index(n))))
        if n in own:
            continue
        if eq != "effect":  # a coefficient an effect frees
            fit.truth[n] = (float(ref.params[pnames.index(n)]), None)
        else:
            t = hidden.get(n, ref.params[pnames.index(n)] if truth_vessel is not None and n in pnames else None)
            fit.truth[n] = (t, "hidden effect")
    fit.vessel = est.vessel_
    fit.replay = est.replay
    return fit


def fit_output_error(model, structure, estimator_cfg: dict, records, seed: int = 0, progress: bool = False) -> _Fit:
    """The estimator's fit of the run's output-error problem (:func:`make_problem`): the model's
    parameters, the problem's summary (``oe_*``) and the estimator's diagnostics (``est_*``) and
    artefacts."""
    fit = _Fit()
    t0 = time.perf_counter()
    problem = make_problem(model, structure, records, seed=seed)
    fit.timings["regressors"] = time.perf_counter() - t0
    est = make_estimator(estimator_cfg)
    t0 = time.perf_counter()
    est.fit_problem(problem, progress=progress)
    fit.timings["fit"] = time.perf_counter() - t0
    fit.metrics.update({f"oe_{k}": v for k, v in problem.summary(est.coef_).items()})
    fit.metrics.update({f"est_{k}": v for k, v in (est.diagnostics_ or {}).items()})
    for name, a in (est.artefacts_ or {}).items():
        fit.artefacts[name if "." in name else f"{name}.csv"] = a if isinstance(a, bytes) else _csv_bytes(a)
    physical = dict(zip(problem.model_names, (float(c) for c in est.coef_[:problem.k_model])))
    eq_of = {n: eq for eq, names in model.physical_names.items() for n in names}
    for j, n in enumerate(problem.model_names):
        fit.coef_rows.append((eq_of[n], n, physical[n], _intervals(est, j)))
    fit.metrics["oe_initial_states"] = len(problem.init_params)
    draws = _learned(est, "samples_")
    if draws is not None:
        fit.samples = {n: draws[:, j] for j, n in enumerate(problem.model_names)}
    return fit


def fit_regression(model, structure, estimator_cfg: dict, records, seed: int = 0, progress: bool = False) -> _Fit:
    """The estimator's fit of each equation's regression (:func:`prepare`), one estimator per
    equation, with the run's prior (``estimator.params.prior``) and, for an estimator that models
    the rows' noise, the structure's noise operators and the rows' errors; then its verdict on
    the intervals (:meth:`Estimator.trust_verdict`)."""
    fit = _Fit()
    cand = (estimator_cfg.get("extra_candidates") or {}).get("degree")
    prior = _run_prior(model, estimator_cfg, fit.metrics)
    est = make_estimator(estimator_cfg)
    # an estimator whose likelihood models the rows' noise (emcee) gets the structure's noise operators ...
    wants_ops = est.uses_noise_operators and prior is None
    t0 = time.perf_counter()
    built = regression_rows(model, structure, records, candidates=cand)
    if same_rows_as_central(structure, cand):
        fit.central_rows = built  # term_scales' rows: built once
    prepared = prepare(model, structure, records, candidates=cand, seed=seed, operators=wants_ops, rows=built)
    fit.timings["regressors"] = time.perf_counter() - t0
    # ... and the rows' truncation and regressors' noise, removed by its likelihood (study.identify.row_errors)
    errors, trunc_rows = {}, None
    if wants_ops and est.uses_row_errors and not cand:
        t0 = time.perf_counter()
        trunc_rows = truncation_rows(model, structure, records)
        errors = row_errors(model, structure, records, prepared, trunc_rows, seed=seed, n_probes=est.row_error_probes)
        fit.timings["row_errors"] = time.perf_counter() - t0
    neighbours = _neighbours(model, structure, records, prepared, seed) \
        if wants_ops and est.checks_omitted_terms and not cand else {}
    collin, coefs, fit_time = {}, {}, 0.0
    bias_reg, dropped_diff = {}, 0  # the truncation bias of a row-noise model's intervals (study.identify.truncation)
    for eq, pr in prepared.items():
        collin[eq] = _collinearity_metrics(eq, pr, fit.metrics)
        est = make_estimator(estimator_cfg)
        problem = RegressionProblem(pr.X, pr.y, _equation_prior(prior, pr.X.columns), pr.noise_operators,
                                    errors.get(eq), equation=eq, neighbours=neighbours.get(eq))
        t0 = time.perf_counter()
        est.fit_problem(problem, progress=progress)
        fit_time += time.perf_counter() - t0
        coef = np.asarray(est.coef_, float).ravel()
        if est.models_row_noise and _learned(est, "coef_std_") is not None:
            if trunc_rows is None:
                trunc_rows = truncation_rows(model, structure, records) if not cand else {}
            dropped_diff += pr.dropped_differences
            bias_reg.update(truncation_bias(est, pr, trunc_rows.get(eq), coef, problem.names))
        _record_equation(eq, est, pr, coef, fit)
        coefs.update({n: float(c) for n, c in zip(problem.names, coef)})
    fit.timings["fit"] = fit_time
    fit.artefacts["collinearity.json"] = json.dumps(collin, allow_nan=True).encode("utf-8")
    _report_physical(model, coefs, fit)
    fit.bias_sd = _bias_in_sd(model, coefs, bias_reg, fit.coef_rows)
    # the verdict is the estimator's (emcee: study.identify.trust), from what its equations reported
    verdict = est.trust_verdict(structure.name, fit.bias_sd, dropped_diff, bool(errors), fit.metrics)
    if verdict is not None:
        fit.metrics["intervals_trusted"], fit.metrics["intervals_note"] = verdict
        if not verdict[0]:
            logger.warning("intervals not trusted: %s", verdict[1])
    return fit


def _neighbours(model, structure, records, prepared: dict, seed: int) -> dict:
    """Per equation the terms the model lacks (its states' monomials up to
    ``trust.NEIGHBOUR_DEGREE``, ``Model.candidates``) on the same training rows as ``prepared``;
    empty where the model has no candidates or the structure's processing does not keep the same
    rows."""
    try:
        built = regression_rows(model, structure, records, candidates=NEIGHBOUR_DEGREE)
    except NotImplementedError:
        return {}
    out = {}
    for eq, pr in prepare(model, structure, records, candidates=NEIGHBOUR_DEGREE, seed=seed, rows=built).items():
        same = eq in prepared and len(pr.y) == len(prepared[eq].y) and np.array_equal(pr.y, prepared[eq].y)
        if same and pr.X.shape[1] > pr.n_model:
            out[eq] = pr.X.iloc[:, pr.n_model:]
    return out


def _run_prior(model, estimator_cfg: dict, metrics: dict) -> dict | None:
    """The run's prior knowledge of the coefficients (``estimator.params.prior``: map, emcee),
    per regression column, or None; its source goes to ``metrics``."""
    prior_cfg = (estimator_cfg.get("params") or {}).get("prior")
    prior = prior_for(model, prior_cfg)
    if prior is not None:
        metrics["prior_source"] = str(prior_cfg["source"])
        metrics["prior_is_truth"] = float(prior_cfg["source"] == "vessel" and bool(model.truth()[2]))
    return prior


def _equation_prior(prior: dict | None, names) -> dict | None:
    """The run's prior restricted to one equation's columns, in their order (None without a
    prior)."""
    return None if prior is None else {n: prior[n] for n in names if n in prior}


def _collinearity_metrics(eq: str, pr: Prepared, metrics: dict) -> dict:
    """One equation's structure report and multicollinearity into ``metrics``; its collinearity
    artefact entry."""
    names = list(pr.X.columns)
    for k, v in pr.report.items():
        metrics[f"{k}_{eq}"] = v
    c = pr.collinearity
    metrics.update({f"cond_{eq}": c["cond_scaled"], f"cond_corr_{eq}": c["cond_corr"],
                    f"vif_max_{eq}": float(np.nanmax(c["vif"])) if np.isfinite(c["vif"]).any() else float("nan"),
                    f"corr_max_{eq}": c["corr_max"]})
    return {"names": names[:pr.n_model], "corr": c["corr"].tolist(), "vif": c["vif"].tolist(),
            "cond_corr": c["cond_corr"], "cond_scaled": c["cond_scaled"]}


def _record_equation(eq: str, est, pr: Prepared, coef: np.ndarray, fit: _Fit) -> None:
    """One equation's fit into ``fit``: residual metrics on the training and held-out rows, the
    estimator's scalar diagnostics and artefacts, a coefficient row per column and the posterior
    draws."""
    names = list(pr.X.columns)
    intercept = _learned(est, "intercept_", 0.0)
    resid = pr.y - pr.X.to_numpy() @ coef - intercept
    fit.metrics[f"fit_rmse_{eq}"] = float(np.sqrt(np.mean(resid ** 2)))
    sy = float(np.std(pr.y))
    fit.metrics[f"fit_r2_{eq}"] = float(1.0 - np.mean(resid ** 2) / sy ** 2) if sy > 0 else float("nan")
    if len(pr.y_test):
        rt = pr.y_test - pr.X_test @ coef - intercept
        fit.metrics[f"test_rmse_{eq}"] = float(np.sqrt(np.mean(rt ** 2)))
    fit.metrics[f"est_{eq}_intercept"] = float(intercept)
    for k, v in (est.diagnostics_ or {}).items():
        if np.isscalar(v):
            fit.metrics[f"est_{eq}_{k}"] = v if isinstance(v, str) else float(v)
    for aname, a in (est.artefacts_ or {}).items():
        if isinstance(a, pd.DataFrame):
            fit.artefacts[f"{eq}/{aname}.csv"] = _csv_bytes(a)
        elif isinstance(a, bytes):
            fit.artefacts[f"{eq}/{aname}"] = a
    sel = _learned(est, "selected_")
    vif = pr.collinearity["vif"]
    for j, n in enumerate(names):
        extra = _intervals(est, j)
        extra["vif"] = float(vif[j]) if j < pr.n_model else None
        if sel is not None:
            extra["selected"] = float(bool(sel[j]))
        fit.coef_rows.append((eq, n, float(coef[j]), extra))
    draws = _learned(est, "samples_")
    if draws is not None:
        fit.samples.update({n: draws[:, j] for j, n in enumerate(names)})


def _report_physical(model, coefs: dict, fit: _Fit) -> None:
    """Nomoto models: report the physical parameters (K, T, ...), with intervals from the draws,
    and keep the regression coefficients as metrics (``coef_<equation>_<name>``)."""
    physical = model.physical({n: v for n, v in coefs.items() if n in _all(model.equations)})
    if model.type != "nomoto":
        return
    for eq, n, v, _ in fit.coef_rows:
        fit.metrics[f"coef_{eq}_{n}"] = v
    phys_samples = model.physical(fit.samples) if fit.samples else {}
    fit.coef_rows = [("N", n, physical[n], _sample_intervals(phys_samples.get(n))) for n in model.physical_names["N"]]


def parameter_rows(coef_rows: list, truth: dict, truth_kind: str, bias_sd: dict, scales: dict,
                   other: dict | None = None) -> list:
    """The results table's parameter rows: estimate, truth (0 for a candidate the truth model
    lacks), the estimator's extras, the truncation bias in posterior sd, and the error scaled by
    the term's weight. ``other``: ``{name: (truth or None, truth kind or None for truth_kind)}``
    of parameters the model's truth lacks but the fit knows (an effect's parameters)."""
    params = []
    other = other or {}
    for eq, n, v, extra in coef_rows:
        if n in other:
            t, kind = other[n][0], other[n][1] or truth_kind
            t = _num(t)
        else:
            t = truth.get(n)
            kind = truth_kind if n in truth else "candidate (not in the truth model)"
            t = _num(t if t is not None else 0.0)
        row = {"equation": eq, "name": n, "estimate": _num(v), "truth": t,
               "truth_kind": kind, **{k: _num(x) for k, x in extra.items()}}
        if n in bias_sd:
            row["truncation_bias_sd"] = _num(bias_sd[n])
        if n in scales and n in truth and row["estimate"] is not None:
            row["term_scale"] = _num(scales[n])
            row["scaled_error"] = _num(abs(row["estimate"] - row["truth"]) * scales[n])
        params.append(row)
    return params


def drift_metrics(params: list, truth: dict) -> dict:
    """Relative errors against the truth (median, max, mean over the run; median per equation,
    never pooled across equations in a claim) and the scaled errors' median and max per equation.
    No truth: no drift."""
    out = {}
    rel = [abs(p["estimate"] - p["truth"]) / abs(p["truth"]) for p in params
           if p["truth"] and p["name"] in truth and p["estimate"] is not None]
    out["drift_median"] = float(np.median(rel)) if rel else float("nan")
    out["drift_max"] = float(np.max(rel)) if rel else float("nan")
    out["drift_mean"] = float(np.mean(rel)) if rel else float("nan")
    for eq in sorted({p["equation"] for p in params}):
        rq = [abs(p["estimate"] - p["truth"]) / abs(p["truth"]) for p in params if p["equation"] == eq
              and p["truth"] and p["name"] in truth and p["estimate"] is not None]
        sq = [p["scaled_error"] for p in params if p["equation"] == eq and p.get("scaled_error") is not None]
        if rq:
            out[f"drift_median_{eq}"] = float(np.median(rq))
        if sq:
            out[f"scaled_drift_median_{eq}"] = float(np.median(sq))
            out[f"scaled_drift_max_{eq}"] = float(np.max(sq))
    return out


def posterior_draws(model, structure, samples: dict, estimates: dict) -> dict:
    """At most :data:`MAX_DRAWS` posterior draws (evenly thinned) of every reported parameter, in
    physical parameters (a Nomoto regression's coefficients mapped by the model); empty unless
    every one has draws."""
    if not samples:
        return {}
    phys = samples if structure.simulates or model.type != "nomoto" else model.physical(samples)
    names = [n for n in estimates if n in phys]
    if len(names) != len(estimates):
        return {}
    m = min(len(np.asarray(phys[n])) for n in names)
    idx = np.unique(np.linspace(0, m - 1, min(MAX_DRAWS, m)).astype(int))
    return {n: np.asarray(phys[n], float)[idx] for n in names}


# ---------------------------------------------------------------------- the output-error problem of a run
def equation_error_start(model, records) -> dict:
    """Least squares on central differences (equation error): the output-error problem's initial
    estimate."""
    from .structures import make_structure

    ident = identify(model, make_structure({"name": "central"}),
                     {"name": "ls", "_target_": "study.identify.estimators.linear.LeastSquares", "params": {}},
                     records)
    return {n: ident.estimates[n] for n in model.oe_names}


def make_problem(model, structure, records, seed: int = 0):
    """The output-error problem (``study.identify.output_error.OutputErrorProblem``) of a study
    run from the ``output_error`` block of the structure config, centred on the equation-error
    estimate."""
    from .output_error import OutputErrorProblem, default_bounds

    cfg = structure.output_error or {}
    x0 = equation_error_start(model, records)
    bounds = default_bounds(model, x0, cfg)
    return OutputErrorProblem(model, records, outputs=cfg.get("outputs"), x0=x0, bounds=bounds,
                              substeps=int(cfg.get("substeps", 1)),
                              initial_state=cfg.get("initial_state", "estimate"))


def truncation_bias(est, pr, rows, coef, names) -> dict:
    """{regression column: its estimated truncation bias} of one equation: the rows' truncation
    errors at the estimate, through the post-processing's row map and the posterior's GLS map
    (``est.row_noise_``'s whitening; least squares where the rows were not whitened)."""
    from .truncation import coefficient_bias

    if rows is None or pr.row_map is None or rows[1].shape[1] != len(coef):
        return {}
    y_t, Phi_t = rows
    e = pr.row_map @ (y_t - Phi_t @ coef)
    centred = bool(getattr(pr.noise_operators, "centred", False))
    b = coefficient_bias(est.row_noise_, pr.X.to_numpy(), e, centred)
    return dict(zip(names, map(float, b)))


def _bias_in_sd(model, coefs: dict, bias: dict, coef_rows: list) -> dict:
    """{reported parameter: estimated truncation bias / posterior sd}. Nomoto models report K, T,
    alpha: their bias is the model's own map of the biased regression coefficients minus that of
    the estimate."""
    sd = {n: extra.get("std") for _, n, _, extra in coef_rows}
    if getattr(model, "type", None) == "nomoto" and bias:
        own = {n: v for n, v in coefs.items() if n in _all(model.equations)}
        ph, ph_b = model.physical(own), model.physical({n: v + bias.get(n, 0.0) for n, v in own.items()})
        bias = {n: float(ph_b[n] - ph[n]) for n in ph}
    return {n: (bias[n] / sd[n] if sd.get(n) else float("nan")) for n in bias if n in sd}


def _all(eqs: dict) -> set:
    return {n for names in eqs.values() for n in names}


def _num(x):
    if x is None:
        return None
    x = float(x)
    return x if np.isfinite(x) else None


def _learned(est, attr: str, default=None):
    """An optional learned attribute of a fitted estimator (``samples_``, ``selected_``,
    ``coef_std_``, ...: the contract in ``study.identify.estimators.base``), or ``default`` where
    the estimator sets none."""
    return getattr(est, attr, default)


def _intervals(est, j: int) -> dict:
    out = {}
    for attr, key in (("prior_mean_", "prior_mean"), ("prior_sd_", "prior_sd"),
                      ("identifiability_", "identifiability")):
        a = _learned(est, attr)
        if a is not None:
            out[key] = float(a[j])
    ci = _learned(est, "coef_interval_")
    if ci is not None:
        out["ci_low"], out["ci_high"] = float(ci[j][0]), float(ci[j][1])
    sd = _learned(est, "coef_std_")
    if sd is not None:
        out["std"] = float(sd[j])
    return out


def _sample_intervals(draws) -> dict:
    if draws is None:
        return {}
    d = np.asarray(draws, float)
    d = d[np.isfinite(d)]
    if d.size < 10:
        return {}
    lo, hi = np.quantile(d, INTERVAL)
    return {"ci_low": float(lo), "ci_high": float(hi), "std": float(np.std(d))}

