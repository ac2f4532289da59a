"""emcee on Nomoto models: are the 90 % intervals calibrated, per likelihood (output error, regression) and noise?

``build`` writes the study's figures and tables into ``paper_figs/emcee_kt/`` and appends its claim (if any) to
``claims``; ``python -m study.figures`` finds this module by the study's name (``conf/experiment/emcee_kt.yaml``)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..plots import (
    Builder, _first, emcee_figures,
)

NAME = "emcee_kt"
SEED = None  # no seed paper's claim
# noise on the outputs only: the absolute and the relative definition (the study pins the relative one)
OUTPUTS_ONLY = ("low_outputs_relative", "low_outputs")


def build(b: Builder, runs, params, claims):
    s = "emcee_kt"
    r, p = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    cov = []
    for (st, nz), d in p.groupby(["cfg_structure.name", "cfg_noise.name"]):
        hit = (d["ci_low"] <= d["truth"]) & (d["truth"] <= d["ci_high"])
        cov.append({"structure": st, "noise": nz, "intervals": int(len(d)), "covered": int(hit.sum()),
                    "coverage": float(hit.mean()), "median_abs_rel_error": d["abs_rel_error"].median(),
                    "median_rel_width": ((d["ci_high"] - d["ci_low"]) / d["truth"].abs()).median()})
    if cov:
        b.table(pd.DataFrame(cov), s, "coverage", "coverage of emcee's 90 % intervals over the datasets (seeds), per "
                "likelihood (output error / regression on central differences) and noise (outputs only / rudder too)")
    # the figures show one dataset, chosen by name: the lowest seed (named in their titles)
    run = None
    for nz in OUTPUTS_ONLY:
        run = run if run is not None else _first(r, **{"cfg_structure.name": "output_error", "cfg_noise.name": nz})
    if run is not None:
        emcee_figures(b, s, run, p)
    claims.append(claim(pd.DataFrame(cov)))


def claim(cov: pd.DataFrame) -> dict:
    if not len(cov):
        return {"seed": "-", "claim": "emcee's 90 % intervals are calibrated", "study": "emcee_kt",
                "rule": "share", "verdict": "not run", "numbers": ""}
    parts = [f"{r.structure}, noise {r.noise}: {r.covered}/{r.intervals} covered" for r in cov.itertuples()]
    good = cov[(cov["structure"] == "output_error") & cov["noise"].isin(OUTPUTS_ONLY)]
    ok = float(good["coverage"].iloc[0]) if len(good) else float("nan")
    verdict = "holds" if 0.75 <= ok <= 1.0 else "does not hold"
    return {"seed": "(this harness)", "claim": "emcee's 90 % intervals cover the truth about 90 % of the time when "
            "the likelihood's assumptions hold (output error, noise on outputs only)", "study": "emcee_kt",
            "rule": "share", "verdict": verdict if np.isfinite(ok) else "not run", "numbers": "; ".join(parts) + "."}
