"""The catalogue of candidate effects the doctor can add to a model: physics, source, parameters, and how each
enters the identification (equation error) and the simulation.

Every effect is the same physics as the truth simulator's (``study.sim.effects``, the compiled integrator):
the doctor estimates its parameters, it does not re-implement it. How each enters the regression rows
``M (a_measured - a_known) = sum_i theta_i phi_i`` (``study.identify.regression``):

==================  =====================================================================================
current             the hydrodynamics act on water-relative velocities: u, v of the record minus the
                    current's components in body axes (Fossen 2011, Sec. 10.3, Property 8.1 makes this
                    exact for a uniform irrotational current). Parameters: the current's north and east
                    components [m/s] (reported as speed and direction towards). Nonlinear: outer search.
wind                a known external force added to a_known: Fossen's (2011, Sec. 8.1) coefficients and the
                    vessel's windage, the compiled integrator's own function. Parameters: the true wind
                    from north and east components [m/s] (reported as speed and direction FROM); with
                    measured true wind in the records (wind_speed, wind_dir), one linear parameter instead:
                    the factor on the wind force.
rudder_dynamics     the record's rudder angle is the COMMAND: the actual angle is the vessel's steering gear
                    (rate limit, first-order lag, dead time: the integrator's actuator) applied to it.
                    Parameters: lag [s] and dead time [s]. Nonlinear.
shallow_water       the deep-water coefficients corrected for h/T (Kijima et al. 1990 and the interaction
                    factors of study.sim.effects.ShallowWater). Parameter: h/T. Nonlinear (one-dimensional).
hull_nonlinear      the higher-order hull terms become free coefficients (those the model omits, else the
                    kind's nonlinear hull terms): extra regressor columns. Linear.
yaw_bias            a constant side force and yaw moment (propeller walk, asymmetry): a constant column in
                    the Y and N equations, non-dimensional as the MMG coefficients. Linear.
==================  =====================================================================================
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Param:
    """An outer (nonlinear) parameter: name, unit, bounds as fractions/multiples of a scale, start grid."""

    name: str
    unit: str
    lo: float
    hi: float
    grid: tuple


@dataclass(frozen=True)
class Effect:
    name: str
    physics: str
    enters: str
    source: str
    linear: bool
    params: tuple = field(default_factory=tuple)  # outer parameters (nonlinear effects)

    def param_text(self) -> str:
        if self.name == "hull_nonlinear":
            return "the omitted / nonlinear hull coefficients (linear)"
        if self.name == "yaw_bias":
            return "Y'_0, N'_0 (non-dimensional, linear)"
        return ", ".join(f"{p.name} [{p.unit}]" for p in self.params)


# Nonlinear hull terms per vessel kind: what ``hull_nonlinear`` frees when the model omits none
# (Yasukawa & Yoshimura 2015 eqs. 9-11; seed 000 eq. 2; mariner.m; seed 003 eq. 3).
NONLINEAR_HULL = {
    "mmg": ("Xvv", "Xvr", "Xrr", "Xvvvv", "Yvvv", "Yvvr", "Yvrr", "Yrrr", "Nvvv", "Nvvr", "Nvrr", "Nrrr"),
    "waterjet": ("Xvv", "Xrr", "Yvv", "Yvr", "Yrr", "Nrr", "Nvrr", "Nvvr"),
    "abkowitz": ("Xvv", "Xrr", "Xrv", "Yvvv", "Yvvr", "Nvvv", "Nvvr"),
    "auv": ("Xvv", "Xrr", "Xvr", "Yrrr", "Yrar", "Yvav", "Nrrr", "Nrar", "Nvav"),
}

CATALOGUE = {
    "current": Effect(
        "current", "uniform, irrotational current: the hull feels water-relative velocities, the track drifts",
        "u, v of the record minus the current in body axes (exact in relative velocities)",
        "Fossen (2011) Handbook of Marine Craft Hydrodynamics and Motion Control, Sec. 10.3", False,
        (Param("current_north", "m/s", -0.5, 0.5, (-0.2, 0.0, 0.2)),
         Param("current_east", "m/s", -0.5, 0.5, (-0.2, 0.0, 0.2)))),
    "wind": Effect(
        "wind", "steady true wind on the superstructure, C_X = -c_x cos g, C_Y = c_y sin g, C_N = c_n sin 2g",
        "a known external force in the equations of motion (the integrator's own wind function)",
        "Fossen (2011) Sec. 8.1 (coefficients c_x 0.7, c_y 0.8, c_n 0.1; vessel windage areas)", False,
        (Param("wind_from_north", "m/s", -8.0, 8.0, (-4.0, 0.0, 4.0)),
         Param("wind_from_east", "m/s", -8.0, 8.0, (-4.0, 0.0, 4.0)))),
    "rudder_dynamics": Effect(
        "rudder_dynamics", "a slow or late steering gear: first-order lag and dead time between command and rudder",
        "the recorded rudder angle taken as the command, passed through the steering gear",
        "IMO MSC.137(76) steering gear; ITTC 7.5-04-02-01 (record the actual rudder angle)", False,
        (Param("rudder_lag", "s", 0.0, 1.0, (0.05, 0.3)), Param("rudder_delay", "s", 0.0, 1.0, (0.0, 0.1)))),
    "shallow_water": Effect(
        "shallow_water", "finite depth: larger hull derivatives, wake, thrust deduction and flow straightening",
        "the deep-water coefficients corrected for h/T",
        "Kijima et al. (1990); Furukawa et al. (2016); Tang et al. (2020); seed 001", False,
        (Param("h_T", "-", 1.1, 8.0, (1.2, 1.5, 2.0, 3.0, 5.0)),)),
    "hull_nonlinear": Effect(
        "hull_nonlinear", "higher-order hull terms the model lacks or has wrong",
        "extra free coefficients in the regression", "Yasukawa & Yoshimura (2015) eqs. 9-11; Abkowitz (1964)",
        True),
    "yaw_bias": Effect(
        "yaw_bias", "constant side force and yaw moment: propeller walk, rudder zero offset, asymmetry",
        "a constant column in the Y and N equations", "(assumption: independent of speed within a record)", True),
}

#: the scale of each outer parameter's bounds: fractions of U0 (current), multiples of U0 (wind), of the
#: ship's time scale L/U0 (rudder: at least 5 s), or as given (h/T)
SCALES = {"current_north": "U0", "current_east": "U0", "wind_from_north": "U0", "wind_from_east": "U0",
          "rudder_lag": "T", "rudder_delay": "T", "h_T": "1"}


def scale_of(name: str, U0: float, L: float) -> float:
    kind = SCALES[name]
    if kind == "U0":
        return U0
    if kind == "T":
        return max(5.0, L / U0)
    return 1.0


def describe(values: dict) -> dict:
    """Outer parameters in a user's terms: current/wind as speed and direction, the rest as they are."""
    pairs = ("current_north", "current_east", "wind_from_north", "wind_from_east")
    out = {k: v for k, v in values.items() if k not in pairs}
    if "current_north" in values:
        n, e = values["current_north"], values["current_east"]
        out["current_speed"] = math.hypot(n, e)
        out["current_direction_deg"] = math.degrees(math.atan2(e, n)) % 360.0  # towards
    if "wind_from_north" in values:
        n, e = values["wind_from_north"], values["wind_from_east"]
        out["wind_speed"] = math.hypot(n, e)
        out["wind_direction_deg"] = math.degrees(math.atan2(e, n)) % 360.0  # from
    return out


def catalogue_rows() -> list:
    return [{"name": e.name, "physics": e.physics, "parameters": e.param_text(), "enters": e.enters,
             "source": e.source} for e in CATALOGUE.values()]
