"""A uniform, irrotational current: the hull feels water-relative velocities, the track drifts.

Fossen, T.I. (2011) Handbook of Marine Craft Hydrodynamics and Motion Control, Sec. 10.3 (Property
8.1 makes the equations of motion in relative velocity exact for a constant irrotational current).
The rows take the record's u, v (over ground) minus the current in body axes; the replay starts from
the water-relative state.
"""
from __future__ import annotations

import math

import numpy as np

from .base import Effect, polar


class Current(Effect):
    physics = "uniform, irrotational current: the hull feels water-relative velocities, the track drifts"
    enters = "u, v of the record minus the current in body axes (exact in relative velocities)"
    source = "Fossen (2011) Handbook of Marine Craft Hydrodynamics and Motion Control, Sec. 10.3"
    needs = ("current",)  # no candidate in still water (study.records.facility)

    def transform(self, problem, t, data, values, vessel, info):
        n, e, psi = values["current_north"], values["current_east"], data["psi"]
        data["u"] = data["u"] - (n * np.cos(psi) + e * np.sin(psi))
        data["v"] = data["v"] - (-n * np.sin(psi) + e * np.cos(psi))
        return ["u", "v"]

    def vessel_changes(self, problem, values, info):
        n, e = values["current_north"], values["current_east"]
        return {"current_speed": math.hypot(n, e), "current_dir": math.atan2(e, n)}

    def initial_state(self, problem, values, state):
        n, e, psi = values["current_north"], values["current_east"], state["psi"]
        state["u"] -= n * math.cos(psi) + e * math.sin(psi)
        state["v"] -= -n * math.sin(psi) + e * math.cos(psi)

    def describe(self, values):
        speed, direction = polar(values["current_north"], values["current_east"])
        return {"current_speed": speed, "current_direction_deg": direction}

    def units(self, problem=None):
        return {"current_speed": "m/s", "current_direction_deg": "deg, towards, clockwise from north"}
