"""The posterior figures of an emcee run: its corner plot and its posterior-predictive band on a
validation manoeuvre, with a note on how much of the truth the band holds."""
from __future__ import annotations

import io
import math

import numpy as np

from .plots import Builder, _plt, _run_setup, _wrap
from .style import OKABE_BLUE, PRINT_WIDTH_IN, param_label

__all__ = ["emcee_figures", "band_coverage_note"]


def emcee_figures(b: Builder, study: str, run, params, maneuver: str = "zigzag_35_35"):
    """Corner plot of an emcee run's chain (model parameters only) and its posterior-predictive
    band, with the band's width drawn again around the posterior median (on the scale of a
    manoeuvre a narrow band is invisible)."""
    plt = _plt()
    setup = _run_setup(run)
    raw = b.artefact(run["run_id"], "chain.npz")
    if raw is not None:
        import corner

        z = np.load(io.BytesIO(raw))
        names = [str(n) for n in z["names"]]
        k = sum(1 for n in names if "[" not in n and not n.startswith("log_sigma"))
        k = min(k, 6)  # a readable grid: the first six model parameters
        flat = z["chain"].reshape(-1, z["chain"].shape[-1])[:, :k]
        tru = params[params["run_id"] == run["run_id"]].set_index("name")["truth"]
        size = min(PRINT_WIDTH_IN, 1.9 * k + 1.2)
        fig = plt.figure(figsize=(size, size))
        corner.corner(flat, fig=fig, labels=[param_label(n) for n in names[:k]],
                      truths=[tru.get(n, np.nan) for n in names[:k]], truth_color=OKABE_BLUE,
                      quantiles=[0.05, 0.5, 0.95], show_titles=True, title_fmt=".4g", bins=30,
                      plot_datapoints=False, fill_contours=True, max_n_ticks=3,
                      label_kwargs={"fontsize": 9}, title_kwargs={"fontsize": 8})
        for ax in fig.axes:
            ax.tick_params(labelsize=8)
        fig.subplots_adjust(left=1.0 / size, bottom=1.0 / size, right=1 - 0.15 / size, top=1 - 0.85 / size,
                            wspace=0.08, hspace=0.08)
        fig.suptitle(_wrap(f"emcee posterior ({setup}); blue: truth; dashed: 5, 50, 95 % quantiles",
                           int(size * 13)))
        b.figure(fig, study, "corner", f"emcee posterior of the model parameters ({run['cfg_model.name']}, "
                 f"{run['cfg_structure.name']}; truth lines, 5/50/95 % quantiles)")
    band = b.artefact_csv(run["run_id"], f"validation/{maneuver}_band.csv")
    if band is not None:
        chans = [c for c in ("u", "v", "r", "psi") if f"q50_{c}" in band]
        inside = {c: float(((band[f"q05_{c}"] <= band[f"truth_{c}"]) & (band[f"truth_{c}"] <= band[f"q95_{c}"])).mean())
                  for c in chans}
        verdict = band_coverage_note(run, params, inside)
        fig, axes = plt.subplots(2 * len(chans), 1, figsize=(PRINT_WIDTH_IN * 0.85, 2.6 * len(chans) + 1.0),
                                 sharex=True, squeeze=False, layout="constrained",
                                 gridspec_kw={"height_ratios": [1.6, 1.0] * len(chans)})
        fill = {"color": OKABE_BLUE, "alpha": 0.3, "edgecolor": OKABE_BLUE, "linewidth": 0.6}
        for k, c in enumerate(chans):
            f, u = (180 / math.pi, "deg/s" if c == "r" else "deg") if c in ("r", "psi") else (1.0, "m/s")
            ax, dev = axes[2 * k, 0], axes[2 * k + 1, 0]
            t, q05, q50, q95 = band["time"], band[f"q05_{c}"] * f, band[f"q50_{c}"] * f, band[f"q95_{c}"] * f
            truth = band[f"truth_{c}"] * f
            ax.fill_between(t, q05, q95, label="90 % posterior-predictive band", **fill)
            ax.plot(t, q50, color=OKABE_BLUE, lw=1.2, label="posterior median")
            ax.plot(t, truth, color="black", ls="--", lw=1.1, label="truth")
            ax.set_ylabel(f"{c} [{u}]")
            ax.set_title(f"{c}: the truth inside the 90 % band at {100 * inside[c]:.0f} % of the samples", loc="left")
            dev.fill_between(t, q05 - q50, q95 - q50, **fill)
            dev.plot(t, truth - q50, color="black", ls="--", lw=1.1)
            dev.axhline(0.0, color=OKABE_BLUE, lw=1.0)
            dev.set_ylabel(f"{c} - median [{u}]")
        for ax in axes[:-1, 0]:
            ax.tick_params(labelbottom=False)
        axes[-1, 0].set_xlabel("time [s]")
        h, lab = axes[0, 0].get_legend_handles_labels()
        fig.legend(h, lab, loc="outside lower center", ncol=3)
        fig.suptitle(_wrap(f"{maneuver}: posterior-predictive band of emcee ({setup}; {int(band['draws'].iloc[0])} "
                           f"draws); below each channel: the band and the truth less the posterior median. {verdict}"))
        b.figure(fig, study, f"posterior_band_{maneuver}", f"posterior-predictive band of the {maneuver} (emcee, "
                 f"{run['cfg_structure.name']}). {verdict}")


def band_coverage_note(run, params, inside: dict) -> str:
    """What a posterior-predictive figure's dataset shows, from its numbers: whether the run's 90
    % parameter intervals hold the truth (how many of how many, which miss) and the share of the
    plotted record at which the truth lies inside the 90 % band, per channel (``inside``: channel
    -> share)."""
    pr = params[params["run_id"] == run["run_id"]]
    pr = pr[pr["ci_low"].notna() & pr["ci_high"].notna() & pr["truth"].notna()] if "ci_low" in pr else pr.iloc[:0]
    hit = (pr["ci_low"] <= pr["truth"]) & (pr["truth"] <= pr["ci_high"])
    missed = list(pr.loc[~hit, "name"])
    band = ", ".join(f"{100 * v:.0f} % of the {c} samples" for c, v in inside.items())
    short = [c for c, v in inside.items() if v < 0.9]
    if not len(pr):
        par = "No parameter intervals recorded"
    elif missed:
        par = (f"This dataset's 90 % intervals miss the truth for {len(missed)} of {len(pr)} parameters "
               f"({', '.join(missed)})")
    else:
        par = f"This dataset's 90 % intervals hold the truth for all {len(pr)} parameters"
    rec = (f"the 90 % band holds the truth at {band}" + (" (below 90 %: the band misses the truth over much of the "
           "record)" if short else ""))
    return f"{par}; {rec}."


def _pct(x) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * x:.3g} %"


def _verdict(ratio_ok: float) -> str:
    return "holds" if ratio_ok >= 0.8 else ("holds in part" if ratio_ok >= 0.3 else "does not hold")
