"""The doctor's figures, as PNG bytes (the report embeds them; they are also written beside it).

- ``compare_<record>``: measured u, v, r, psi and the track against the baseline and the final
  model;
- ``residuals_time``, ``residuals_states``: the residual forces and moment of the baseline model
  (inverse dynamics on the training records: measured inertial forces minus the model's), against
  time and against the states and inputs -- where a missing effect leaves its signature (a current:
  residuals that follow the heading; a yaw bias: a constant offset; a missing nonlinear term: a
  curve against v or r);
- ``growth``: how the error of each validation record grows along it, the worst windows shaded;
- ``ladder``: the validation error of each step of the ladder, a rejected step hatched, a diverged
  one marked;
- ``metric_intervals``: the turning circles' and zigzags' metrics of the validation records,
  measured against predicted with 90 % intervals.

Made to be read at the report's full width (about 900 px on screen, A4 in print): about 9.5 in wide
at 110 dpi, 10 pt text, a unit on every axis (angles and the yaw rate in degrees, said on the axis),
one legend per figure naming only what is drawn, and a replay that diverged said in the figure,
never drawn at infinity.
"""
from __future__ import annotations

import io
import math

import numpy as np

from .measurement_noise import agrees

WIDTH = 9.5  # in; at DPI this is about 1050 px, shown at the page's ~900 px
DPI = 110
C_MEAS, C_BASE, C_FINAL, C_WARN = "0.15", "C3", "C0", "#b00020"
C_TIE = "C2"
#: the two candidates of a weak verdict, drawn beside the baseline (Okabe & Ito's colour-blind-safe orange and green)
C_PAIR = ("#E69F00", "#009E73")

STYLE = {"font.size": 10, "axes.titlesize": 10.5, "axes.labelsize": 10, "xtick.labelsize": 9,
         "ytick.labelsize": 9, "legend.fontsize": 9, "figure.titlesize": 11.5, "axes.titlelocation": "left",
         "axes.grid": True, "grid.color": "0.88", "grid.linewidth": 0.6, "axes.axisbelow": True,
         "svg.hashsalt": "study"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(STYLE)
    return plt


def _png(fig) -> bytes:
    plt = _plt()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None}, bbox_inches="tight", pad_inches=0.08)
    plt.close(fig)
    return buf.getvalue()


#: factor and unit of a state or input as plotted (the records are SI, angles in radians)
SCALE = {"u": (1.0, "m/s"), "v": (1.0, "m/s"), "r": (180 / math.pi, "deg/s"), "psi": (180 / math.pi, "deg"),
         "delta": (180 / math.pi, "deg"), "wind_angle_rel": (180 / math.pi, "deg")}
NAMES = {"u": "surge speed u", "v": "sway speed v", "r": "yaw rate r", "psi": "heading psi",
         "delta": "rudder delta", "wind_angle_rel": "relative wind angle"}
FORCE_UNIT = {"X": "N", "Y": "N", "N": "N m"}


def _finite(a) -> np.ndarray:
    """``a`` as floats with +-inf as NaN (matplotlib leaves a gap there instead of scaling to
    infinity)."""
    a = np.asarray(a, dtype=float)
    return np.where(np.isfinite(a), a, np.nan)


def _col(df, c):
    return _finite(df[c].to_numpy() if hasattr(df[c], "to_numpy") else df[c])


def _warn_box(ax, text: str, y: float = 0.5) -> None:
    ax.text(0.5, y, text, transform=ax.transAxes, ha="center", va="center", color=C_WARN, fontsize=10,
            fontweight="bold", bbox={"boxstyle": "round,pad=0.3", "fc": "white", "ec": C_WARN, "alpha": 0.9},
            zorder=10)


