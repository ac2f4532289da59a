"""Steady true wind on the superstructure, Fossen's (2011, Sec. 8.1) coefficients and the vessel's
windage.

C_X = -c_x cos g, C_Y = c_y sin g, C_N = c_n sin 2g (g: apparent wind angle of attack): the compiled
integrator's own function (``study.sim.wind_forces``) gives a known force once the wind is known.
Without wind measurements the true wind's north and east components are the nonlinear parameters;
with measured true wind in the records (``wind_speed``, ``wind_dir``) the wind is known and one
factor per equation on its force (on c_x, c_y, c_n) is a linear unknown instead.
"""
from __future__ import annotations

import math

import numpy as np

from ...sim import wind_forces
from .base import Effect, polar

EQ = ("X", "Y", "N")


class Wind(Effect):
    physics = "steady true wind on the superstructure, C_X = -c_x cos g, C_Y = c_y sin g, C_N = c_n sin 2g"
    enters = "a known external force in the equations of motion (the integrator's own wind function)"
    source = "Fossen (2011) Sec. 8.1 (coefficients c_x 0.7, c_y 0.8, c_n 0.1; vessel windage areas)"
    needs = ("wind",)  # no candidate indoors (study.records.facility)

    def applies(self, problem):
        if not problem.vessel_cfg.get("windage"):
            return f"vessel '{problem.vessel_cfg.get('name')}' has no windage block (A_F, A_L, L_oa)"
        return None

    def outer(self, problem):
        return [] if problem.measured_wind else super().outer(problem)

    def linear(self, problem):
        if problem is not None and problem.measured_wind:
            return {f"wind_factor_{eq}": ("-", eq) for eq in EQ}
        return {}

    def known_forces(self, problem, nodes, values, vessel, info):
        if problem.measured_wind:
            return None
        n, e = values["wind_from_north"], values["wind_from_east"]
        return wind_forces(vessel, nodes["u"], nodes["v"], nodes["psi"], math.hypot(n, e), math.atan2(e, n))

    def linear_forces(self, problem, nodes, values, vessel, info):
        if not problem.measured_wind:
            return {}
        F = wind_forces(vessel, nodes["u"], nodes["v"], nodes["psi"], nodes["wind_speed"], nodes["wind_dir"])
        out = {}
        for k, eq in enumerate(EQ):
            col = np.zeros_like(F)
            col[:, k] = F[:, k]
            out[f"wind_factor_{eq}"] = col
        return out

    def vessel_changes(self, problem, values, info):
        if not problem.measured_wind:
            n, e = values["wind_from_north"], values["wind_from_east"]
            return {"wind_speed": math.hypot(n, e), "wind_dir": math.atan2(e, n)}
        if info is None or "wind_factor_X" not in values:  # rows: the measured wind is in the columns
            return {}
        df = info.data  # replay: a constant wind, the record's mean, its force scaled by the factors
        wn = float(np.mean(df["wind_speed"] * np.cos(df["wind_dir"])))
        we = float(np.mean(df["wind_speed"] * np.sin(df["wind_dir"])))
        env = dict(zip(problem.base.param_names, problem.base.params))
        return {"wind_speed": math.hypot(wn, we), "wind_dir": math.atan2(we, wn),
                "wind_cx": env["wind_cx"] * values["wind_factor_X"],
                "wind_cy": env["wind_cy"] * values["wind_factor_Y"],
                "wind_cn": env["wind_cn"] * values["wind_factor_N"]}

    def describe(self, values):
        if "wind_from_north" not in values:
            return dict(values)
        speed, direction = polar(values["wind_from_north"], values["wind_from_east"])
        return {"wind_speed": speed, "wind_direction_deg": direction}

    def units(self, problem=None):
        if problem is not None and problem.measured_wind:
            return {f"wind_factor_{eq}": "- (on the measured wind's force)" for eq in EQ}
        return {"wind_speed": "m/s", "wind_direction_deg": "deg, from, clockwise from north"}
