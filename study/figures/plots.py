"""Generic figure and table builders of ``python -m study.figures``: where outputs go (:class:`Builder`: PNG and PDF
figures, CSV and Markdown tables, byte-stable between rebuilds), the results table as the figures read it
(:func:`load_tables`), and the plots and tables several studies share (drift heatmaps, fit times, collinearity,
validation traces, L-curves, online convergence, emcee posteriors). A study's own figures and its claim live in
its module of :mod:`study.studies`."""
from __future__ import annotations

import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

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

    plt.rcParams.update({"svg.hashsalt": "study", "figure.dpi": 100, "font.size": 8, "axes.titlesize": 9,
                         "legend.fontsize": 7, "pdf.fonttype": 42})
    return plt


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

    def artefact(self, run_id: str, name: str) -> bytes | None:
        for root in self.artefact_roots or [self.results]:
            p = Path(root) / "artefacts" / run_id / name
            if p.is_file():
                self.read.add((run_id, name))
                return p.read_bytes()
        return None

    def artefact_csv(self, run_id: str, name: str) -> pd.DataFrame | None:
        b = self.artefact(run_id, name)
        return pd.read_csv(io.BytesIO(b)) if b is not None else None

    def figure(self, fig, study: str, name: str, what: str) -> None:
        plt = _plt()
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
    """(runs, params) of the finished runs, params joined with the run columns the figures group by."""
    from ..results import ResultStore

    return prepare_tables(*ResultStore(results).load())


