"""The evidence of a dataset-unit verdict, drawn whole: one point per dataset, one method's error
against the other's on the same records."""
from __future__ import annotations

import math

import numpy as np

from .plots import Builder, _plt, _wrap
from .style import PRINT_WIDTH_IN, log_ticks

__all__ = ["paired_datasets_figure"]


def paired_datasets_figure(b: Builder, study: str, panels: list, a: str, b_: str, name: str, what: str,
                           title: str, metric: str = "median |relative error| of the run's coefficients"):
    """One point per dataset: method ``a``'s error against ``b_``'s on the same records, log-log,
    one panel per ``(label, errors)`` (``errors``: rows = datasets, columns include ``a`` and
    ``b_``, as :func:`study.figures.verdicts.dataset_errors` returns them; inf = a failed fit,
    drawn at the panel's edge). Below the diagonal ``a`` wins. The evidence of a dataset-unit
    verdict, shown whole."""
    plt = _plt()
    panels = [(lab, e) for lab, e in panels if a in e and b_ in e and len(e)]
    if not panels:
        return
    n = len(panels)
    cols = min(n, 3)
    rows_ = math.ceil(n / cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(PRINT_WIDTH_IN, 2.6 * rows_ + 0.8), squeeze=False,
                             layout="constrained")
    for ax, (lab, e) in zip(axes.flat, panels):
        x, y = e[b_].to_numpy(float), e[a].to_numpy(float)
        ok = ~(np.isnan(x) | np.isnan(y))
        x, y = x[ok], y[ok]
        fin = np.concatenate([x[np.isfinite(x) & (x > 0)], y[np.isfinite(y) & (y > 0)]])
        if not len(fin):
            ax.set_visible(False)
            continue
        lo, hi = fin.min() / 2, fin.max() * 2
        xs, ys = np.clip(np.where(np.isfinite(x), x, hi), lo, hi), np.clip(np.where(np.isfinite(y), y, hi), lo, hi)
        failed = ~(np.isfinite(x) & np.isfinite(y))
        ax.plot([lo, hi], [lo, hi], color="grey", lw=0.8, ls="--")
        ax.scatter(xs[~failed], ys[~failed], s=12, color="black", alpha=0.7, lw=0)
        if failed.any():
            ax.scatter(xs[failed], ys[failed], s=22, marker="x", color="tab:red", label="a fit failed")
            ax.legend(loc="lower right", fontsize=8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        log_ticks(ax, "x")
        log_ticks(ax, "y")
        ax.set_title(f"{lab} ({int(ok.sum())} datasets)", fontsize=8)
        ax.set_xlabel(f"{b_} [-]")
        ax.set_ylabel(f"{a} [-]")
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    fig.suptitle(_wrap(f"{title}: {metric} per dataset, {a} against {b_} (below the diagonal {a} is better)"))
    b.figure(fig, study, name, what)