def compare(name: str, meas, base, final, base_label: str, final_label: str, pair=()) -> bytes:
    """Measured u, v, r, psi against time and the track, with the baseline's and the final model's
    replays.

    ``base`` / ``final`` None: not drawn -- a replay that diverged when its label is given (said
    in the legend and on the panels), no such model when the label is empty (``final`` when no
    effect was added). ``pair``: up to two more (replay, label), the candidates a weak verdict
    could not tell apart."""
    plt = _plt()
    from matplotlib.lines import Line2D

    fig = plt.figure(figsize=(WIDTH, 7.4), layout="constrained")
    gs = fig.add_gridspec(4, 2, width_ratios=(1.75, 1.0))
    axes = [fig.add_subplot(gs[0, 0])]
    axes += [fig.add_subplot(gs[k, 0], sharex=axes[0]) for k in (1, 2, 3)]
    track = fig.add_subplot(gs[:, 1])
    t = _col(meas, "time")
    models = [(base, base_label or "baseline", C_BASE), (final, final_label, C_FINAL)] + \
        [(pred, lab, col) for (pred, lab), col in zip(pair, C_PAIR)]
    diverged = [lab for pred, lab, _ in models if pred is None and lab]
    for ax, c in zip(axes, ("u", "v", "r", "psi")):
        f, unit = SCALE[c]
        ax.plot(t, _col(meas, c) * f, ".", color=C_MEAS, ms=1.3, rasterized=True)
        for pred, lab, col in models:
            if pred is not None:
                ax.plot(_col(pred, "time"), _col(pred, c) * f, "-", color=col, lw=1.2)
        ax.set_ylabel(f"{c} [{unit}]")
        ax.yaxis.set_major_locator(plt.MaxNLocator(4))
        if ax is not axes[-1]:
            ax.tick_params(labelbottom=False)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title("speeds, yaw rate and heading (r and psi in degrees)")
    track.plot(_col(meas, "y0"), _col(meas, "x0"), ".", color=C_MEAS, ms=1.3, rasterized=True)
    for pred, _, col in models:
        if pred is not None:
            track.plot(_col(pred, "y0"), _col(pred, "x0"), "-", color=col, lw=1.2)
    x0, y0 = _col(meas, "x0"), _col(meas, "y0")
    ok = np.isfinite(x0) & np.isfinite(y0)
    if ok.any():
        track.plot(y0[ok][0], x0[ok][0], "o", color="k", mfc="white", ms=6, zorder=5)
    track.set_aspect("equal", adjustable="datalim")
    track.set_xlabel("y0, east [m]")
    track.set_ylabel("x0, north [m]")
    track.set_title("track (circle: start)")
    for lab in diverged:
        for ax in axes[:1] + [track]:
            _warn_box(ax, f"{lab}: replay DIVERGED, not drawn", y=0.88 if ax is track else 0.5)
    handles = [Line2D([], [], ls="", marker=".", color=C_MEAS, ms=7, label="measured")]
    for pred, lab, col in models:
        if pred is not None:
            handles.append(Line2D([], [], color=col, lw=1.6, label=lab))
        elif lab:
            handles.append(Line2D([], [], color=col, lw=1.6, ls=":", label=f"{lab}: DIVERGED (not drawn)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), frameon=False)
    fig.suptitle(f"{name}: measured and replayed open loop with the measured rudder")
    return _png(fig)


def _record_handles(res: list, marker: bool = False) -> list:
    from matplotlib.lines import Line2D

    seen, out = set(), []
    for r in res:
        if r["record"] in seen:
            continue
        seen.add(r["record"])
        col = f"C{r['record'] % 10}"
        out.append(Line2D([], [], ls="" if marker else "-", marker="o" if marker else None, ms=5, lw=1.5,
                          color=col, label=str(r.get("name", r["record"]))))
    return out


def residuals_time(res: list) -> bytes:
    """``res``: per training segment dict(record, name, first, time, X, Y, N, ...)."""
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(WIDTH, 6.6), sharex=True, layout="constrained")
    for k, eq in enumerate(("X", "Y", "N")):
        ax = axes[k]
        for r in res:
            ax.plot(_finite(r["time"]), _finite(r[eq]), lw=0.6, color=f"C{r['record'] % 10}", alpha=0.85)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"residual {eq} [{FORCE_UNIT[eq]}]")
        ax.yaxis.set_major_locator(plt.MaxNLocator(5))
    axes[-1].set_xlabel("time [s]")
    if not res:
        _warn_box(axes[1], "no training segment")
    handles = _record_handles(res)
    if handles:  # records' names are about 27 characters: three columns fit the figure's width
        fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 3), frameon=False,
                   title="training record")
    fig.suptitle("Residual forces and moment of the baseline model (inverse dynamics on the training records)")
    return _png(fig)


