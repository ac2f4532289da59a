"""Hull-rudder interaction of an MMG vessel, freed: t_R (surge), a_H (sway and yaw) and x_R (yaw).

MMG rudder forces (Yasukawa & Yoshimura 2015, eqs. 17-25): X_R = -(1 - t_R) F_N sin delta, Y_R = -(1
+ a_H) F_N cos delta, N_R = -(x_R + a_H x_H) F_N cos delta. Each of t_R, a_H, x_R enters linearly,
so they are free coefficients read off the compiled equations. This is what real free-running data
point to when the yaw residual grows with the rudder angle while the sway residual falls with it
(HSVA's KVLCC2 records): the rudder force is shared between sway and yaw differently from the
model's.
"""
from __future__ import annotations

from .base import Effect


class RudderInteraction(Effect):
    physics = "hull-rudder interaction differs from the model's: t_R, a_H and the rudder's effective position x_R"
    enters = "t_R, a_H, x_R as free coefficients (linear in the MMG rudder forces)"
    source = "Yasukawa & Yoshimura (2015) J Mar Sci Technol 20, eqs. 17-25"

    def __init__(self, name, params=None, coefficients=None):
        super().__init__(name, params)
        self.coefficients = dict(coefficients or {"tR": "X", "aH": "Y", "xR": "N"})

    def applies(self, problem):
        if problem.base.kind_name != "mmg":
            return f"MMG rudder model only (vessel kind '{problem.base.kind_name}')"
        return None

    def free_coefficients(self, problem):
        return {c: eq for c, eq in self.coefficients.items() if c not in problem.model_free}
