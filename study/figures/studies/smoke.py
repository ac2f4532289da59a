"""The CI study: one of every figure kind the table allows, no claims (it is too small to test any).

``build`` writes the study's figures and tables into ``paper_figs/smoke/`` and appends its claim
(if any) to ``claims``; ``python -m study figures`` finds this module by the study's name
(``conf/experiment/smoke.yaml``)."""
from __future__ import annotations

import json

from ..posterior_plots import emcee_figures
from ..plots import (
    NOISE_ORDER, STRUCTURE_ORDER, _order, Builder, _first, drift_heatmaps, fit_time_figure, collinearity_tables,
    vif_table, correlation_figure, validation_figure, rmse_cc_table, lcurve_figure, convergence_figure,
    estimator_style, sampling_label,
)

NAME = "smoke"
SEED = None  # no seed paper's claim


def build(b: Builder, runs, params, claims):
    """The CI study: one of every figure kind the table allows, no claims (it is too small to
    test any)."""
    s = "smoke"
    r, p = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    for model in _order(r["cfg_model.name"], []):
        for noise in _order(r[r["cfg_model.name"] == model]["cfg_noise.name"], NOISE_ORDER):
            drift_heatmaps(b, r, p, s, model, noise, f"drift_heatmap_{model}_{noise}")
    collinearity_tables(b, r, s)
    vif_table(b, p, s)
    # the single-run figures at one set-up chosen by name (not by run id): the first model in sorted order, the
    # first regression structure in STRUCTURE_ORDER (output error for emcee's posterior), noted in their titles
    models = sorted(r["cfg_model.name"].dropna().unique())
    regs = [st for st in _order(r["cfg_structure.name"], STRUCTURE_ORDER) if st != "output_error"]
    model, struct = (models[0] if models else None), (regs[0] if regs else None)
    run = _first(r, **{"cfg_estimator.name": "ls", "cfg_model.name": model, "cfg_structure.name": struct})
    if run is not None:
        sub = sampling_label(r[r["cfg_model.name"] == model])
        correlation_figure(b, r, s, run, f"{model}, {struct}, noise {run['cfg_noise.name']}, {sub}")
        man = json.loads(run["cfg_maneuvers.validate"])[0]
        ent = [(e, x["run_id"], estimator_style(e)) for e in ("ls", "de", "emcee")
               if (x := _first(r, **{"cfg_estimator.name": e, "cfg_model.name": model,
                                     "cfg_structure.name": struct})) is not None]
        validation_figure(b, s, ent, man, f"validation_{man}", f"{man} predicted by three estimators",
                          setup=f"{model}, {struct} samples, noise {run['cfg_noise.name']}, {sub}")
    rmse_cc_table(b, r, s, ("cfg_model.name", "cfg_estimator.name", "cfg_structure.name"),
                  sorted({m for v in r["cfg_maneuvers.validate"] for m in json.loads(v)}), ("r",))
    lc = [(f"{m}, {struct}", x) for m in models
          if (x := _first(r, **{"cfg_estimator.name": "tlssvm", "cfg_model.name": m,
                                "cfg_structure.name": struct})) is not None]
    lcurve_figure(b, s, lc, eq="N")
    run = _first(r, **{"cfg_estimator.name": "lssvm_online", "cfg_model.name": model, "cfg_structure.name": struct})
    if run is not None:
        convergence_figure(b, s, run, p, "online_convergence", f"{run['cfg_model.name']}, {run['cfg_structure.name']}")
    run = _first(r, **{"cfg_estimator.name": "emcee", "cfg_model.name": model, "cfg_structure.name": "output_error"})
    if run is not None:
        emcee_figures(b, s, run, p, json.loads(run["cfg_maneuvers.validate"])[0])
    fit_time_figure(b, r, s)
