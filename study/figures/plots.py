"""Generic figure and table builders of ``python -m study figures``: where outputs go
(:class:`Builder`: PNG and PDF figures, CSV and Markdown tables, byte-stable between rebuilds),
the results table as the figures read it (:func:`load_tables`), and the plots and tables several
studies share (drift heatmaps, fit times, collinearity, validation traces, L-curves, online
convergence, emcee posteriors). A study's own figures and its claim live in its module of
:mod:`study.figures.studies`; how every figure looks (colours and markers per estimator and
structure, fonts, log ticks, units) is :mod:`study.figures.style`."""
from __future__ import annotations

import io
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import textwrap

import numpy as np
import pandas as pd

from .style import (  # estimator_style: re-exported for the studies
    PRINT_WIDTH_IN, TOL_MUTED, TRUTH_STYLE, annotate_cells, estimator_style, log_ticks, rc, readability_problems,
    sampling_label, short_number, structure_style,
)

REPO = Path(__file__).resolve().parents[2]

EQ_ORDER = {"X": 0, "Y": 1, "N": 2}

ESTIMATOR_ORDER = ["ls", "ridge", "lasso", "lssvm", "tlssvm", "lssvm_online", "svr_eps", "svr_nu", "sindy", "de",
                   "emcee"]

STRUCTURE_ORDER = ["euler", "diff_center", "central", "integral", "smoothed", "output_error"]

# each level in its absolute definition (conf/noise/<level>.yaml) and its relative one (<level>_relative: the named
# studies pin it); a study holds one of the two
NOISE_ORDER = ["none", "low_outputs", "low_outputs_relative", "low", "low_relative", "medium", "medium_relative",
               "high", "high_relative"]

def _cell(text: str) -> str:
    """Text for a Markdown table cell: a bare | (as in |relative error|) would split the cell."""
    return text.replace("|", "\\|")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(rc())
    return plt


def _wrap(text: str, width: int = 100) -> str:
    """A figure title broken into lines that fit the figure (about 100 characters of 10 pt on
    PRINT_WIDTH_IN)."""
    return "\n".join(textwrap.wrap(text, width, break_on_hyphens=False))


def _order(values, preferred):
    vals = list(dict.fromkeys(values))
    return [v for v in preferred if v in vals] + sorted(v for v in vals if v not in preferred)


@dataclass
class Output:
    path: str
    what: str
    study: str


@dataclass
class Builder:
    """Where outputs go, what has been written, and the artefact reader."""

    results: Path
    out: Path
    written: list = field(default_factory=list)
    #: folders whose ``artefacts/<run_id>/`` hold the runs' artefacts (default: the results folder)
    artefact_roots: list = field(default_factory=list)
    #: (run_id, name) of every artefact read, so a study's table can carry the few its figures need
    read: set = field(default_factory=set)
    #: what keeps each figure written from print (``study/name: problem``; :func:`style.readability_problems`),
    #: also printed to stderr: a figure is still written, the rebuild says what to fix
    problems: list = field(default_factory=list)
    #: the study's runs of every status (failed ones too), set for each study by ``build_study``: a claim counts a
    #: failed fit as a loss (:func:`study.figures.verdicts.dataset_errors`)
    all_runs: pd.DataFrame | None = None
    #: (study, run_id, name) of artefacts a run's record lists that no folder holds (its records were imported
    #: without their files: ``python -m study results export --no-artefacts``); the figure is drawn without them
    missing: set = field(default_factory=set)

    def artefact(self, run_id: str, name: str) -> bytes | None:
        for root in self.artefact_roots or [self.results]:
            p = Path(root) / "artefacts" / run_id / name
            if p.is_file():
                self.read.add((run_id, name))
                return p.read_bytes()
        if self._listed(run_id, name):
            study = self.all_runs.loc[self.all_runs["run_id"] == run_id, "cfg_study"] \
                if "cfg_study" in self.all_runs else pd.Series(dtype=object)
            self.missing.add((str(study.iloc[0]) if len(study) else "?", run_id, name))
        return None

    def _listed(self, run_id: str, name: str) -> bool:
        """Whether run ``run_id``'s record lists the artefact ``name`` (a figure probing for an
        artefact a run never wrote is no loss)."""
        r = self.all_runs
        if r is None or "artefacts" not in r:
            return False
        hit = r.loc[r["run_id"] == run_id, "artefacts"]
        if not len(hit) or not isinstance(hit.iloc[0], str):
            return False
        try:
            return name in json.loads(hit.iloc[0])
        except ValueError:
            return False

    def artefact_csv(self, run_id: str, name: str) -> pd.DataFrame | None:
        b = self.artefact(run_id, name)
        return pd.read_csv(io.BytesIO(b)) if b is not None else None

    def figure(self, fig, study: str, name: str, what: str) -> None:
        plt = _plt()
        found = [f"{study}/{name}: {p}" for p in readability_problems(fig)]
        for p in found:
            print(f"study figures: not fit for print: {p}", file=sys.stderr)
        self.problems += found
        d = self.out / study
        d.mkdir(parents=True, exist_ok=True)
        for ext in ("png", "pdf"):
            meta = {"Software": None} if ext == "png" else {"CreationDate": None, "Producer": None,
                                                             "Creator": None}
            fig.savefig(d / f"{name}.{ext}", dpi=120, metadata=meta, bbox_inches="tight")
        plt.close(fig)
        self.written.append(Output(f"{study}/{name}.{{png,pdf}}", what, study))

    def table(self, df: pd.DataFrame, study: str, name: str, what: str, floatfmt: str = ".4g") -> None:
        d = self.out / study
        d.mkdir(parents=True, exist_ok=True)
        df.to_csv(d / f"{name}.csv", index=False, float_format="%.6g", lineterminator="\n")
        (d / f"{name}.md").write_text(df.to_markdown(index=False, floatfmt=floatfmt) + "\n", encoding="utf-8")
        self.written.append(Output(f"{study}/{name}.{{csv,md}}", what, study))