def prepare_tables(runs: pd.DataFrame, params: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The tables as the figures read them: finished runs only, params joined with the run columns the figures
    group by."""
    if not len(runs):
        return runs, params
    runs = runs[runs["status"] == "ok"].copy()
    if "cfg_study" not in runs:
        runs["cfg_study"] = None
    keep = [c for c in ("run_id", "cfg_study", "cfg_noise.name", "cfg_depth.h_T", "cfg_vessel.operation.U0",
                        "cfg_maneuvers.name", "cfg_seed", "cfg_vessel.particulars.Lpp", "cfg_case.name",
                        "m_sample_dt", "m_sample_dt_LU") if c in runs]
    p = params.drop(columns=[c for c in params.columns if c.startswith("cfg_") and c in keep], errors="ignore")
    p = p.merge(runs[keep], on="run_id", how="inner")
    p["abs_rel_error"] = p["rel_error"].abs()
    for c in ("scaled_error", "term_scale", "m_sample_dt", "m_sample_dt_LU"):  # tables written before they existed
        if c not in p:
            p[c] = np.nan
    return runs, p


def finest(df: pd.DataFrame) -> tuple[pd.DataFrame, list]:
    """(the rows at the finest sampling interval swept, ``m_sample_dt_LU``; the other intervals, finest first):
    figures that show one set-up show it at one named interval, never one picked by run-id order. A table
    without the column (written before it existed) is returned whole."""
    if "m_sample_dt_LU" not in df or not df["m_sample_dt_LU"].notna().any():
        return df, []
    dts = sorted(df["m_sample_dt_LU"].dropna().unique())
    return df[df["m_sample_dt_LU"] == dts[0]], dts[1:]


def _hT(x) -> str:
    return "deep" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{float(x):g}"


def _first(df: pd.DataFrame, **eq) -> pd.Series | None:
    sel = df
    for k, v in eq.items():
        sel = sel[sel[k] == v]
    if not len(sel):
        return None
    return sel.sort_values("run_id").iloc[0]


def drift_heatmaps(b: Builder, runs, params, study: str, model: str, noise: str, name: str):
    """Median |relative error| per estimator x parameter, one panel per structure."""
    p = params[(params["cfg_model.name"] == model) & (params["cfg_noise.name"] == noise)
               & params["truth_kind"].isin(["exact", "approximate", "derived"])]
    if not len(p):
        return None
    plt = _plt()
    structs = _order(p["cfg_structure.name"], STRUCTURE_ORDER)
    names = (p[["equation", "name"]].drop_duplicates()
             .assign(o=lambda d: d["equation"].map(EQ_ORDER).fillna(3)).sort_values(["o"], kind="stable"))
    pnames = list(dict.fromkeys(names["name"]))
    ests = _order(p["cfg_estimator.name"], ESTIMATOR_ORDER)
    fig, axes = plt.subplots(len(structs), 1, figsize=(max(6, 0.42 * len(pnames) + 2), 1.0 + 0.32 * len(ests) *
                                                        len(structs)), squeeze=False)
    from matplotlib.colors import LogNorm

    table = []
    for ax, s in zip(axes[:, 0], structs):
        piv = (p[p["cfg_structure.name"] == s].pivot_table(index="cfg_estimator.name", columns="name",
                                                           values="abs_rel_error", aggfunc="median")
               .reindex(index=ests, columns=pnames))
        im = ax.imshow(np.clip(piv.to_numpy(float), 1e-4, 10), aspect="auto", cmap="viridis",
                       norm=LogNorm(1e-4, 10))
        ax.set_yticks(range(len(ests)), ests)
        ax.set_xticks(range(len(pnames)), pnames, rotation=90)
        ax.set_title(f"{s}: median |relative error| ({model}, noise {noise})")
        for i in range(piv.shape[0]):
            for j in range(piv.shape[1]):
                v = piv.iat[i, j]
                if np.isfinite(v):
                    ax.text(j, i, f"{v:.2g}", ha="center", va="center", fontsize=5,
                            color="white" if v < 0.03 else "black")
        for e in ests:
            row = {"structure": s, "estimator": e}
            row.update({n: piv.loc[e, n] for n in pnames})
            table.append(row)
    fig.colorbar(im, ax=axes[:, 0].tolist(), shrink=0.6, label="|estimate - truth| / |truth|")
    b.figure(fig, study, name, f"parameter drift heatmaps, estimator x parameter per structure ({model}, noise "
                               f"{noise})")
    b.table(pd.DataFrame(table), study, name, f"the drift heatmap's numbers ({model}, noise {noise})")
    return pd.DataFrame(table)


def fit_time_figure(b: Builder, runs, study: str):
    r = runs[runs["t_fit"].notna()]
    if not len(r):
        return
    plt = _plt()
    ests = _order(r["cfg_estimator.name"], ESTIMATOR_ORDER)
    fig, ax = plt.subplots(figsize=(6, 3))
    structs = _order(r["cfg_structure.name"], STRUCTURE_ORDER)
    w = 0.8 / len(structs)
    rows = []
    for k, s in enumerate(structs):
        med = r[r["cfg_structure.name"] == s].groupby("cfg_estimator.name")["t_fit"].median().reindex(ests)
        ax.bar(np.arange(len(ests)) + k * w, med.to_numpy(float), width=w, label=s)
        rows += [{"structure": s, "estimator": e, "median_fit_s": med[e],
                  "runs": int(((r["cfg_structure.name"] == s) & (r["cfg_estimator.name"] == e)).sum())} for e in ests]
    ax.set_yscale("log")
    ax.set_xticks(np.arange(len(ests)) + 0.4 - w / 2, ests, rotation=45)
    ax.set_ylabel("median fit time [s]")
    ax.legend(ncol=len(structs))
    ax.set_title(f"{study}: fit time per estimator")
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
        b.table(df, study, "condition_numbers", "condition numbers of the correlation matrix (seed 000 Table 3) and "
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
    fig, axes = plt.subplots(1, len(eqs), figsize=(3.2 * len(eqs), 3.0), squeeze=False)
    for ax, e in zip(axes[0], eqs):
        C = np.array(col[e]["corr"], dtype=float)
        names = col[e]["names"]
        im = ax.imshow(C, vmin=-1, vmax=1, cmap="RdBu_r")
        ax.set_xticks(range(len(names)), names, rotation=90)
        ax.set_yticks(range(len(names)), names)
        ax.set_title(f"{e}: cond(R) = {col[e]['cond_corr']:.3g}")
        for i in range(len(names)):
            for j in range(len(names)):
                if np.isfinite(C[i, j]):
                    ax.text(j, i, f"{C[i, j]:.2f}", ha="center", va="center", fontsize=5)
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.7)
    b.figure(fig, study, "correlation_matrices", f"regressor correlation matrices per equation ({label}; seed 000 "
                                                 "Fig. 6)")


def validation_figure(b: Builder, study: str, entries: list, maneuver: str, name: str, what: str):
    """Truth against the predictions of several runs on one validation manoeuvre (from the saved traces)."""
    traces = [(lab, b.artefact_csv(rid, f"validation/{maneuver}.csv")) for lab, rid in entries]
    lost = [lab for lab, t in traces if t is None]  # a prediction that diverged leaves no trace
    traces = [(lab, t) for lab, t in traces if t is not None]
    if not traces:
        return
    plt = _plt()
    t0 = traces[0][1]
    chans = [c for c in ("u", "v", "r", "psi") if f"model_{c}" in t0]
    turning = maneuver.startswith("turning")
    n = len(chans) + (1 if turning else 0)
    fig, axes = plt.subplots(n, 1, figsize=(6.5, 1.6 * n), squeeze=False)
    scale = {"r": 180 / math.pi, "psi": 180 / math.pi}
    unit = {"u": "m/s", "v": "m/s", "r": "deg/s", "psi": "deg"}
    for ax, c in zip(axes[:, 0], chans):
        ax.plot(t0["time"], t0[f"truth_{c}"] * scale.get(c, 1), "k-", lw=1.4, label="truth")
        for lab, t in traces:
            ax.plot(t["time"], t[f"model_{c}"] * scale.get(c, 1), lw=0.9, label=lab)
        ax.set_ylabel(f"{c} [{unit[c]}]")
    axes[len(chans) - 1, 0].set_xlabel("time [s]")
    axes[0, 0].legend(ncol=3)
    if turning:
        ax = axes[-1, 0]
        ax.plot(t0["truth_y0"], t0["truth_x0"], "k-", lw=1.4)
        for lab, t in traces:
            if "model_y0" in t:
                ax.plot(t["model_y0"], t["model_x0"], lw=0.9)
        ax.set_aspect("equal")
        ax.set_xlabel("y0 (east) [m]")
        ax.set_ylabel("x0 (north) [m]")
    axes[0, 0].set_title(f"{maneuver}: predicted against simulated truth"
                         + (f" (diverged, not shown: {', '.join(lost)})" if lost else ""))
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
                "manoeuvres (seed 000 Table 4; medians over runs)")
    return df


def lcurve_figure(b: Builder, study: str, entries: list, eq: str = "N"):
    """L-curves of truncated LS-SVM runs (artefact <eq>/lcurve.csv) with the rank each chose."""
    curves = [(lab, b.artefact_csv(run["run_id"], f"{eq}/lcurve.csv"), run.get(f"m_est_{eq}_rank"))
              for lab, run in entries]
    curves = [c for c in curves if c[1] is not None]
    if not curves:
        return
    plt = _plt()
    fig, ax = plt.subplots(figsize=(4.5, 3.5))
    for lab, lc, rank in curves:
        ok = rank is not None and np.isfinite(rank)
        ax.loglog(lc["residual_norm"], lc["solution_norm"], marker="o", label=f"{lab} (rank {rank:g})" if ok else lab)
        for _, row in lc.iterrows():
            ax.annotate(str(int(row["rank"])), (row["residual_norm"], row["solution_norm"]), fontsize=6)
    ax.set_xlabel("residual norm")
    ax.set_ylabel("solution norm (standardised columns)")
    ax.legend()
    ax.set_title("truncated LS-SVM: L-curve (labels: rank r)")
    b.figure(fig, study, "lcurve", "the L-curve of the truncated LS-SVM (seed 001 Sec. 3) and the rank chosen at its "
             "corner")


def convergence_figure(b: Builder, study: str, run, params, name: str, label: str):
    """Every coefficient of an incremental LS-SVM run against the number of samples, over its truth."""
    plt = _plt()
    tru = params[params["run_id"] == run["run_id"]].set_index("name")["truth"]
    eqs = [e for e in ("X", "Y", "N") if b.artefact(run["run_id"], f"{e}/convergence.csv") is not None]
    if not eqs:
        return
    fig, axes = plt.subplots(len(eqs), 1, figsize=(6.5, 2.0 * len(eqs)), sharex=True, squeeze=False)
    for ax, eq in zip(axes[:, 0], eqs):
        cv = b.artefact_csv(run["run_id"], f"{eq}/convergence.csv")
        by_truth = any(c in tru for c in cv.columns[1:])
        for c in cv.columns[1:]:
            if c == "intercept":
                continue
            ref = tru.get(c) if by_truth else cv[c].iloc[-1]  # regression coefficients (Nomoto): / final value
            if ref is not None and np.isfinite(ref) and ref != 0:
                ax.plot(cv.iloc[:, 0], cv[c] / ref, lw=0.9, label=c)
            elif c in tru:
                ax.plot(cv.iloc[:, 0], cv[c], lw=0.9, ls=":", label=f"{c} (truth 0)")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_ylim(-1, 3)
        ax.set_ylabel(f"{eq}: estimate / {'truth' if by_truth else 'final value'}")
        ax.legend(ncol=4, fontsize=5)
    axes[-1, 0].set_xlabel("samples used")
    axes[0, 0].set_title(f"incremental LS-SVM convergence ({label})")
    b.figure(fig, study, name, f"convergence of every coefficient against the number of samples, incremental LS-SVM "
             f"({label})")


def emcee_figures(b: Builder, study: str, run, params, maneuver: str = "zigzag_35_35"):
    """Corner plot of an emcee run's chain (model parameters only) and its posterior-predictive band."""
    plt = _plt()
    raw = b.artefact(run["run_id"], "chain.npz")
    if raw is not None:
        import corner

        z = np.load(io.BytesIO(raw))
        names = [str(n) for n in z["names"]]
        k = sum(1 for n in names if "[" not in n and not n.startswith("log_sigma"))
        k = min(k, 6)  # a readable grid: the first six model parameters
        flat = z["chain"].reshape(-1, z["chain"].shape[-1])[:, :k]
        tru = params[params["run_id"] == run["run_id"]].set_index("name")["truth"]
        fig = corner.corner(flat, labels=names[:k], truths=[tru.get(n, np.nan) for n in names[:k]],
                            quantiles=[0.05, 0.5, 0.95], show_titles=True, title_fmt=".4g", bins=30,
                            plot_datapoints=False, fill_contours=True)
        b.figure(fig, study, "corner", f"emcee posterior of the model parameters ({run['cfg_model.name']}, "
                 f"{run['cfg_structure.name']}; truth lines, 5/50/95 % quantiles)")
    band = b.artefact_csv(run["run_id"], f"validation/{maneuver}_band.csv")
    if band is not None:
        chans = [c for c in ("u", "v", "r", "psi") if f"q50_{c}" in band]
        fig, axes = plt.subplots(len(chans), 1, figsize=(6.5, 2.0 * len(chans)), sharex=True, squeeze=False)
        for ax, c in zip(axes[:, 0], chans):
            f, u = (180 / math.pi, "deg/s" if c == "r" else "deg") if c in ("r", "psi") else (1.0, "m/s")
            ax.fill_between(band["time"], band[f"q05_{c}"] * f, band[f"q95_{c}"] * f, alpha=0.4,
                            label="90 % posterior-predictive band")
            ax.plot(band["time"], band[f"q50_{c}"] * f, lw=0.9, label="median")
            ax.plot(band["time"], band[f"truth_{c}"] * f, "k--", lw=0.9, label="truth")
            ax.set_ylabel(f"{c} [{u}]")
        axes[0, 0].legend()
        axes[-1, 0].set_xlabel("time [s]")
        axes[0, 0].set_title(f"{maneuver}: posterior-predictive band ({int(band['draws'].iloc[0])} draws)")
        b.figure(fig, study, f"posterior_band_{maneuver}", f"posterior-predictive band of the {maneuver} (emcee, "
                 f"{run['cfg_structure.name']})")


def _pct(x) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * x:.3g} %"


def _verdict(ratio_ok: float) -> str:
    return "holds" if ratio_ok >= 0.8 else ("holds in part" if ratio_ok >= 0.3 else "does not hold")
