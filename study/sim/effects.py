"""Environmental and actuator effects of the truth simulator, as separate, composable pieces.

Each effect is a small dataclass with ``apply(vessel_cfg, env)``: it either transforms the vessel's
coefficients (``shallow_water``) or sets entries of the environment/actuator parameter block that
the compiled integrator reads (``current``, ``wind``, ``rudder_dynamics``, ``yaw_bias``). The model
doctor uses the same classes as its candidate effects.

Sources are given per effect; formulas are in ``../shared/reference/vessels.md`` as gathered for
this project.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from .core import ENV_NAMES


class NotApplicable(ValueError):
    """An effect that cannot act on this vessel (a study records the run as skipped, with this
    message)."""


def default_env(vessel_cfg: dict) -> dict:
    """Environment/actuator block with no environment and the vessel's own steering gear."""
    act = vessel_cfg.get("actuator", {}) or {}
    wind = vessel_cfg.get("windage", {}) or {}
    L = float(vessel_cfg["particulars"]["Lpp"])
    env = {k: 0.0 for k in ENV_NAMES}
    env.update(
        # Fossen (2011) Sec. 8.1: c_x in 0.50-0.90, c_y in 0.70-0.95, c_n in 0.05-0.20; mid values taken.
        wind_cx=0.7, wind_cy=0.8, wind_cn=0.10,
        wind_AF=float(wind.get("A_F", 0.0)), wind_AL=float(wind.get("A_L", 0.0)),
        wind_Loa=float(wind.get("L_oa", L)),
        rho_air=1.225,  # ISA sea level
        rudder_rate=math.radians(float(act.get("rudder_rate_deg", 0.0))),
        rudder_lag=float(act.get("rudder_lag", 0.0)),
        rudder_delay=float(act.get("rudder_delay", 0.0)),
        delta_max=math.radians(float(act.get("delta_max_deg", 35.0))),
    )
    return env


@dataclass
class Current:
    """Uniform, irrotational current: hydrodynamics on water-relative velocities, drift in the
    kinematics.

    Fossen, T.I. (2011) Handbook of Marine Craft Hydrodynamics and Motion Control, Sec. 10.3
    (Property 8.1 makes the equations of motion in relative velocity exact for a constant
    irrotational current).

    speed : m/s; direction_deg : direction the water flows TOWARDS, clockwise from north.
    """

    speed: float = 0.0
    direction_deg: float = 0.0
    name: str = "current"

    def apply(self, vessel_cfg: dict, env: dict) -> None:
        env["current_speed"] = float(self.speed)
        env["current_dir"] = math.radians(float(self.direction_deg))


@dataclass
class Wind:
    """Uniform steady wind with Fossen's (2011, Sec. 8.1) simplified force coefficients.

    C_X = -c_x cos(g), C_Y = c_y sin(g), C_N = c_n sin(2 g), g the apparent wind angle of attack
    (0 = wind from ahead); areas from the vessel's ``windage`` block.
    speed : m/s (true); direction_deg : where the wind comes FROM, clockwise from north.
    """

    speed: float = 0.0
    direction_deg: float = 0.0
    cx: float | None = None
    cy: float | None = None
    cn: float | None = None
    name: str = "wind"

    def apply(self, vessel_cfg: dict, env: dict) -> None:
        if not vessel_cfg.get("windage"):
            raise ValueError(f"vessel '{vessel_cfg.get('name')}' has no 'windage' block (A_F, A_L, L_oa): "
                             "the wind effect needs its projected areas")
        env["wind_speed"] = float(self.speed)
        env["wind_dir"] = math.radians(float(self.direction_deg))
        for key, val in (("wind_cx", self.cx), ("wind_cy", self.cy), ("wind_cn", self.cn)):
            if val is not None:
                env[key] = float(val)


@dataclass
class RudderDynamics:
    """Steering gear: rate limit, first-order lag, dead time (any may be None = keep the vessel's
    value).

    The rate limit follows the vessel's steering gear (IMO MSC.137(76): 35 deg to 30 deg the other
    side in 28 s, i.e. 2.32 deg/s, at full scale); lag and delay model a slow or late servo (ITTC
    7.5-04-02-01 asks for the rudder to be recorded because it is not the command).
    """

    rate_deg: float | None = None
    lag: float | None = None
    delay: float | None = None
    name: str = "rudder_dynamics"

    def apply(self, vessel_cfg: dict, env: dict) -> None:
        if self.rate_deg is not None:
            env["rudder_rate"] = math.radians(float(self.rate_deg))
        if self.lag is not None:
            env["rudder_lag"] = float(self.lag)
        if self.delay is not None:
            env["rudder_delay"] = float(self.delay)


