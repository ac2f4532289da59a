"""The doctor's figures, as PNG bytes (the report embeds them; they are also written beside it).

- ``compare_<record>``: measured u, v, r, psi and the track against the baseline and the final model;
- ``residuals_time``, ``residuals_states``: the residual forces and moment of the baseline model (inverse
  dynamics on the training records: measured inertial forces minus the model's), against time and against
  the states and inputs -- where a missing effect leaves its signature (a current: residuals that follow the
  heading; a yaw bias: a constant offset; a missing nonlinear term: a curve against v or r);
- ``growth``: how the error of each validation record grows along it, the worst windows shaded;
- ``ladder``: the validation error of each step of the ladder.
"""
from __future__ import annotations

import io
import math

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"font.size": 8, "axes.titlesize": 9, "legend.fontsize": 7, "svg.hashsalt": "study"})
    return plt


def _png(fig) -> bytes:
    plt = _plt()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None}, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


SCALE = {"u": (1.0, "m/s"), "v": (1.0, "m/s"), "r": (180 / math.pi, "deg/s"), "psi": (180 / math.pi, "deg")}


def compare(name: str, meas, base, final, base_label: str, final_label: str) -> bytes:
    plt = _plt()
    fig, axes = plt.subplots(5, 1, figsize=(7, 9))
    t = meas["time"].to_numpy()
    for ax, c in zip(axes[:4], ("u", "v", "r", "psi")):
        f, unit = SCALE[c]
        ax.plot(t, meas[c] * f, "k.", ms=1.2, label="measured")
        for pred, lab, st in ((base, base_label, "C3-"), (final, final_label, "C0-")):
            if pred is not None:
                ax.plot(pred["time"], pred[c] * f, st, lw=1.0, label=lab)
        ax.set_ylabel(f"{c} [{unit}]")
    axes[3].set_xlabel("time [s]")
    axes[0].legend(ncol=3)
    ax = axes[4]
    ax.plot(meas["y0"], meas["x0"], "k.", ms=1.2)
    for pred, st in ((base, "C3-"), (final, "C0-")):
        if pred is not None:
            ax.plot(pred["y0"], pred["x0"], st, lw=1.0)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("y0 [m]")
    ax.set_ylabel("x0 [m]")
    axes[0].set_title(f"{name}: measured against predicted (replayed with the measured rudder)")
    return _png(fig)


def residuals_time(res: list) -> bytes:
    """``res``: per training segment dict(record, time, X, Y, N, ...)."""
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(7, 5.5), sharex=False)
    for k, eq in enumerate(("X", "Y", "N")):
        for i, r in enumerate(res):
            axes[k].plot(r["time"], r[eq], lw=0.6, color=f"C{r['record'] % 10}",
                         label=r["name"] if k == 0 and r["first"] else None)
        axes[k].axhline(0.0, color="k", lw=0.5)
        axes[k].set_ylabel(f"residual {eq} [{'N m' if eq == 'N' else 'N'}]")
    axes[-1].set_xlabel("time [s]")
    axes[0].legend(ncol=3)
    axes[0].set_title("residual forces of the baseline model (inverse dynamics on the training records)")
    return _png(fig)


def residuals_states(res: list, states: tuple) -> bytes:
    plt = _plt()
    fig, axes = plt.subplots(3, len(states), figsize=(2.1 * len(states), 5.5), squeeze=False)
    rng = np.random.default_rng(0)
    for k, eq in enumerate(("X", "Y", "N")):
        for j, s in enumerate(states):
            ax = axes[k, j]
            for r in res:
                if s not in r:
                    continue
                x, y = np.asarray(r[s]), np.asarray(r[eq])
                idx = rng.choice(len(x), min(len(x), 1500), replace=False) if len(x) > 1500 else slice(None)
                f = SCALE.get(s, (180 / math.pi, "deg") if s in ("delta", "wind_angle_rel") else (1.0, ""))[0]
                ax.plot(x[idx] * f, y[idx], ".", ms=1.0, color=f"C{r['record'] % 10}")
            ax.axhline(0.0, color="k", lw=0.5)
            if k == 2:
                unit = {"u": "m/s", "v": "m/s", "r": "deg/s", "psi": "deg", "delta": "deg",
                        "wind_angle_rel": "deg"}.get(s, "")
                ax.set_xlabel(f"{s} [{unit}]")
            if j == 0:
                ax.set_ylabel(f"residual {eq}")
    fig.suptitle("residual forces of the baseline model against the states and inputs")
    return _png(fig)


def growth(curves: list, windows: list) -> bytes:
    """``curves``: per validation record (name, t, nrmse-like running error); ``windows``: worst windows."""
    plt = _plt()
    fig, axes = plt.subplots(len(curves), 1, figsize=(7, 1.6 * len(curves) + 0.6), squeeze=False)
    for ax, (name, t, base_err, final_err) in zip(axes[:, 0], curves):
        ax.plot(t, base_err, "C3-", lw=0.9, label="baseline")
        if final_err is not None:
            ax.plot(t, final_err, "C0-", lw=0.9, label="final")
        for w in windows:
            if w["record"] == name:
                ax.axvspan(w["t_start"], w["t_end"], color="orange", alpha=0.3)
        ax.set_ylabel("|error| / spread")
        ax.set_title(f"{name}: error along the record (mean of u, v, r, psi; worst windows shaded)")
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].legend()
    return _png(fig)


def ladder(steps: list) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 2.6))
    labels = [s["step"] for s in steps]
    vals = [s["validation_error"] if np.isfinite(s["validation_error"]) else np.nan for s in steps]
    ax.bar(range(len(vals)), vals, color=["C3"] + ["C0"] * (len(vals) - 1))
    ax.set_xticks(range(len(vals)), labels)
    for i, v in enumerate(vals):
        if np.isfinite(v):
            ax.text(i, v, f"{v:.3g}", ha="center", va="bottom")
    ax.set_ylabel("validation error")
    ax.set_title("the error ladder: the model, then each effect added")
    return _png(fig)
