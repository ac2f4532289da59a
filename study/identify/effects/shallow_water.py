"""Finite water depth: larger hull derivatives, wake, thrust deduction and flow straightening.

The truth simulator's own corrections (``study.sim.effects.ShallowWater``): the linear hull
derivatives by one of the published formulas (``options.formulas``: Kijima et al. 1990; Ankudinov et
al. as ported in ShipYard), and for MMG vessels R'0, X'vv, X'vr, N'vvr, N'vrr, 1-t_P, 1-w_P and
gamma_R (Furukawa et al. 2016; Tang et al. 2020). The formula, and whether the MMG interaction
factors apply (a model of the same physics may correct the hull derivatives only), are chosen by the
data (the lowest training error).

Depth per record: a record's water depth (its ``depth`` column [m], or ``depth`` in its metadata:
metres, or ``{h_T: ...}``) gives its own h/T = depth / draft, in the fit and in the replay, so a
validation record at a depth no training record had is predicted at its own depth. When a training
record has no depth, one h/T common to the records without one is a nonlinear parameter; with depths
measured, one factor on every record's under-keel clearance h/T - 1 (``clearance_scale``, 1 = the
formula as published) is, so that corrections of another strength than the formulas' are still
matched. Free model coefficients are identified as their deep-water values: each record's column is
scaled by the formula's factor at its depth.
"""
from __future__ import annotations

from ...sim.effects import LINEAR_FORMULAS, ShallowWater as SimShallowWater
from .base import Effect


class ShallowWater(Effect):
    physics = "finite depth: larger hull derivatives, wake, thrust deduction and flow straightening"
    enters = "the deep-water coefficients corrected for each record's h/T (its depth, or a fitted h/T)"
    source = "Kijima et al. (1990); Ankudinov et al. (ShipYard port); Furukawa et al. (2016); Tang et al. (2020)"

    def __init__(self, name, params=None, formulas=("kijima_1990", "ankudinov"), deep_h_T=20.0,
                 clearance=(0.5, 2.0, (0.7, 1.0, 1.4)), interaction=(True, False)):
        super().__init__(name, params)
        self.interaction = tuple(bool(i) for i in interaction)
        self.clearance = (float(clearance[0]), float(clearance[1]), tuple(float(g) for g in clearance[2]))
        bad = [f for f in formulas if f not in LINEAR_FORMULAS]
        if bad:
            raise ValueError(f"shallow_water: unknown formula(s) {bad}; the simulator has {sorted(LINEAR_FORMULAS)}")
        self.formulas = tuple(formulas)
        self.deep_h_T = float(deep_h_T)  # above this h/T a record counts as deep (no correction)

    def applies(self, problem):
        if not problem.base.kind.LINEAR_DERIVATIVES:
            return f"vessel kind '{problem.base.kind_name}' has no hull derivatives for the depth factors to act on"
        return None

    def outer(self, problem):
        if problem.needs_fitted_depth():
            return super().outer(problem)
        # depths measured: how strongly they act is still the data's to say. Another model of the same physics
        # (a simulator or a basin with other shallow-water corrections) differs from every formula here by more
        # than the choice between them; an effective under-keel clearance h/T - 1 scaled by ``clearance_scale``
        # (1: the formula as published) lets the data correct its strength, the same factor on every record.
        lo, hi, grid = self.clearance
        return [("clearance_scale", lo, hi, tuple(grid))]

    def variants(self, problem):
        inter = self.interaction if problem.base.kind_name == "mmg" else (False,)
        return [{"formula": f, "interaction": i} for f in self.formulas for i in inter]

    def h_T(self, values, info):
        if info is not None and info.h_T is not None:
            return 1.0 + float(values.get("clearance_scale", 1.0)) * (info.h_T - 1.0)
        return values.get("h_T")

    def sim_effects(self, problem, values, info):
        h = self.h_T(values, info)
        if h is None or h >= self.deep_h_T:
            return []
        return [SimShallowWater(h_T=max(float(h), 1.06), formula=values.get("formula", self.formulas[0]),
                                interaction=bool(values.get("interaction", True)))]

    def describe(self, values):
        out = {"formula": values.get("formula")}
        if "interaction" in values:
            out["interaction_factors"] = "yes" if values["interaction"] else "no"
        for k in ("h_T", "clearance_scale"):
            if k in values:
                out[k] = values[k]
        return out

    def units(self, problem=None):
        return {"formula": "(chosen by the data)",
                "interaction_factors": "(MMG t_P, w_P, gamma_R, R_0...: chosen by the data)",
                "h_T": "- (water depth / draft)",
                "clearance_scale": "- (on each record's h/T - 1; 1: the formula as published)"}
