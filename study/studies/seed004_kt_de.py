"""Seed 004 (Zheng & Xiao 2017): nonlinear KT models by differential evolution on output-error (integral) samples
against central differences, one record against two.

``build`` writes the study's figures and tables into ``paper_figs/seed004_kt_de/`` and appends its claim (if any) to
``claims``; ``python -m study.figures`` finds this module by the study's name (``conf/experiment/seed004_kt_de.yaml``)."""
from __future__ import annotations

import numpy as np

from ..figures.plots import (
    _plt, Builder, _first, fit_time_figure, validation_figure, _pct, _verdict,
)

NAME = "seed004_kt_de"
SEED = "004"  # the seed paper whose claim it tests: a "not run" row in CLAIMS.md until it has run


def build(b: Builder, runs, params, claims):
    s = "seed004_kt_de"
    r, p = runs[runs["cfg_study"] == s], params[params["cfg_study"] == s]
    plt = _plt()
    tab = (p.groupby(["cfg_vessel.name", "cfg_model.name", "cfg_maneuvers.name", "cfg_noise.name",
                      "cfg_structure.name"])["abs_rel_error"].max().unstack("cfg_structure.name").reset_index())
    if len(tab):
        tab.columns.name = None
        b.table(tab.rename(columns={"cfg_vessel.name": "vessel", "cfg_model.name": "model",
                                    "cfg_maneuvers.name": "records", "cfg_noise.name": "noise"}), s,
                "difference_vs_integral", "largest |relative error| of the KT parameters: DE by output error on the "
                "heading ('integral') against central differences of the heading")
        fig, axes = plt.subplots(1, 2, figsize=(10, 4.4), sharey=True, layout="constrained")
        for ax, model in zip(axes, ("nomoto1_nl", "nomoto2_nl")):
            d = tab[tab["cfg_model.name"] == model] if "cfg_model.name" in tab else tab[tab["model"] == model]
            d = d.rename(columns={"cfg_vessel.name": "vessel", "cfg_maneuvers.name": "records",
                                  "cfg_noise.name": "noise"})
            labels = [f"{v} {'x1' if m.endswith('_single') else 'x2'} {n}"
                      for v, m, n in zip(d["vessel"], d["records"], d["noise"])]
            x = np.arange(len(d))
            for k, st in enumerate(("central", "output_error")):
                if st in d:
                    ax.bar(x + 0.4 * k, d[st].to_numpy(float), width=0.4, label=st)
            ax.set_xticks(x + 0.2, labels, rotation=90, fontsize=6)
            ax.set_yscale("log")
            ax.set_title(model)
        axes[0].set_ylabel("largest |relative error|")
        axes[0].legend()
        b.figure(fig, s, "difference_vs_integral", "seed 004: KT parameters by DE, output error against central "
                 "differences, per vessel, records (x1/x2) and noise")
    ent = []
    for st in ("output_error", "central"):
        run = _first(r, **{"cfg_vessel.name": "mariner", "cfg_model.name": "nomoto1_nl", "cfg_structure.name": st,
                           "cfg_maneuvers.name": "seed004", "cfg_noise.name": "low"})
        if run is not None:
            ent.append((f"DE, {st}", run["run_id"]))
    validation_figure(b, s, ent, "zigzag_35_35", "validation_zigzag_35_35", "seed 004 Fig. 3: the 35/35 zigzag of the "
                      "Abkowitz Mariner predicted by nonlinear KT models identified by DE")
    fit_time_figure(b, r, s)
    claims.append(claim(r, p))


def claim(r, p) -> dict:
    """Verdict on the exact KT truths (kt1_mariner, kt_mariner with its own order); the Abkowitz Mariner (KT
    parameters derived by linearisation and a steady-turn fit) is reported beside it."""
    q = p.groupby(["run_id", "cfg_vessel.name", "cfg_model.name", "cfg_maneuvers.name", "cfg_noise.name",
                   "cfg_structure.name", "truth_kind"])["abs_rel_error"].max().reset_index()
    keys = ["cfg_vessel.name", "cfg_model.name", "cfg_maneuvers.name", "cfg_noise.name"]
    parts, verdict = [], "not run"
    for kinds, label in ((("exact",), "exact KT truths"), (("approximate", "derived"), "approximate or derived truths "
                                                                                       "(a KT model of another order, the Abkowitz Mariner)")):
        d = q[q["truth_kind"].isin(kinds)]
        piv = d.pivot_table(index=keys, columns="cfg_structure.name", values="abs_rel_error")
        if not {"output_error", "central"} <= set(piv.columns):
            continue
        ok = piv.dropna(subset=["output_error", "central"])
        wins, n = int((ok["output_error"] < ok["central"]).sum()), len(ok)
        med = d.groupby("cfg_structure.name")["abs_rel_error"].median()
        rec = d[d["cfg_structure.name"] == "output_error"].pivot_table(
            index=["cfg_vessel.name", "cfg_model.name", "cfg_noise.name"], columns="cfg_maneuvers.name",
            values="abs_rel_error")
        rw = int((rec["seed004"] < rec["seed004_single"]).sum()) if {"seed004", "seed004_single"} <= set(rec) else 0
        rn = int(rec.dropna().shape[0]) if len(rec) else 0
        parts.append(f"{label}: output error beats central differences in {wins} of {n} set-ups (median of the "
                     f"largest parameter error {_pct(med.get('output_error'))} against {_pct(med.get('central'))}); "
                     f"two records at once beat one in {rw} of {rn} output-error set-ups")
        if kinds == ("exact",) and n:
            verdict = _verdict(wins / n)
    return {"seed": "004 (Zheng & Xiao 2017)", "claim": "integral (output error) samples identify the nonlinear KT "
            "parameters better than differences; several records at once (parallel processing) help",
            "study": "seed004_kt_de", "verdict": verdict, "numbers": "; ".join(parts) + "."}
