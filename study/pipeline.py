"""One run of the study, independent of Hydra: simulate -> measure -> identify -> validate.

``run_study(conf)`` takes the resolved configuration as a plain dict (what the Hydra app passes, and what
tests build with ``compose``) and returns the run's result: metrics, per-parameter estimates against truth,
timings. The results store (``study.results``) wraps it so that every run, ok or failed, becomes one record.
"""
from __future__ import annotations

import time

import numpy as np

from . import maneuvers as man_mod
from .identify.estimators import make_estimator
from .identify.regression import build
from .measure import MeasurementModel
from .metrics import prediction_metrics, standard_metrics
from .sim import default_dt, load_vessel, simulate
from .sim.effects import ShallowWater


def resolve_effects(effects: list, U0: float) -> list[dict]:
    """Copy effect configs, turning keys ending in ``_U0`` (fractions of the service speed) into m/s."""
    out = []
    for e in effects or []:
        e = dict(e)
        for k in [k for k in e if k.endswith("_U0")]:
            e[k[: -len("_U0")]] = float(e.pop(k)) * U0
        out.append(e)
    return out


def vessels_for(conf: dict):
    """(truth vessel with depth + environment, model vessel with depth only).

    The model vessel is what the engineer knows: the depth (measured) but not the current or wind, and not the
    coefficients being identified.
    """
    depth = conf.get("depth") or {}
    shallow = ShallowWater(h_T=depth.get("h_T"), formula=depth.get("formula", "kijima_1990"))
    U0 = float(conf["vessel"]["operation"]["U0"])
    env_effects = resolve_effects((conf.get("environment") or {}).get("effects", []), U0)
    truth = load_vessel(conf["vessel"], [shallow, *env_effects])
    base = load_vessel(conf["vessel"], [shallow])
    return truth, base


def measurement(conf: dict, seed: int) -> MeasurementModel:
    nz = dict(conf.get("noise") or {})
    return MeasurementModel(
        dt=nz.get("sample_dt"), noise_level=float(nz.get("level", 0.0)), bias=nz.get("bias") or {},
        colored=nz.get("colored"), outliers=nz.get("outliers"), dropouts=nz.get("dropouts"), seed=seed,
    )


def simulate_set(vessel, names, conf, seed_base):
    sim = conf.get("sim") or {}
    dt = sim.get("dt") or default_dt(vessel)
    out = {}
    for i, name in enumerate(names):
        man = man_mod.get_maneuver(name)
        T = man.duration_for(vessel) * float(sim.get("duration_scale", 1.0))
        out[name] = simulate(vessel, man, dt=dt, duration=T, seed=seed_base + i)
    return out


def run_study(conf: dict) -> dict:
    """Run one configuration; returns ``{'metrics', 'params', 'timings'}`` (see study.results)."""
    timings = {}
    seed = int(conf.get("seed", 0))
    t0 = time.perf_counter()
    truth, base = vessels_for(conf)
    mans = conf["maneuvers"]
    clean_train = simulate_set(truth, mans["train"], conf, seed_base=1000 * seed)
    timings["simulate_train"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    records = []
    for i, (name, df) in enumerate(clean_train.items()):
        records.append(measurement(conf, seed=seed * 7919 + i).apply(df))
    timings["measure"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    model = conf["model"]
    reg = build(base, model, records, conf["structure"]["name"])
    timings["regressors"] = time.perf_counter() - t0

    est_cfg = conf["estimator"]
    t0 = time.perf_counter()
    params, identified = [], {}
    metrics = {"n_samples": reg.n_samples}
    for eq in reg.Phi:
        est = make_estimator(est_cfg).fit(reg.Phi[eq], reg.y[eq])
        resid = reg.y[eq] - reg.Phi[eq] @ est.coef_
        metrics[f"fit_rmse_{eq}"] = float(np.sqrt(np.mean(resid ** 2)))
        metrics[f"cond_{eq}"] = float(np.linalg.cond(reg.Phi[eq] / np.linalg.norm(reg.Phi[eq], axis=0)))
        for name, value, true in zip(reg.names[eq], est.coef_, reg.truth[eq]):
            params.append({"equation": eq, "name": name, "estimate": float(value), "truth": true})
            identified[name] = float(value)
    timings["fit"] = time.perf_counter() - t0
    rel = [abs(p["estimate"] - p["truth"]) / abs(p["truth"]) for p in params if p["truth"]]
    metrics["drift_median"] = float(np.median(rel)) if rel else float("nan")
    metrics["drift_max"] = float(np.max(rel)) if rel else float("nan")

    # validation: the identified model (depth known, environment unknown) against the truth
    t0 = time.perf_counter()
    model_vessel = base.with_params(**identified)
    truth_val = simulate_set(truth, mans["validate"], conf, seed_base=1000 * seed + 500)
    pred_val = simulate_set(model_vessel, mans["validate"], conf, seed_base=1000 * seed + 500)
    L = truth.L
    for name in truth_val:
        meas, pred = truth_val[name], pred_val[name]
        if not np.all(np.isfinite(pred[["u", "v", "r", "psi"]].to_numpy())):
            metrics[f"val_{name}_diverged"] = 1.0
            continue
        for k, v in prediction_metrics(meas, pred).items():
            if np.isscalar(v):
                metrics[f"val_{name}_{k}"] = float(v)
        for label, df in (("truth", meas), ("model", pred)):
            try:
                for k, v in standard_metrics(df, L=L).items():
                    if np.isscalar(v) and not isinstance(v, str):
                        metrics[f"val_{name}_{label}_{k}"] = float(v)
            except ValueError:
                pass  # a metric the record cannot carry (e.g. too short) is simply absent
    timings["validate"] = time.perf_counter() - t0
    return {"metrics": metrics, "params": params, "timings": timings}
