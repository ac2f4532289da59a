"""The CI study: one of every figure kind the table allows, no claims (it is too small to test any).

``build`` writes the study's figures and tables into ``paper_figs/smoke/`` and appends its claim (if any) to
``claims``; ``python -m study.figures`` finds this module by the study's name (``conf/experiment/smoke.yaml``)."""
from __future__ import annotations

import json

from ..figures.plots import (
    NOISE_ORDER, _order, Builder, _first, drift_heatmaps, fit_time_figure, collinearity_tables, vif_table,
    correlation_figure, validation_figure, rmse_cc_table, lcurve_figure, convergence_figure, emcee_figures,
)

NAME = "smoke"
SEED = None  # no seed paper's claim


def build(b: Builder, runs, params, claims):
    """The CI study: one of every figure kind the table allows, no claims (it is too small to test any)."""
    s = "smoke"
    r, p = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    for model in _order(r["cfg_model.name"], []):
        for noise in _order(r[r["cfg_model.name"] == model]["cfg_noise.name"], NOISE_ORDER):
            drift_heatmaps(b, r, p, s, model, noise, f"drift_heatmap_{model}_{noise}")
    collinearity_tables(b, r, s)
    vif_table(b, p, s)
    run = _first(r[r["cfg_structure.name"] != "output_error"], **{"cfg_estimator.name": "ls"})
    if run is not None:
        correlation_figure(b, r, s, run, f"{run['cfg_model.name']}, {run['cfg_structure.name']}")
        man = json.loads(run["cfg_maneuvers.validate"])[0]
        ent = [(e, x["run_id"]) for e in ("ls", "de", "emcee")
               if (x := _first(r, **{"cfg_estimator.name": e, "cfg_model.name": run["cfg_model.name"],
                                     "cfg_structure.name": run["cfg_structure.name"]})) is not None]
        validation_figure(b, s, ent, man, f"validation_{man}", f"{man} predicted by three estimators")
    rmse_cc_table(b, r, s, ("cfg_model.name", "cfg_estimator.name", "cfg_structure.name"),
                  sorted({m for v in r["cfg_maneuvers.validate"] for m in json.loads(v)}), ("r",))
    lc = [(f"{x['cfg_model.name']}, {x['cfg_structure.name']}", x) for _, x in
          r[r["cfg_estimator.name"] == "tlssvm"].sort_values("run_id").head(2).iterrows()]
    lcurve_figure(b, s, lc, eq="N")
    run = _first(r, **{"cfg_estimator.name": "lssvm_online"})
    if run is not None:
        convergence_figure(b, s, run, p, "online_convergence", f"{run['cfg_model.name']}, {run['cfg_structure.name']}")
    run = _first(r, **{"cfg_estimator.name": "emcee", "cfg_structure.name": "output_error"})
    if run is not None:
        emcee_figures(b, s, run, p, json.loads(run["cfg_maneuvers.validate"])[0])
    fit_time_figure(b, r, s)
