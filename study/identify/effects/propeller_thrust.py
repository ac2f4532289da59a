"""The propeller of an MMG vessel identified from the records' measured thrust: the wake fraction
w_P0 by least squares on the thrust, the thrust deduction t_P then from the surge equation.

MMG propeller (Yasukawa & Yoshimura 2015, eqs. 13-16): T = rho n^2 D_P^4 K_T(J_P), K_T = k0 + k1 J_P
+ k2 J_P^2, J_P = u (1 - w_P) / (n D_P), 1 - w_P = (1 - w_P0) (1 + (1 - exp(-C1 |beta_P|)) (C2 -
1)), beta_P = beta - x'_P r'. With the thrust measured (a column ``thrust`` [N] in every training
record, as HSVA's free-running KVLCC2 records have), w_P0 is what makes the vessel's propeller (its
D_P, K_T polynomial, C1, C2) give the measured thrust at the measured u, v, r and n: a one-parameter
least-squares fit over every sample with the propeller running, before any force is identified (the
thrust identity of ITTC 7.5-02-03-01.4, applied sample by sample). It is then held, and t_P is a
free coefficient of the surge equation (X_P = (1 - t_P) T, linear in t_P). This is the propeller
model Alexandersson, Mao & Ringsberg (2022, Ocean Eng 266, 112940) regressed on HSVA's measured
thrust, reduced to its wake fraction.

What is not identified, and why: the K_T polynomial's own coefficients. With the propeller at one
speed (HSVA's runs: 10.23 rps throughout) J_P spans a narrow range, and k1, k2 are confounded with
w_P0 (K_T depends on (1 - w_P0) J only through k1 (1 - w_P0) and k2 (1 - w_P0)^2): the polynomial is
the vessel's (its open-water curve) and w_P0 absorbs the rest. Assumption labelled: the measured
thrust is the propeller's (not the shaft's with the rudder's reaction), and the records' ``n`` is
the propeller's speed in rps.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import optimize

from .base import Effect


def model_thrust(problem, df, wP0: float) -> np.ndarray:
    """The vessel's propeller thrust [N] at a record's u, v, r, n for wake fraction ``wP0`` (eqs.
    13-16)."""
    p = problem.base_param
    rho, L, D = p("rho"), p("L"), p("DP")
    u, v, r, n = (df[c].to_numpy(float) for c in ("u", "v", "r", "n"))
    U = np.hypot(u, v)
    with np.errstate(all="ignore"):
        beta = np.where(U > 1e-6, np.arctan2(-v, u), 0.0)
        rp = np.where(U > 1e-6, r * L / U, 0.0)
    beta_P = beta - p("xP") * rp
    C2 = np.where(beta_P > 0.0, p("C2_pos"), p("C2_neg"))
    uP = u * (1.0 - wP0) * (1.0 + (1.0 - np.exp(-p("C1") * np.abs(beta_P))) * (C2 - 1.0))
    nD = n * D
    kt = p("k0") * nD * nD + (p("k1") * nD + p("k2") * uP) * uP  # K_T n^2 D^2, finite at J -> 0
    return np.where(n > 0.0, rho * D * D * kt, 0.0)


class PropellerThrust(Effect):
    physics = "the propeller's wake fraction differs from the model's, identified from the measured thrust"
    enters = "w_P0 from the measured thrust (held in the rows and the replay), t_P a free coefficient"
    source = ("Yasukawa & Yoshimura (2015) J Mar Sci Technol 20, eqs. 12-16; Alexandersson, Mao & Ringsberg "
              "(2022) Ocean Eng 266, 112940")

    def __init__(self, name, params=None, wP0_bounds=(0.0, 0.9)):
        super().__init__(name, params)
        self.wP0_bounds = tuple(float(b) for b in wP0_bounds)

    def applies(self, problem):
        if problem.base.kind_name != "mmg":
            return f"MMG propeller model only (vessel kind '{problem.base.kind_name}')"
        miss = [i.name for i in problem.infos if "thrust" not in i.data.columns
                or not np.isfinite(np.asarray(i.data["thrust"], float)).any()]
        if miss:
            return f"needs the measured propeller thrust (a 'thrust' column): not in {', '.join(miss[:3])}"
        return None

    def thrust_fit(self, problem) -> dict:
        """w_P0 by least squares on the measured thrust of the training records (cached on the
        problem), with the thrust's RMS error at the vessel's w_P0 and at the fitted one."""
        cache = getattr(problem, "_thrust_fit", None)
        if cache is not None:
            return cache
        frames = []
        for i in problem.infos:
            df = i.data
            T = np.asarray(df["thrust"], float)
            ok = np.isfinite(T) & (np.asarray(df["n"], float) > 0)
            frames.append(df[ok])
        meas = np.concatenate([np.asarray(f["thrust"], float) for f in frames])

        def rms(w):
            pred = np.concatenate([model_thrust(problem, f, w) for f in frames])
            return float(np.sqrt(np.mean((pred - meas) ** 2)))

        lo, hi = self.wP0_bounds
        res = optimize.minimize_scalar(rms, bounds=(lo, hi), method="bounded", options={"xatol": 1e-5})
        w0 = problem.base_param("wP0")
        out = {"wP0": float(res.x), "thrust_rms_N": rms(float(res.x)), "thrust_rms_vessel_N": rms(w0),
               "thrust_mean_N": float(np.mean(meas)), "thrust_samples": int(len(meas))}
        problem._thrust_fit = out
        return out

    def free_coefficients(self, problem):
        return {} if "tP" in problem.model_free else {"tP": "X"}

    def variants(self, problem):
        # one variant: the thrust fit, so that w_P0 and the thrust's error are among the fit's reported values
        if self.applies(problem) is not None:
            return [{}]
        return [dict(self.thrust_fit(problem))]

    def vessel_changes(self, problem, values, info):
        w = values.get("wP0")
        return {"wP0": float(w if w is not None else self.thrust_fit(problem)["wP0"])}

    def units(self, problem=None):
        out = {"wP0": "-", "thrust_rms_N": "N", "thrust_rms_vessel_N": "N", "thrust_mean_N": "N",
               "thrust_samples": "-"}
        if problem is not None:
            out.update({k: "-" for k in self.free_coefficients(problem)})
        return out