@dataclass
class YawBias:
    """Constant body-fixed side force and yaw moment (propeller walk, hull or rudder asymmetry).

    Given non-dimensionally (MMG convention: Y' = Y/(0.5 rho L d U0^2), N' = N/(0.5 rho L^2 d U0^2))
    so that one value means the same on any vessel. Assumption: the bias does not change with speed
    within a record.
    """

    Y: float = 0.0
    N: float = 0.0
    name: str = "yaw_bias"

    def apply(self, vessel_cfg: dict, env: dict) -> None:
        p = vessel_cfg["particulars"]
        U0 = float(vessel_cfg["operation"]["U0"])
        q = 0.5 * float(p["rho"]) * float(p["Lpp"]) * float(p["d"]) * U0 ** 2
        env["ext_Y"] = float(self.Y) * q
        env["ext_N"] = float(self.N) * q * float(p["Lpp"])


# ---------------------------------------------------------------------------------------------------------
# Shallow water: factors on the deep-water coefficients, H = d/h.
def _kijima_1990(h_T: float, vessel_cfg: dict) -> dict:
    """Kijima, K., Nakiri, Y., Tsutsui, Y., Matsunaga, M. (1990) Prediction method of ship
    manoeuvrability in deep and shallow waters. MARSIM & ICSM 90, Tokyo; as given by Maimun et
    al. (2011), Ocean Eng 38. Linear hull derivatives Y'v, Y'r, N'v, N'r."""
    p = vessel_cfg["particulars"]
    H = 1.0 / h_T
    B, d, L, Cb = float(p["B"]), float(p["d"]), float(p["Lpp"]), float(p["Cb"])
    q = Cb * B / d

    def f(n):
        return (1.0 - H) ** (-n) - H

    A1 = -5.5 * q * q + 26.0 * q - 31.5
    A2 = 37.0 * q * q - 185.0 * q + 230.0
    A3 = -38.0 * q * q + 197.0 * q - 250.0
    return {
        "Yv": f(0.40 * q), "Nv": f(0.425 * q), "Nr": f(-7.14 * (2.0 * d / L) + 1.5),
        "Yr": 1.0 + A1 * H + A2 * H * H + A3 * H ** 3,
    }


def _ankudinov(h_T: float, vessel_cfg: dict) -> dict:
    """Ankudinov et al. shallow-water factors as given in a public port of the DMI/FORCE ShipYard
    code (collected in ../shared/reference/vessels.md; not checked against the original report).
    Linear derivatives and added mass."""
    p = vessel_cfg["particulars"]
    F = h_T - 1.0
    B, d, L, Cb = float(p["B"]), float(p["d"]), float(p["Lpp"]), float(p["Cb"])
    K0 = 1.0 + 0.0775 / F ** 2 - 0.011 / F ** 3 + 0.000068 / F ** 5
    K1 = -0.0643 / F + 0.0724 / F ** 2 - 0.0113 / F ** 3 + 0.0000767 / F ** 5
    K2 = 0.137 * (d / B) / F if B / d > 4.0 else 0.0342 / F
    B1T = Cb * (B / d) * (1.0 + B / L) ** 2
    fNv = K0 + K1 * B1T + K2 * B1T ** 2
    return {
        "Nv": fNv, "Yv": 1.5 * fNv - 0.5,
        "Yr": K0 + 0.4 * K1 * B1T + (24.0 / 105.0) * K2 * B1T ** 2,
        "Nr": K0 + 0.5 * K1 * B1T + (1.0 / 3.0) * K2 * B1T ** 2,
        "added_mass": K0 + (2.0 / 3.0) * K1 * B1T + (8.0 / 15.0) * K2 * B1T ** 2,
    }


LINEAR_FORMULAS = {"kijima_1990": _kijima_1990, "ankudinov": _ankudinov}


