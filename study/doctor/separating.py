"""Which manoeuvre would tell two explanations apart.

When the doctor cannot tell two candidate effects apart (or names one on weak evidence), each candidate's fit is
simulated through a menu of standard manoeuvres -- the 10/10, 20/20, 20/10 and 35/35 zigzags and the 10 and 35
deg turning circles, each to starboard and to port, from a steady approach at the service speed and at 60 % of it
-- from the heading the records start at, and the manoeuvres are ranked by how far the two predictions differ
against the records' measurement noise. The same score is computed for the records already run (each fit
replayed through them), so the recommendation says how much more a new record would tell than the ones in hand.

The score of a manoeuvre is the expected log-likelihood ratio a record of it would give for the right
explanation over the other (the Kullback-Leibler divergence of two Gaussian records with the same noise):

    D = 1/2 sum_t sum_c ((a_c(t) - b_c(t)) / sigma_c)^2,

summed over the samples at the records' sampling interval and over the velocities both simulate and the records
hold (u, v, r). Heading and positions are left out: they integrate the velocities, so any small difference
between two fits grows along a long manoeuvre and would swamp D whether or not it is the effects' own. Assumptions,
labelled: the measurement noise is white, of the size the training
records show (each channel's sigma by the difference method, :func:`study.state_estimation.noise_std`), and each
fit is taken as exact (its own identification spread is left out, so D is the evidence about the two
explanations, not about their parameters). D of about 3 or more favours the right one by a likelihood ratio of
20 on average; a record whose D is below 1 cannot tell them apart.
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
#: D at which a record favours the right explanation by a likelihood ratio of about 20 (e^3)
DECISIVE = 3.0


def channel_noise(records: list) -> dict:
    """Each channel's white-noise sd over the records (the median of the records' difference-method estimates);
    channels whose estimate is zero (noise-free or quantised to nothing) are left out."""
    from ..state_estimation import noise_std

    out = {}
    for c in CHANNELS:
        est = [noise_std(df[c].to_numpy(float)) for df in records if c in df]
        s = float(np.median(est)) if est else 0.0
        if s > 0 and math.isfinite(s):
            out[c] = s
    return out


def divergence(a: pd.DataFrame, b: pd.DataFrame, sigma: dict, dt_record: float) -> dict:
    """``D`` of two predictions of one manoeuvre (on ``a``'s time grid, ``b`` interpolated), with the channel
    that carries most of it and the largest difference in noise sd."""
    t = a["time"].to_numpy(float)
    tb = b["time"].to_numpy(float)
    keep = t <= tb[-1]
    t = t[keep]
    if len(t) < 2:
        return {"D": float("nan"), "channel": None, "max_sd": float("nan")}
    step = float(np.median(np.diff(t)))
    per, worst = {}, 0.0
    for c, s in sigma.items():
        if c not in a or c not in b:
            continue
        xa = a[c].to_numpy(float)[keep]
        xb = np.interp(t, tb, b[c].to_numpy(float))
        z = (xa - xb) / s
        per[c] = 0.5 * float(np.sum(z ** 2)) * step / dt_record
        worst = max(worst, float(np.max(np.abs(z))))
    if not per:
        return {"D": float("nan"), "channel": None, "max_sd": float("nan")}
    return {"D": float(sum(per.values())), "channel": max(per, key=per.get), "max_sd": worst}


def _maneuver(name: str, side: str) -> dict:
    from ..config import read_config

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
    records, names : the measured records (DataFrames) and their names: the noise, the starting heading and the
        sampling interval come from them, and each is scored too (both fits replayed through it)
    infos : the records' RecordInfo (depth), in order; None: from the records

    Returns
    -------
    dict
        ``pair`` (the two labels), ``sigma`` (noise sd per channel), ``menu`` (rows best first: maneuver, side,
        speed_U0, D, channel, max_sd, or ``diverged`` naming the fit that does), ``recorded`` (the same for the
        records in hand), ``best`` (the top row) and ``text`` (one sentence for the report).
    """
    (la, fa), (lb, fb) = list(fits.items())[:2]
    sigma = channel_noise(records)
    dts = [float(np.median(np.diff(df["time"].to_numpy(float)))) for df in records if len(df) > 1]
    dt_rec = float(np.median(dts)) if dts else 0.1
    psi0 = float(np.median([df["psi"].iloc[0] for df in records])) if records else 0.0
    menu = []
    for name in MENU:
        for side in ("starboard", "port"):
            man = _maneuver(name, side)
            for share in SPEEDS_U0:
                u0 = share * problem.U0
                pa, pb = _simulate(problem, fa, man, u0, psi0), _simulate(problem, fb, man, u0, psi0)
                row = {"maneuver": name, "side": side, "speed_U0": share}
                if pa is None or pb is None:
                    row.update(D=float("nan"), channel=None, max_sd=float("nan"),
                               diverged=", ".join(lab for lab, p in ((la, pa), (lb, pb)) if p is None))
                else:
                    row.update(divergence(pa, pb, sigma, dt_rec))
                menu.append(row)
    menu.sort(key=lambda r: -r["D"] if np.isfinite(r["D"]) else math.inf)
    recorded = []
    for i, (df, name) in enumerate(zip(records, names)):
        info = infos[i] if infos is not None else None
        pa, pb = problem.predict(fa, df, info), problem.predict(fb, df, info)
        row = {"record": name}
        if pa is None or pb is None:
            row.update(D=float("nan"), channel=None, max_sd=float("nan"),
                       diverged=", ".join(lab for lab, p in ((la, pa), (lb, pb)) if p is None))
        else:
            row.update(divergence(pa, pb, sigma, dt_rec))
        recorded.append(row)
    best = next((r for r in menu if np.isfinite(r["D"])), None)
    return {"pair": [la, lb], "sigma": sigma, "menu": menu, "recorded": recorded, "best": best,
            "text": _sentence(la, lb, best, recorded)}


def _sentence(la: str, lb: str, best: dict | None, recorded: list) -> str:
    if best is None:
        return f"no manoeuvre of the menu could be simulated with both {la} and {lb}: none is recommended"
    speed = "the service speed" if best["speed_U0"] == 1.0 else f"{100 * best['speed_U0']:.0f} % of the service speed"
    what = best["maneuver"].replace("zigzag_", "zigzag ").replace("turning_", "turning circle ").replace("_", "/")
    rec = [r["D"] for r in recorded if np.isfinite(r["D"])]
    have = (f"; the records in hand give D = {max(rec):.2g} at most" if rec else "")
    verdict = ("a record of it would settle it" if best["D"] >= DECISIVE else
               "even that would hardly settle it: more than one such record, or a larger manoeuvre, is needed")
    return (f"to tell {la} from {lb}: a {what} to {best['side']} from {speed}, where their predictions differ most "
            f"against the records' noise (expected log-likelihood ratio D = {best['D']:.3g}, mostly in {best['channel']}, "
            f"up to {best['max_sd']:.2g} noise sd){have}: {verdict}")