def residuals_states(res: list, states: tuple) -> bytes:
    plt = _plt()
    n = max(1, len(states))
    fig, axes = plt.subplots(3, n, figsize=(WIDTH, 7.0), squeeze=False, sharex="col", sharey="row",
                             layout="constrained")
    rng = np.random.default_rng(0)
    for k, eq in enumerate(("X", "Y", "N")):
        for j, s in enumerate(states):
            ax = axes[k, j]
            for r in res:
                if s not in r:
                    continue
                x, y = _finite(r[s]), _finite(r[eq])
                idx = rng.choice(len(x), min(len(x), 1500), replace=False) if len(x) > 1500 else slice(None)
                f = SCALE.get(s, (1.0, ""))[0]
                ax.plot(x[idx] * f, y[idx], ".", ms=1.2, color=f"C{r['record'] % 10}", alpha=0.7,
                        rasterized=True)
            ax.axhline(0.0, color="k", lw=0.6)
            ax.xaxis.set_major_locator(plt.MaxNLocator(4))
            ax.yaxis.set_major_locator(plt.MaxNLocator(5))
            if k == 2:
                unit = SCALE.get(s, (1.0, "as recorded"))[1]
                ax.set_xlabel(f"{s} [{unit}]")
            if j == 0:
                ax.set_ylabel(f"residual {eq} [{FORCE_UNIT[eq]}]")
    if not states:
        _warn_box(axes[1, 0], "no state to plot against")
    handles = _record_handles(res, marker=True)
    if handles:  # three columns of record names fit the figure's width (six made it 15 in wide)
        fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 3), frameon=False,
                   title="training record")
    fig.suptitle("Residual forces and moment of the baseline model against the states and inputs")
    return _png(fig)


def growth(curves: list, windows: list) -> bytes:
    """``curves``: per validation record (name, t, baseline's running error, final's or None);
    ``windows``: the worst windows. A baseline curve that is all NaN is a replay that diverged:
    said in its panel."""
    plt = _plt()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    n = max(1, len(curves))
    fig, axes = plt.subplots(n, 1, figsize=(WIDTH, 1.9 * n + 1.3), squeeze=False, layout="constrained")
    any_final = any_window = any_base = False
    for ax, (name, t, base_err, final_err) in zip(axes[:, 0], curves):
        t = _finite(t)
        b = _finite(base_err) if base_err is not None else np.full(len(t), np.nan)
        if np.isfinite(b).any():
            ax.plot(t, b, "-", color=C_BASE, lw=1.0)
            any_base = True
        else:
            _warn_box(ax, "baseline replay DIVERGED: no error curve")
            ax.tick_params(axis="y", labelleft=False)
            if np.isfinite(t).any():
                ax.set_xlim(np.nanmin(t), np.nanmax(t))
        if final_err is not None and np.isfinite(_finite(final_err)).any():
            ax.plot(t, _finite(final_err), "-", color=C_FINAL, lw=1.0)
            any_final = True
        for w in windows:
            if w["record"] == name:
                ax.axvspan(w["t_start"], w["t_end"], color="orange", alpha=0.3, lw=0)
                any_window = True
        ax.set_ylim(bottom=0.0)
        ax.yaxis.set_major_locator(plt.MaxNLocator(4))
        ax.set_ylabel("error [-]")
        ax.set_title(str(name), fontweight="bold")
        ax.set_xlabel("time [s]")
    if not curves:
        _warn_box(axes[0, 0], "no validation record")
    handles = []
    if any_base:
        handles.append(Line2D([], [], color=C_BASE, lw=1.6, label="baseline"))
    if any_final:
        handles.append(Line2D([], [], color=C_FINAL, lw=1.6, label="with the effects found"))
    if any_window:
        handles.append(Patch(color="orange", alpha=0.3, label="worst window of the baseline"))
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), frameon=False)
    fig.suptitle("Error along each record: |predicted - measured| / spread of the measured channel, "
                 "mean of u, v, r, psi")
    return _png(fig)