@dataclass
class ShallowWater:
    """Water depth as h/T: corrects hull derivatives and interaction coefficients.

    ``formula`` picks the linear-derivative correction (default ``kijima_1990``; ``ankudinov``
    selectable). For MMG vessels the remaining coefficients follow Furukawa et al. (2016, MASHCON 4)
    and Tang et al. (2020, Ocean Eng 195:106679): R'0, X'vv, X'vr, N'vvr, N'vrr, 1-t_P, 1-w_P,
    gamma_R (``interaction=True``). Added mass: Ankudinov's factor when ``formula='ankudinov'``,
    otherwise unchanged (assumption, labelled: the Kijima set gives no added-mass factor). ``h_T =
    None`` or ``inf`` is deep water (no change). A kind without hull derivatives
    (``LINEAR_DERIVATIVES`` empty: ``nomoto``) raises a ValueError in shallow water; the depth
    changes K and T of a real ship, and a Nomoto truth would need them from elsewhere. Xu & Guedes
    Soares classes h/T > 3 deep, 1.5-3 medium, 1.2-1.5 shallow, < 1.2 very shallow.
    """

    h_T: float | None = None
    formula: str = "kijima_1990"
    interaction: bool = True
    name: str = "shallow_water"

    def factors(self, vessel_cfg: dict) -> dict:
        if self.h_T is None or not math.isfinite(float(self.h_T)):
            return {}
        h_T = float(self.h_T)
        if h_T <= 1.05:
            raise ValueError(f"shallow_water: h/T = {h_T} is below 1.05, outside every formula's range")
        if self.formula not in LINEAR_FORMULAS:
            raise ValueError(f"shallow_water: unknown formula '{self.formula}', expected one of "
                             f"{sorted(LINEAR_FORMULAS)}")
        return LINEAR_FORMULAS[self.formula](h_T, vessel_cfg)

    def apply(self, vessel_cfg: dict, env: dict) -> None:
        fac = self.factors(vessel_cfg)
        if not fac:
            return
        from .kinds import get_kind

        kind = get_kind(vessel_cfg["kind"])
        H = 1.0 / float(self.h_T)
        sec, names = kind.COEFF_SECTION, kind.LINEAR_DERIVATIVES
        if not names:  # e.g. a Nomoto model: no hull derivatives (as Wind raises without a windage block)
            raise NotApplicable(f"shallow_water: vessel '{vessel_cfg.get('name')}' is of kind '{vessel_cfg['kind']}', "
                             "which has no hull derivatives for the depth factors to act on (its "
                             "LINEAR_DERIVATIVES is empty); use deep water (h_T = null) or a hull-based kind")
        for generic, key in names.items():
            vessel_cfg[sec][key] = float(vessel_cfg[sec][key]) * fac[generic]
        if "added_mass" in fac:
            for key in getattr(kind, "ADDED_MASS_KEYS", ()):
                vessel_cfg[sec][key] = float(vessel_cfg[sec][key]) * fac["added_mass"]
        if self.interaction and vessel_cfg["kind"] == "mmg":
            h = vessel_cfg["hull"]
            Cb = float(vessel_cfg["particulars"]["Cb"])
            h["R_0"] = float(h["R_0"]) * (1.0 + 0.388 * H ** 2)
            h["X_vv"] = float(h["X_vv"]) * (1.0 + 27.7 * H ** 2 - 70.8 * H ** 4)
            h["X_vr"] = float(h["X_vr"]) * (1.0 + 1.3 * H ** 2)
            h["N_vvr"] = float(h["N_vvr"]) * (1.0 + 6.0 * H ** 2.5)
            h["N_vrr"] = float(h["N_vrr"]) * (1.0 + 6.0 * H ** 2.5)
            pr = vessel_cfg["propeller"]
            pr["t_P"] = 1.0 - (1.0 - float(pr["t_P"])) / (1.0 - 0.2 * H + 0.7295 * H ** 2)
            pr["w_P0"] = 1.0 - (1.0 - float(pr["w_P0"])) * math.cos(1.4 * Cb * H)
            rd = vessel_cfg["rudder"]
            g = 1.0 + 0.0161 * H + 4.4222 * H ** 2 - 4.9825 * H ** 3
            rd["gamma_R_neg"] = float(rd["gamma_R_neg"]) * g
            rd["gamma_R_pos"] = float(rd["gamma_R_pos"]) * g


EFFECTS = {"current": Current, "wind": Wind, "rudder_dynamics": RudderDynamics,
           "shallow_water": ShallowWater, "yaw_bias": YawBias}


def make_effect(name: str, **params):
    """Build an effect from its catalogue name and parameters (as in a Hydra config)."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect '{name}'; known effects: {sorted(EFFECTS)}")
    return EFFECTS[name](**params)


def apply_effects(vessel_cfg: dict, effects) -> tuple[dict, dict]:
    """Return (modified copy of the vessel config, environment block) with the effects applied in
    order."""
    vcfg = copy.deepcopy(vessel_cfg)
    env = default_env(vcfg)
    for eff in effects:
        eff.apply(vcfg, env)
    return vcfg, env


def env_vector(env: dict) -> np.ndarray:
    return np.array([float(env[k]) for k in ENV_NAMES])
