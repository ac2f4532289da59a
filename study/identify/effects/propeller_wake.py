"""Propeller-hull interaction of an MMG vessel: the wake fraction w_P0 and the thrust deduction t_P.

MMG propeller (Yasukawa & Yoshimura 2015, eqs. 12-16): X_P = (1 - t_P) rho n^2 D_P^4 K_T(J_P), J_P
from u (1 - w_P); w_P also sets the rudder's inflow (eqs. 21-24). t_P enters linearly (a free
coefficient); w_P0 does not (a nonlinear parameter, searched within 0.3 of the vessel's value). When
every training record measures the propeller thrust, w_P0 is not searched here: the thrust sets it
(``propeller_thrust``), and a w_P0 searched to fit the motions alone may contradict the thrust
measured (on HSVA's KVLCC2 records: 0.24 searched, 0.43 from the thrust with the vessel's
propeller).
"""
from __future__ import annotations

import numpy as np

from .base import Effect


class PropellerWake(Effect):
    physics = "propeller-hull interaction differs from the model's: wake fraction w_P0 and thrust deduction t_P"
    enters = "w_P0 as a nonlinear parameter (thrust and rudder inflow), t_P a free coefficient"
    source = "Yasukawa & Yoshimura (2015) J Mar Sci Technol 20, eqs. 12-16, 21-24"

    def applies(self, problem):
        if problem.base.kind_name != "mmg":
            return f"MMG propeller model only (vessel kind '{problem.base.kind_name}')"
        if problem.infos and all("thrust" in i.data.columns and np.isfinite(np.asarray(i.data["thrust"], float)).any()
                                 for i in problem.infos):
            return "the records measure the propeller thrust: w_P0 is identified from it (propeller_thrust)"
        return None

    def outer(self, problem):
        w = problem.base_param("wP0")
        return [("wP0", max(0.0, w - 0.3), min(0.9, w + 0.3), (max(0.0, w - 0.1), w, min(0.9, w + 0.1)))]

    def free_coefficients(self, problem):
        return {} if "tP" in problem.model_free else {"tP": "X"}

    def vessel_changes(self, problem, values, info):
        return {"wP0": values["wP0"]}

    def units(self, problem=None):
        out = {"wP0": "-"}
        if problem is not None:
            out.update({k: "-" for k in self.free_coefficients(problem)})
        return out
