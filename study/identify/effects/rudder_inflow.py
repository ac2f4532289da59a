"""The rudder's inflow of an MMG vessel, freed: the flow-straightening coefficients gamma_R (one for
beta_R < 0, one for beta_R > 0), their lever l_R and the wake ratio epsilon.

MMG rudder inflow (Yasukawa & Yoshimura 2015, eqs. 22-25): u_R = epsilon u_P sqrt(eta (1 + kappa
s)^2 + 1 - eta), v_R = U gamma_R (beta - l'_R r'), F_N = 0.5 rho A_R U_R^2 f_alpha sin(delta -
atan(v_R / u_R)); gamma_R takes one value for beta_R < 0 and another for beta_R > 0 (their Table 5
for KVLCC2: 0.395 and 0.640). None of them enters linearly: they are nonlinear parameters, searched
inside bounds (the YAML's), set in the vessel at each point of the search (the rows and the replay
use the simulator's own rudder model).

Which parameters (identifiability): F_N depends on (epsilon, gamma_R, f_alpha) only through f_alpha
epsilon^2 and gamma_R / epsilon (scaling epsilon and both gamma_R by c and f_alpha by 1/c^2 leaves
F_N unchanged), so f_alpha is kept at the vessel's value and epsilon carries the rudder's
effectiveness. kappa acts only through the propeller's loading (s), which a record at one propeller
speed hardly varies; it is kept at the vessel's value unless the YAML lists it (``params``). An
asymmetric gamma_R makes the rudder force, and so the residual yaw moment of a model with the
symmetric or wrong pair, different for rudder angles to port and to starboard (a V against the
rudder angle).
"""
from __future__ import annotations

from .base import Effect

#: the kind's parameter each outer parameter may be (the YAML's ``params`` names them)
INFLOW = ("gR_neg", "gR_pos", "lR", "eps", "kappa", "f_alpha")


class RudderInflow(Effect):
    physics = ("the rudder's inflow differs from the model's: flow straightening gamma_R (port and starboard), "
               "its lever l_R and the wake ratio epsilon")
    enters = "gamma_R (beta_R < 0, > 0), l_R, epsilon as nonlinear parameters of the MMG rudder inflow"
    source = "Yasukawa & Yoshimura (2015) J Mar Sci Technol 20, eqs. 22-25, Table 5"

    def __init__(self, name, params=None, **options):
        super().__init__(name, params, **options)
        bad = [p.name for p in self.params if p.name not in INFLOW]
        if bad:
            raise ValueError(f"effect '{name}': parameters {bad} are not MMG rudder-inflow parameters {INFLOW}")

    def applies(self, problem):
        if problem.base.kind_name != "mmg":
            return f"MMG rudder model only (vessel kind '{problem.base.kind_name}')"
        return None

    def vessel_changes(self, problem, values, info):
        return {p.name: values[p.name] for p in self.params if p.name in values}