def load_tables(results: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(runs, params) of the finished runs, params joined with the run columns the figures group
    by."""
    from ..store import ResultStore

    return prepare_tables(*ResultStore(results).load())


def prepare_tables(runs: pd.DataFrame, params: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The tables as the figures read them: finished runs only, params joined with the run
    columns the figures group by."""
    if not len(runs):
        return runs, params
    runs = runs[runs["status"] == "ok"].copy()
    if "cfg_study" not in runs:
        runs["cfg_study"] = None
    if "replicate" not in runs:  # a table of runs made before replicates: each run is replicate 0
        runs["replicate"] = 0
    keep = [c for c in ("run_id", "replicate", "cfg_study", "cfg_noise.name", "cfg_depth.h_T", "cfg_vessel.operation.U0",
                        "cfg_maneuvers.name", "cfg_seed", "cfg_vessel.particulars.Lpp", "cfg_case.name",
                        "m_sample_dt", "m_sample_dt_LU", "cfg_noise.sample_dt_LU") if c in runs]
    p = params.drop(columns=[c for c in params.columns if c in keep and c != "run_id"], errors="ignore")
    p = p.merge(runs[keep], on="run_id", how="inner")
    p["abs_rel_error"] = p["rel_error"].abs()
    for c in ("scaled_error", "term_scale", "m_sample_dt", "m_sample_dt_LU"):  # tables written before they existed
        if c not in p:
            p[c] = np.nan
    return runs, p


def finest(df: pd.DataFrame) -> tuple[pd.DataFrame, list]:
    """(the rows at the finest sampling interval swept, ``m_sample_dt_LU``; the other intervals,
    finest first): figures that show one set-up show it at one named interval, never one picked
    by run-id order. A table without the column (written before it existed) is returned whole."""
    if "m_sample_dt_LU" not in df or not df["m_sample_dt_LU"].notna().any():
        return df, []
    dts = sorted(df["m_sample_dt_LU"].dropna().unique())
    return df[df["m_sample_dt_LU"] == dts[0]], dts[1:]


def _hT(x) -> str:
    return "deep" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{float(x):g}"


def at_sampling(df: pd.DataFrame, which: str = "finest") -> pd.DataFrame:
    """The rows of a figure that shows one sampling interval: the finest (``which='finest'``) or
    the coarsest of the intervals the sweep asked for (``cfg_noise.sample_dt_LU``, in L/U0).
    Selected by the requested value, not the realised one (``m_sample_dt_LU``): each vessel and
    speed decimates the request to its own nearest step, so the realised finest value can belong
    to one vessel alone. A table without the request falls back on the realised interval; one
    without either is returned whole. (The claims use :func:`finest`.)"""
    for col in ("cfg_noise.sample_dt_LU", "m_sample_dt_LU"):
        if col in df and df[col].notna().any():
            vals = sorted(df[col].dropna().unique())
            return df[df[col] == (vals[0] if which == "finest" else vals[-1])]
    return df


def _first(df: pd.DataFrame, **eq) -> pd.Series | None:
    """The run of ``df`` matching ``eq``; of several (datasets), the lowest seed (the figure
    names it)."""
    sel = df
    for k, v in eq.items():
        sel = sel[sel[k] == v]
    if not len(sel):
        return None
    by = [c for c in ("cfg_seed", "run_id") if c in sel]
    return sel.sort_values(by).iloc[0]


def drift_heatmaps(b: Builder, runs, params, study: str, model: str, noise: str, name: str):
    """Median |relative error| per estimator x parameter, one panel per structure. Each cell's
    number is written where it fits at 8 pt, else the title points to the table with the numbers;
    grey cells have no relative error (a zero truth) or no run."""
    p = params[(params["cfg_model.name"] == model) & (params["cfg_noise.name"] == noise)
               & params["truth_kind"].isin(["exact", "approximate", "derived"])]
    if not len(p):
        return None
    plt = _plt()
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm

    structs = _order(p["cfg_structure.name"], STRUCTURE_ORDER)
    names = (p[["equation", "name"]].drop_duplicates()
             .assign(o=lambda d: d["equation"].map(EQ_ORDER).fillna(3)).sort_values(["o"], kind="stable"))
    pnames = list(dict.fromkeys(names["name"]))
    ests = _order(p["cfg_estimator.name"], ESTIMATOR_ORDER)
    zero = {n for n, d in p.groupby("name") if (d["truth"] == 0).all()}
    fig, axes = plt.subplots(len(structs), 1, figsize=(PRINT_WIDTH_IN, 1.1 + (0.2 * len(ests) + 0.5) * len(structs)
                                                       + 0.6), sharex=True, squeeze=False, layout="constrained")
    cmap = colormaps["viridis"].with_extremes(bad="#DDDDDD")
    norm = LogNorm(1e-4, 10)
    table, grids = [], []
    for ax, s in zip(axes[:, 0], structs):
        piv = (p[p["cfg_structure.name"] == s].pivot_table(index="cfg_estimator.name", columns="name",
                                                           values="abs_rel_error", aggfunc="median")
               .reindex(index=ests, columns=pnames))
        vals = piv.to_numpy(float)
        im = ax.imshow(np.clip(vals, 1e-4, 10), aspect="auto", cmap=cmap, norm=norm, interpolation="nearest")
        ax.set_yticks(range(len(ests)), ests)
        ax.set_xticks(range(len(pnames)), pnames, rotation=90)
        ax.set_ylabel("estimator")
        ax.set_title(f"{s} samples")
        grids.append((ax, vals))
        for e in ests:
            row = {"structure": s, "estimator": e}
            row.update({n: piv.loc[e, n] for n in pnames})
            table.append(row)
    axes[-1, 0].set_xlabel("coefficient")
    fig.colorbar(im, ax=axes[:, 0].tolist(), shrink=min(1.0, 0.9 / len(structs) ** 0.5 + 0.1), extend="both",
                 label="median |estimate - truth| / |truth| [-]")
    grey = []
    if any(np.isnan(v[:, [pnames.index(n) for n in zero]]).any() for _, v in grids if zero):
        grey.append("truth 0")
    if any(np.isnan(v[:, [j for j, n in enumerate(pnames) if n not in zero]]).any() for _, v in grids):
        grey.append("no run")
    sub = sampling_label(p)

    def title(cells):
        note = {2: "", 1: f"; cells: one significant digit, numbers in {name}.md", 0: f"; numbers in {name}.md"}
        return _wrap(f"Median |relative error| per coefficient: {model}, noise {noise}" + (f", {sub}" if sub else "")
                     + note[cells] + (f"; grey: {' or '.join(grey)}" if grey else ""))

    fig.suptitle(title(2))  # before the cells are measured: the title takes its room from the panels
    cells = 0
    for digits in (2, 1):  # one significant digit where two do not fit; none where one does not
        # every panel has the same cells: all are written or none
        if all([annotate_cells(fig, ax, v, fmt=lambda x: short_number(x, digits), dark=lambda x: x < 0.03)
                for ax, v in grids]):
            cells = digits
            break
    fig.suptitle(title(cells))
    b.figure(fig, study, name, f"parameter drift heatmaps, estimator x parameter per structure ({model}, noise "
                               f"{noise})")
    b.table(pd.DataFrame(table), study, name, f"the drift heatmap's numbers ({model}, noise {noise})")
    return pd.DataFrame(table)


def fit_time_figure(b: Builder, runs, study: str):
    """Median fit time per estimator (groups) and structure (bars, coloured and hatched by
    structure)."""
    r = runs[runs["t_fit"].notna()]
    if not len(r):
        return
    plt = _plt()
    ests = _order(r["cfg_estimator.name"], ESTIMATOR_ORDER)
    fig, ax = plt.subplots(figsize=(min(PRINT_WIDTH_IN, 3.2 + 0.5 * len(ests)), 3.2), layout="constrained")
    structs = _order(r["cfg_structure.name"], STRUCTURE_ORDER)
    w = 0.8 / len(structs)
    rows = []
    for k, s in enumerate(structs):
        st = structure_style(s)
        med = r[r["cfg_structure.name"] == s].groupby("cfg_estimator.name")["t_fit"].median().reindex(ests)
        ax.bar(np.arange(len(ests)) + k * w, med.to_numpy(float), width=w, label=s, color=st["color"],
               hatch=st["hatch"], edgecolor="black", linewidth=0.5)
        rows += [{"structure": s, "estimator": e, "median_fit_s": med[e],
                  "runs": int(((r["cfg_structure.name"] == s) & (r["cfg_estimator.name"] == e)).sum())} for e in ests]
    ax.set_yscale("log")
    ax.set_xticks(np.arange(len(ests)) + 0.4 - w / 2, ests, rotation=45, ha="right", rotation_mode="anchor")
    ax.set_xlabel("estimator")
    ax.set_ylabel("median fit time [s]")
    ax.legend(title="sample structure", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    log_ticks(ax)
    sub = sampling_label(r)
    ax.set_title(_wrap(f"{study}: fit time per estimator" + (f" ({sub})" if sub else ""), 80))
    b.figure(fig, study, "fit_time", "median fit time per estimator and structure")
    b.table(pd.DataFrame(rows), study, "fit_time", "median fit time per estimator and structure")


def collinearity_tables(b: Builder, runs, study: str, group=("cfg_model.name", "cfg_structure.name",
                                                              "cfg_noise.name")):
    eqs = [e for e in ("X", "Y", "N") if f"m_cond_corr_{e}" in runs]
    if not eqs:
        return None
    g = [c for c in group if c in runs]
    rows = []
    for key, d in runs.groupby(g, sort=True, dropna=False):
        key = key if isinstance(key, tuple) else (key,)
        for e in eqs:
            if d[f"m_cond_corr_{e}"].notna().any():
                rows.append({**dict(zip([c.replace("cfg_", "").replace(".name", "") for c in g], key)),
                             "equation": e, "cond_corr": d[f"m_cond_corr_{e}"].median(),
                             "cond_scaled": d[f"m_cond_{e}"].median(), "vif_max": d[f"m_vif_max_{e}"].median(),
                             "corr_max": d[f"m_corr_max_{e}"].median()})
    df = pd.DataFrame(rows)
    if len(df):
        b.table(df, study, "condition_numbers", "condition numbers of the correlation matrix (Song et al. 2025 Table 3) and "
                "of the column-scaled regressors, largest VIF and correlation, per equation (medians over runs)")
    return df


def vif_table(b: Builder, params, study: str):
    p = params[params["vif"].notna()]
    if not len(p):
        return
    piv = (p.pivot_table(index=["cfg_model.name", "cfg_structure.name", "equation", "name"], values="vif",
                         aggfunc="median").reset_index())
    b.table(piv, study, "vif", "variance inflation factor of each regressor (median over runs)")


def correlation_figure(b: Builder, runs, study: str, run: pd.Series, label: str):
    raw = b.artefact(run["run_id"], "collinearity.json")
    if raw is None:
        return
    col = json.loads(raw.decode("utf-8"))
    plt = _plt()
    eqs = [e for e in ("X", "Y", "N") if e in col]
    n = max(len(col[e]["names"]) for e in eqs)
    side = min((PRINT_WIDTH_IN - 1.0) / len(eqs), 3.0)
    fig, axes = plt.subplots(1, len(eqs), figsize=(min(PRINT_WIDTH_IN, side * len(eqs) + 1.0), side + 1.2 + 0.06 * n),
                             squeeze=False, layout="constrained")
    written = True
    for ax, e in zip(axes[0], eqs):
        C = np.array(col[e]["corr"], dtype=float)
        names = col[e]["names"]
        im = ax.imshow(C, vmin=-1, vmax=1, cmap="RdBu_r", interpolation="nearest")
        ax.set_xticks(range(len(names)), names, rotation=90)
        ax.set_yticks(range(len(names)), names)
        ax.set_xlabel("regressor")
        ax.set_ylabel("regressor")
        ax.set_title(f"{e} equation: cond(R) = {col[e]['cond_corr']:.3g}")
        written = annotate_cells(fig, ax, C, fmt=lambda v: f"{v:.2f}" if np.isfinite(v) else "",
                                 dark=lambda v: abs(v) > 0.6) and written
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.8, label="correlation coefficient [-]")
    fig.suptitle(_wrap(f"Regressor correlation matrices ({label})" + ("" if written else
                                                                      "; numbers in the run's collinearity.json")))
    b.figure(fig, study, "correlation_matrices", f"regressor correlation matrices per equation ({label}; Song et al. 2025 "
                                                 "Fig. 6)")


def validation_figure(b: Builder, study: str, entries: list, maneuver: str, name: str, what: str, setup: str = ""):
    """Truth against the predictions of several runs on one validation manoeuvre (from the saved
    traces). ``entries``: (label, run_id, style) with style a dict of ``color``, ``marker``,
    ``ls`` (from :func:`estimator_style` or :func:`structure_style`: the colour follows what the
    traces differ in); ``setup`` names what they share (model, noise, sampling interval), for the
    title. A channel no model predicts (a Nomoto model's u and v stay at their initial values) is
    left out, and the title says so."""
    entries = [e if len(e) == 3 else (e[0], e[1], {"color": TOL_MUTED[k % len(TOL_MUTED)]})
               for k, e in enumerate(entries)]
    traces = [(lab, b.artefact_csv(rid, f"validation/{maneuver}.csv"), st) for lab, rid, st in entries]
    lost = [lab for lab, t, _ in traces if t is None]  # a prediction that diverged leaves no trace
    traces = [(lab, t, st) for lab, t, st in traces if t is not None]
    if not traces:
        return
    plt = _plt()
    t0 = traces[0][1]
    chans = [c for c in ("u", "v", "r", "psi") if f"model_{c}" in t0]
    held = [c for c in chans if not any(np.nanmax(t[f"model_{c}"].to_numpy(float)) > np.nanmin(t[f"model_{c}"].to_numpy(
        float)) for _, t, _ in traces)]
    chans = [c for c in chans if c not in held]
    turning = maneuver.startswith("turning")
    fig = plt.figure(figsize=(PRINT_WIDTH_IN * 0.85, 1.45 * len(chans) + (2.6 if turning else 0) + 1.2),
                     layout="constrained")
    gs = fig.add_gridspec(len(chans) + (1 if turning else 0), 1,
                          height_ratios=[1.0] * len(chans) + ([2.2] if turning else []))
    axes = []
    for k in range(len(chans)):
        axes.append(fig.add_subplot(gs[k, 0], sharex=axes[0] if axes else None))
    scale = {"r": 180 / math.pi, "psi": 180 / math.pi}
    unit = {"u": "m/s", "v": "m/s", "r": "deg/s", "psi": "deg"}
    for k, (ax, c) in enumerate(zip(axes, chans)):
        ax.plot(t0["time"], t0[f"truth_{c}"] * scale.get(c, 1), label="truth", **TRUTH_STYLE)
        for lab, t, st in traces:
            ax.plot(t["time"], t[f"model_{c}"] * scale.get(c, 1), lw=1.1, color=st.get("color"),
                    ls=st.get("ls", "-"), marker=st.get("marker"), markevery=max(1, len(t) // 12), ms=4, label=lab)
        ax.set_ylabel(f"{c} [{unit[c]}]")
        if k < len(chans) - 1:
            ax.tick_params(labelbottom=False)
    axes[-1].set_xlabel("time [s]")
    if turning:
        ax = fig.add_subplot(gs[-1, 0])
        ax.plot(t0["truth_y0"], t0["truth_x0"], **TRUTH_STYLE)
        for lab, t, st in traces:
            if "model_y0" in t:
                ax.plot(t["model_y0"], t["model_x0"], lw=1.1, color=st.get("color"), ls=st.get("ls", "-"),
                        marker=st.get("marker"), markevery=max(1, len(t) // 12), ms=4)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("y0 (east) [m]")
        ax.set_ylabel("x0 (north) [m]")
        ax.set_title("track")
    h, lab = axes[0].get_legend_handles_labels()
    fig.legend(h, lab, loc="outside lower center", ncol=min(len(lab), 4))
    notes = []
    if lost:
        notes.append(f"diverged, not shown: {', '.join(lost)}")
    if held:
        notes.append(f"{', '.join(held)} not predicted by the model(s)")
    fig.suptitle(_wrap(f"{maneuver}: predicted against the simulated truth" + (f" ({setup})" if setup else "")
                       + ("; " + "; ".join(notes) if notes else "")))
    b.figure(fig, study, name, what)


def rmse_cc_table(b: Builder, runs, study: str, group, maneuvers, channels=("u", "v", "r")):
    rows = []
    for key, d in runs.groupby(list(group), sort=True, dropna=False):
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip([c.replace("cfg_", "").replace(".name", "") for c in group], key))
        for m in maneuvers:
            for c in channels:
                for k in ("rmse", "cc"):
                    col = f"m_val_{m}_{k}_{c}"
                    if col in d:
                        row[f"{m}_{k}_{c}"] = d[col].median()
        rows.append(row)
    df = pd.DataFrame(rows)
    if len(df):
        b.table(df, study, "rmse_cc", "RMSE and correlation coefficient of the predicted motions on the validation "
                "manoeuvres (Song et al. 2025 Table 4; medians over runs)")
    return df


def lcurve_figure(b: Builder, study: str, entries: list, eq: str = "N"):
    """L-curves of truncated LS-SVM runs (artefact <eq>/lcurve.csv) with the rank each chose
    (ringed)."""
    curves = [(lab, b.artefact_csv(run["run_id"], f"{eq}/lcurve.csv"), run.get(f"m_est_{eq}_rank"))
              for lab, run in entries]
    curves = [c for c in curves if c[1] is not None]
    if not curves:
        return
    plt = _plt()
    fig, ax = plt.subplots(figsize=(PRINT_WIDTH_IN * 0.6, 3.6), layout="constrained")
    markers = ["o", "s", "^", "v", "D"]
    for k, (lab, lc, rank) in enumerate(curves):
        ok = rank is not None and np.isfinite(rank)
        colour = TOL_MUTED[k % len(TOL_MUTED)]
        ax.loglog(lc["residual_norm"], lc["solution_norm"], marker=markers[k % 5], color=colour, lw=1.1,
                  label=f"{lab} (rank {rank:g})" if ok else lab)
        if ok:
            c = lc[lc["rank"] == rank]
            ax.plot(c["residual_norm"], c["solution_norm"], "o", ms=12, mfc="none", mec=colour, mew=1.2)
        # ranks whose points nearly coincide (within 0.03 decades) share one label, '1, 2'
        groups = []
        for _, row in lc.iterrows():
            xy = (float(row["residual_norm"]), float(row["solution_norm"]))
            near = [g for g in groups if all(abs(math.log10(a / b)) < 0.03 for a, b in zip(g[0], xy) if a > 0 and
                                             b > 0)]
            if near:
                near[0][1].append(int(row["rank"]))
            else:
                groups.append((xy, [int(row["rank"])]))
        for xy, ranks in groups:
            ax.annotate(", ".join(str(k) for k in sorted(ranks)), xy, fontsize=8, xytext=(4, 3),
                        textcoords="offset points")
    ax.set_xlabel("residual norm ||y - Z w|| [units of y]")
    ax.set_ylabel("solution norm ||w|| (standardised) [units of y]")
    log_ticks(ax, "x")
    log_ticks(ax, "y")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.22))
    ax.set_title(_wrap(f"Truncated LS-SVM, {eq} equation: L-curve (numbers: rank kept; ringed: the corner chosen)",
                       60))
    b.figure(fig, study, "lcurve", "the L-curve of the truncated LS-SVM (Xu & Guedes Soares Sec. 3) and the rank chosen at its "
             "corner")


#: the convergence figures' axis: estimate / truth, linear within +-CONV_LINEAR (a coefficient within its truth's
#: size of the truth), logarithmic beyond, so no coefficient is cut off
CONV_LINEAR = 2.0


def convergence_figure(b: Builder, study: str, run, params, name: str, label: str, title: str | None = None):
    """Every coefficient of an incremental LS-SVM run against the number of samples, over its
    truth, on a symmetric-log axis (linear within +-2, logarithmic beyond: every coefficient
    shown, however far off). The coefficients that end beyond twice their truth (on the
    logarithmic part) are named in the title and in the caption with their final ratio. ``label``
    describes the output (README), ``title`` (default: the run's set-up) heads the figure."""
    from .style import signed_axis

    plt = _plt()
    tru = params[params["run_id"] == run["run_id"]].set_index("name")["truth"]
    eqs = [e for e in ("X", "Y", "N") if b.artefact(run["run_id"], f"{e}/convergence.csv") is not None]
    if not eqs:
        return
    fig, axes = plt.subplots(len(eqs), 1, figsize=(PRINT_WIDTH_IN, 2.3 * len(eqs) + 0.9), sharex=True,
                             squeeze=False, layout="constrained")
    markers = ["o", "s", "^", "v", "D", "<", ">", "P", "X"]
    far = []  # (coefficient, final estimate / truth) beyond +-CONV_LINEAR at the last sample
    for ax, eq in zip(axes[:, 0], eqs):
        cv = b.artefact_csv(run["run_id"], f"{eq}/convergence.csv")
        by_truth = any(c in tru for c in cv.columns[1:])
        cols = [c for c in cv.columns[1:] if c != "intercept"]
        every = max(1, len(cv) // 10)
        ys = [np.array([1.0])]
        for k, c in enumerate(cols):
            st = {"color": TOL_MUTED[k % len(TOL_MUTED)], "marker": markers[k % len(markers)], "markevery": every,
                  "ms": 4, "lw": 1.0}
            ref = tru.get(c) if by_truth else cv[c].iloc[-1]  # regression coefficients (Nomoto): / final value
            if ref is not None and np.isfinite(ref) and ref != 0:
                y = (cv[c] / ref).to_numpy(float)
                last = y[np.isfinite(y)][-1] if np.isfinite(y).any() else np.nan
                off = np.isfinite(last) and abs(last) > CONV_LINEAR
                if off:
                    far.append((c, last))
                ax.plot(cv.iloc[:, 0], y, label=f"{c} (ends at {last:.3g})" if off else c, **st)
                ys.append(y)
            elif c in tru:
                y = cv[c].to_numpy(float)
                ax.plot(cv.iloc[:, 0], y, ls=":", label=f"{c} (truth 0: the estimate)", **st)
                ys.append(y)
        ax.axhline(1.0, color="k", lw=0.8)
        signed_axis(ax, np.concatenate(ys), linthresh=CONV_LINEAR, linear_below=3.0, linscale=1.5, inner=(1.0,),
                    allow_log=False)
        ax.set_ylabel(f"{eq}: estimate / {'truth' if by_truth else 'final value'} [-]")
        ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), ncol=1 if len(cols) <= 8 else 2)
    axes[-1, 0].set_xlabel("samples used [-]")
    note = (f"ending beyond {CONV_LINEAR:g} times the truth (estimate / truth at the last sample): "
            + ", ".join(f"{c} {v:.3g}" for c, v in far) if far else
            f"every coefficient ends within {CONV_LINEAR:g} times its truth")
    fig.suptitle(_wrap(f"Incremental LS-SVM: each coefficient against the samples used ({title or _run_setup(run)}); "
                       f"symmetric-log axis, linear within ±{CONV_LINEAR:g}; {note}"))
    b.figure(fig, study, name, f"convergence of every coefficient against the number of samples, incremental LS-SVM "
             f"({label}; {note})")


def _run_setup(run) -> str:
    """What one run was: model, structure, noise, sampling interval and dataset seed, for a
    figure's title."""
    parts = [f"{run.get('cfg_model.name')}", f"{run.get('cfg_structure.name')}", f"noise {run.get('cfg_noise.name')}"]
    sub = sampling_label(pd.DataFrame([run]))
    if sub:
        parts.append(sub)
    if "cfg_seed" in run and pd.notna(run.get("cfg_seed")):
        parts.append(f"dataset seed {int(run['cfg_seed'])}")
    return ", ".join(parts)
