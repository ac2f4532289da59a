"""What a simulated run (``study.run.pipeline``) and a run on files (``study.run.records_run``)
share: the vessel as the engineer knows it, the estimator config with the study's overrides, whether
a model x structure x estimator can run at all, and the validation traces a run keeps as artefacts.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from study.sim import load_vessel
from study.sim.effects import ShallowWater


def shallow_water(conf: dict) -> ShallowWater:
    """The configured water depth (``depth``) as the simulator's shallow-water effect (deep
    water: no change)."""
    depth = conf.get("depth") or {}
    return ShallowWater(h_T=depth.get("h_T"), formula=depth.get("formula", "kijima_1990"))


def known_vessel(conf: dict):
    """The vessel as the engineer knows it: the vessel config at the configured depth (no current
    or wind)."""
    return load_vessel(conf["vessel"], [shallow_water(conf)])


def estimator_config(conf: dict) -> dict:
    """The run's estimator config with the study's ``estimator_overrides[<name>]`` merged into
    its params (a sweep over estimators can shorten, say, emcee's chains without touching the
    others)."""
    cfg = dict(conf["estimator"])
    over = (conf.get("estimator_overrides") or {}).get(cfg.get("name")) or {}
    if over:
        cfg["params"] = {**(cfg.get("params") or {}), **over}
    return cfg


def run_estimators(model, est_cfg: dict) -> list:
    """The run's estimator and, when the model is identified by another one (a model with effects:
    ``study.identify.fit.estimator_for``), that one too."""
    from study.identify.estimators import make_estimator
    from study.identify.fit import estimator_for

    used = estimator_for(model, est_cfg)
    return [make_estimator(est_cfg)] + ([make_estimator(used)] if used is not est_cfg else [])


def skip_reason(model, structure, *estimators) -> str | None:
    """Why this model x structure x estimator(s) cannot run (None when it can)."""
    for who in (model, *estimators):
        skip, why = who.skip(structure) if who is model else who.skip(model, structure)
        if skip:
            return why
    return None


def trace_bytes(meas, pred, channels, max_rows: int = 600, label: str = "truth") -> bytes:
    """Truth (or, with ``label='measured'``, a measured record) and prediction of one validation
    manoeuvre, thinned to at most ``max_rows`` rows, as CSV."""
    step = max(1, int(np.ceil(len(meas) / max_rows)))
    m = meas.iloc[::step].reset_index(drop=True)
    out = {"time": m["time"]}
    for c in ("u", "v", "r", "x0", "y0", "psi", "delta"):
        out[f"{label}_{c}"] = m[c]
        if c in pred:
            out[f"model_{c}"] = np.interp(m["time"], pred["time"], pred[c])
    return pd.DataFrame(out).to_csv(index=False, float_format="%.7g").encode("utf-8")