def _f(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def ladder(steps: list) -> bytes:
    """Bars of the validation error of each ladder step (dicts with ``step``,
    ``validation_error`` and optionally ``diverged`` (records), ``rejected``): the baseline red,
    accepted steps blue, a rejected step hatched, a diverged step (no finite error) a marker and
    the word "DIVERGED" instead of a bar."""
    plt = _plt()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    n = max(1, len(steps))
    fig, ax = plt.subplots(figsize=(min(WIDTH, max(6.0, 1.5 * n + 2.5)), 3.6), layout="constrained")
    vals = np.array([_f(s.get("validation_error")) for s in steps], dtype=float)
    div = [bool(s.get("diverged")) or not np.isfinite(vals[i]) for i, s in enumerate(steps)]
    finite = vals[np.isfinite(vals)]
    top = float(finite.max()) if finite.size else 1.0
    top = top if top > 0 else 1.0
    kinds = set()
    for i, s in enumerate(steps):
        rejected = bool(s.get("rejected"))
        if div[i]:
            kinds.add("diverged")
            ax.plot(i, 0.06 * top, marker="X", ms=13, color=C_WARN, ls="")
            ax.text(i, 0.16 * top, "DIVERGED", ha="center", va="bottom", color=C_WARN, fontweight="bold",
                    fontsize=10)
            if rejected:
                kinds.add("rejected")
            continue
        v = vals[i]
        if rejected:
            kinds.add("rejected")
            ax.bar(i, v, width=0.62, facecolor="white", edgecolor="0.35", hatch="///", lw=1.0)
        elif i == 0:
            kinds.add("baseline")
            ax.bar(i, v, width=0.62, color=C_BASE)
        else:
            kinds.add("accepted")
            ax.bar(i, v, width=0.62, color=C_FINAL)
        ax.text(i, v + 0.02 * top, f"{v:.3g}", ha="center", va="bottom", fontsize=9.5)
    labels = []
    for i, s in enumerate(steps):
        lab = str(s.get("step", i))
        if s.get("rejected"):
            lab += "\n(rejected)"
        labels.append(lab)
    ax.set_xticks(range(len(steps)), labels)
    if len(steps) > 5:
        ax.tick_params(axis="x", labelrotation=20)
    ax.set_xlim(-0.6, n - 0.4)
    ax.set_ylim(0.0, 1.2 * top)
    ax.grid(axis="x", visible=False)
    ax.set_ylabel("validation error [-]\n(mean NRMSE)")
    handles = []
    if "baseline" in kinds:
        handles.append(Patch(color=C_BASE, label="baseline"))
    if "accepted" in kinds:
        handles.append(Patch(color=C_FINAL, label="effect added (accepted)"))
    if "rejected" in kinds:
        handles.append(Patch(facecolor="white", edgecolor="0.35", hatch="///", label="rejected step"))
    if "diverged" in kinds:
        handles.append(Line2D([], [], marker="X", ms=9, color=C_WARN, ls="", label="diverged (no error)"))
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), frameon=False)
    if not steps:
        _warn_box(ax, "no ladder step")
    fig.suptitle("Error ladder: the model, then each effect added in turn")
    return _png(fig)


#: the manoeuvre metrics the interval figure draws, in this order (the ``*_L`` rows rather than metres), and
#: their axis labels. Not the zigzag's period: a replay takes the record's rudder, whose switches set it.
INTERVAL_METRICS = {"tactical_diameter_L": "tactical diameter [L]", "advance_L": "advance [L]",
                    "transfer_L": "transfer [L]", "first_overshoot": "first overshoot [deg]",
                    "second_overshoot": "second overshoot [deg]"}


