"""Which manoeuvre would tell two explanations apart.

When the doctor cannot tell two candidate effects apart (or names one on weak evidence), each
candidate's fit is simulated through a menu of standard manoeuvres -- the 10/10, 20/20, 20/10 and
35/35 zigzags and the 10 and 35 deg turning circles, each to starboard and to port, from a steady
approach at the service speed and at 60 % of it -- from the heading the records start at, and the
manoeuvres are ranked by how far the two predictions differ against the records' measurement noise.
The same score is computed for the records already run (each fit replayed through them), so the
recommendation says how much more a new record would tell than the ones in hand.

The score of a manoeuvre is how far apart the two predictions lie, in units of how far the fits
already miss the
records:

    S = sqrt( mean_t sum_c ((a_c(t) - b_c(t)) / s_c)^2 ),

over the velocities both simulate and the records hold (u, v, r), where s_c is the larger of the
channel's white measurement noise (the difference method,
:func:`study.records.state_estimation.noise_std`) and the RMS misfit of the first candidate's
replays of the records in hand. Heading and positions are left out: they integrate the velocities,
so any small difference between two fits grows along a long manoeuvre. Why the misfit and not the
sensor noise alone: on real records the model's own error is far larger than the sensors' (and
velocities derived from positions are smooth), so two fits that differ by less than they already
miss cannot be told apart by one more record, however long. Assumption, labelled: a manoeuvre
separates the two when S is above :data:`SEPARATES` (their predictions differ by more than twice
what either misses the records by); each fit is taken as exact (its own identification spread is
left out).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

#: the manoeuvres offered (conf/maneuver/<name>.yaml), each run to both sides
MENU = ("zigzag_10_10", "zigzag_20_20", "zigzag_20_10", "zigzag_35_35", "turning_10", "turning_35")
#: approach speeds offered, as shares of the vessel's service speed
SPEEDS_U0 = (1.0, 0.6)
#: the channels compared, where the records hold them (velocities: see the module docstring)
CHANNELS = ("u", "v", "r")
#: S above which a record of the manoeuvre shows the two apart (assumption: twice the misfit)
SEPARATES = 2.0


def channel_noise(records: list) -> dict:
    """Each channel's white-noise sd over the records (the median of the records'
    difference-method estimates); channels whose estimate is zero (noise-free or quantised to
    nothing) are left out."""
    from study.records.state_estimation import noise_std

    out = {}
    for c in CHANNELS:
        est = [noise_std(df[c].to_numpy(float)) for df in records if c in df]
        s = float(np.median(est)) if est else 0.0
        if s > 0 and math.isfinite(s):
            out[c] = s
    return out


def separation(a: pd.DataFrame, b: pd.DataFrame, scale: dict) -> dict:
    """``S`` of two predictions of one manoeuvre (on ``a``'s time grid, ``b`` interpolated), the
    channel that carries most of it and the largest difference, each in units of ``scale`` (per
    channel)."""
    t = a["time"].to_numpy(float)
    tb = b["time"].to_numpy(float)
    keep = t <= tb[-1]
    t = t[keep]
    per, worst = {}, 0.0
    for c, s in scale.items():
        if c not in a or c not in b or len(t) < 2:
            continue
        z = (a[c].to_numpy(float)[keep] - np.interp(t, tb, b[c].to_numpy(float))) / s
        per[c] = float(np.mean(z ** 2))
        worst = max(worst, float(np.max(np.abs(z))))
    if not per:
        return {"S": float("nan"), "channel": None, "max": float("nan")}
    return {"S": float(np.sqrt(sum(per.values()))), "channel": max(per, key=per.get), "max": worst}


def misfit(problem, fit, records: list, infos=None) -> dict:
    """Each channel's RMS of the records minus ``fit``'s replays of them (on the replays' time
    grid), over the records whose replay does not diverge."""
    sq = {c: [] for c in CHANNELS}
    for i, df in enumerate(records):
        pred = problem.predict(fit, df, infos[i] if infos is not None else None)
        if pred is None:
            continue
        t = pred["time"].to_numpy(float)
        for c in CHANNELS:
            if c in df and c in pred:
                meas = np.interp(t, df["time"].to_numpy(float), df[c].to_numpy(float))
                sq[c].append((meas - pred[c].to_numpy(float)) ** 2)
    return {c: float(np.sqrt(np.mean(np.concatenate(v)))) for c, v in sq.items() if v}


def _maneuver(name: str, side: str) -> dict:
    from study.configuration.compose import read_config

    cfg = dict(read_config("maneuver", name))
    cfg["first"] = side
    cfg["name"] = f"{name}_{side}"
    return cfg


def _simulate(problem, fit, maneuver: dict, u0: float, psi0: float):
    from ..sim import simulate
    from .predictions import turn_vessel

    try:
        v, _ = turn_vessel(problem, fit, u0=u0)
        with np.errstate(all="ignore"):
            df = simulate(v, maneuver, u0=u0, psi0=psi0)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        return None
    cols = [c for c in CHANNELS if c in df]
    return df if np.all(np.isfinite(df[cols].to_numpy(float))) else None


def separating_maneuvers(problem, fits: dict, records: list, names: list, infos=None) -> dict:
    """Rank the menu's manoeuvres by how well a record of each would tell the two ``fits`` apart.

    Parameters
    ----------
    problem : study.identify.with_effects.EffectsProblem
    fits : {label: Fit}, two of them (e.g. the two candidate effects the doctor cannot tell apart)
    records, names : the measured records (DataFrames) and their names: the noise, the starting
    heading and the
        sampling interval come from them, and each is scored too (both fits replayed through it)
    infos : the records' RecordInfo (depth), in order; None: from the records

    Returns
    -------
    dict
        ``pair`` (the two labels), ``sigma`` (noise sd per channel), ``menu`` (rows best first:
        maneuver, side, speed_U0, D, channel, max_sd, or ``diverged`` naming the fit that does),
        ``recorded`` (the same for the records in hand), ``best`` (the top row) and ``text`` (one
        sentence for the report).
    """
    (la, fa), (lb, fb) = list(fits.items())[:2]
    noise, miss = channel_noise(records), misfit(problem, fa, records, infos)
    scale = {c: max(noise.get(c, 0.0), miss.get(c, 0.0)) for c in CHANNELS if c in noise or c in miss}
    scale = {c: v for c, v in scale.items() if v > 0 and math.isfinite(v)}
    psi0 = float(np.median([df["psi"].iloc[0] for df in records])) if records else 0.0
    menu = []
    for name in MENU:
        for side in ("starboard", "port"):
            man = _maneuver(name, side)
            for share in SPEEDS_U0:
                u0 = share * problem.U0
                pred = {la: _simulate(problem, fa, man, u0, psi0), lb: _simulate(problem, fb, man, u0, psi0)}
                menu.append({"maneuver": name, "side": side, "speed_U0": share, **_scored(pred, scale)})
    menu.sort(key=lambda r: -r["S"] if np.isfinite(r["S"]) else math.inf)
    recorded = []
    for i, (df, name) in enumerate(zip(records, names)):
        info = infos[i] if infos is not None else None
        pred = {la: problem.predict(fa, df, info), lb: problem.predict(fb, df, info)}
        recorded.append({"record": name, **_scored(pred, scale)})
    best = next((r for r in menu if np.isfinite(r["S"])), None)
    return {"pair": [la, lb], "scale": scale, "noise": noise, "misfit": miss, "menu": menu, "recorded": recorded,
            "best": best, "text": _sentence(la, lb, best, recorded)}


def _scored(pred: dict, scale: dict) -> dict:
    """:func:`separation` of the two predictions ``{label: frame or None}``, or which of them
    diverged."""
    (la, pa), (lb, pb) = pred.items()
    if pa is None or pb is None:
        return {"S": float("nan"), "channel": None, "max": float("nan"),
                "diverged": ", ".join(lab for lab, p in pred.items() if p is None)}
    return separation(pa, pb, scale)


def _sentence(la: str, lb: str, best: dict | None, recorded: list) -> str:
    if best is None:
        return f"no manoeuvre of the menu could be simulated with both {la} and {lb}: none is recommended"
    speed = "the service speed" if best["speed_U0"] == 1.0 else f"{100 * best['speed_U0']:.0f} % of the service speed"
    what = best["maneuver"].replace("zigzag_", "zigzag ").replace("turning_", "turning circle ").replace("_", "/")
    rec = [r["S"] for r in recorded if np.isfinite(r["S"])]
    have = f"; on the records in hand they lie {max(rec):.2g} apart at most" if rec else ""
    if rec and max(rec) >= best["S"]:
        verdict = ("the records in hand already show the two apart as far, so the doubt is not for want of a "
                   "manoeuvre: both miss the records about equally, so neither explanation alone is right (or a "
                   "third effect is missing)")
    elif best["S"] >= SEPARATES:
        verdict = "a record of it would tell them apart"
    else:
        verdict = (f"that is less than {SEPARATES:g} times the misfit: no manoeuvre of the menu would settle it, and "
                   "the records cannot tell the two explanations apart")
    return (f"to tell {la} from {lb}: a {what} to {best['side']} from {speed}, where their predictions lie furthest "
            f"apart, {best['S']:.2g} times what the fits already miss the records by (mostly in {best['channel']}){have}: "
            f"{verdict}")