def metric_intervals(rows: list) -> bytes | None:
    """Per manoeuvre metric (:data:`INTERVAL_METRICS`), each validation record's measured value
    with its own noise's 90 % interval (black) against the final model's prediction with its 90 %
    interval (blue), the baseline's (red, open) and, under a tie, the tied readings' mixture
    (green); each panel's title counts the measured values
    inside the final model's intervals, and the pairs that agree once the measured value's noise
    is included (``study.doctor.measurement_noise.agrees``).
    None when no row has a measured value and an
    interval."""
    from matplotlib.lines import Line2D

    def ok(row, *keys):
        return all(math.isfinite(_f(row.get(k))) for k in keys)

    def bar(ax, x, v, lo, hi, **kw):
        ax.errorbar(x, v, yerr=[np.maximum(v - lo, 0.0), np.maximum(hi - v, 0.0)], capsize=3, ms=5, ls="", **kw)

    panels = [(label, [r for r in rows if r.get("metric") == m and ok(r, "measured", "final", "final_low",
                                                                       "final_high")])
              for m, label in INTERVAL_METRICS.items()]
    panels = [p for p in panels if p[1]]
    if not panels:
        return None
    plt = _plt()
    n_rec = max(len(sel) for _, sel in panels)
    fig, axes = plt.subplots(len(panels), 1, figsize=(min(WIDTH, max(6.0, 0.55 * n_rec + 3.0)),
                                                      2.3 * len(panels) + 0.9), layout="constrained",
                             squeeze=False)
    baseline_drawn = tie_drawn = False
    for ax, (label, sel) in zip(axes[:, 0], panels):
        x = np.arange(len(sel))
        col = {k: np.array([_f(r.get(k)) for r in sel]) for k in ("measured", "final", "final_low", "final_high",
                                                                    "baseline", "baseline_low", "baseline_high")}
        if all(ok(r, "baseline", "baseline_low", "baseline_high") for r in sel):
            baseline_drawn = True
            bar(ax, x - 0.2, col["baseline"], col["baseline_low"], col["baseline_high"], fmt="o", mfc="white",
                color=C_BASE, lw=1.0)
        bar(ax, x + 0.2, col["final"], col["final_low"], col["final_high"], fmt="s", color=C_FINAL, lw=1.2)
        if all(ok(r, "tie", "tie_low", "tie_high") for r in sel):
            tie_drawn = True
            t = {k: np.array([_f(r.get(k)) for r in sel]) for k in ("tie", "tie_low", "tie_high")}
            bar(ax, x + 0.4, t["tie"], t["tie_low"], t["tie_high"], fmt="D", color=C_TIE, lw=1.2)
        lo = np.array([_f(r.get("measured_low", r["measured"])) for r in sel])
        hi = np.array([_f(r.get("measured_high", r["measured"])) for r in sel])
        bar(ax, x, col["measured"], lo, hi, fmt="o", color=C_MEAS, lw=1.0)
        inside = int(np.sum((col["measured"] >= col["final_low"]) & (col["measured"] <= col["final_high"])))
        agree = sum(bool(agrees(r)) for r in sel)
        ax.set_title(f"{label}: {inside} of {len(sel)} measured inside the final model's 90 % interval; {agree} "
                     "agree with the measured value's own noise", fontsize=9)
        names = [str(r["record"]) for r in sel]
        tilt = len(sel) * max(len(n) for n in names) > 60  # record names that would overlap side by side
        ax.set_xticks(x, names, rotation=30 if tilt else 0,
                      ha="right" if tilt else "center", fontsize=8)
        ax.set_xlim(-0.6, len(sel) - 0.4 + (0.2 if tie_drawn else 0.0))
        ax.ticklabel_format(axis="y", useOffset=False)
        ax.set_ylabel(label.split(" [")[-1].rstrip("]") if "[" in label else "")
    handles = [Line2D([], [], marker="o", color=C_MEAS, label="measured, its noise's 90 %"),
               Line2D([], [], marker="s", color=C_FINAL, label="final model, 90 % interval")]
    if baseline_drawn:
        handles.append(Line2D([], [], marker="o", mfc="white", color=C_BASE, label="baseline, 90 % interval"))
    if tie_drawn:
        handles.append(Line2D([], [], marker="D", color=C_TIE, label="the tied readings mixed, 90 %"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), frameon=False)
    fig.suptitle("Manoeuvre metrics: measured against predicted, with 90 % intervals")
    return _png(fig)
