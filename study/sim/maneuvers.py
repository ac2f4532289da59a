"""Manoeuvres: zigzags (either side first, multi-stage sequences), turning circles with pull-out,
random rudder.

A manoeuvre config (``conf/maneuver/<name>.yaml``) becomes a :class:`Maneuver`, which encodes itself
for the compiled integrator as a controller programme (closed loop on the simulated heading: zigzag
switches and the pull-out depend on the ship's own response) plus an open-loop command series.
Definitions follow IMO MSC.137(76) and its explanatory notes MSC/Circ.1053, and ITTC Recommended
Procedure 7.5-04-02-01.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from study.configuration.compose import read_config

# Controller codes of the compiled integrator's programme (``study.sim.core`` runs it): 0 open loop (command
# series), 1 zigzag programme, 2 turning circle with pull-out. Defined here, where programmes are written.
CTRL_OPEN, CTRL_ZIGZAG, CTRL_TURN = 0, 1, 2

SIDES = {"starboard": 1.0, "port": -1.0}


def open_loop_ctrl() -> np.ndarray:
    return np.array([CTRL_OPEN, 0.0, 1.0, 0.0, 0.0])


@dataclass
class Maneuver:
    """A manoeuvre definition; see the module docstring and ``conf/maneuver/``."""

    name: str
    type: str
    first: str = "starboard"
    t_start: float = 10.0
    stages: list = field(default_factory=list)  # zigzag: [{amp_deg, switch_deg, switches}]
    amp_deg: float = 35.0  # turning / random amplitude
    pullout_deg: float = 540.0
    hold_L: tuple = (0.5, 2.0)
    duration: float | None = None
    duration_L: float | None = None

    def __post_init__(self):
        if self.type not in ("zigzag", "turning", "random"):
            raise ValueError(f"maneuver '{self.name}': unknown type '{self.type}' "
                             "(expected zigzag, turning or random)")
        if self.first not in SIDES:
            raise ValueError(f"maneuver '{self.name}': first='{self.first}', expected 'starboard' or 'port'")
        if self.type == "zigzag" and not self.stages:
            raise ValueError(f"maneuver '{self.name}': a zigzag needs at least one stage")
        if self.duration is None and self.duration_L is None:
            raise ValueError(f"maneuver '{self.name}': give 'duration' (s) or 'duration_L' (Lpp/U0 units)")

    def duration_for(self, vessel) -> float:
        if self.duration is not None:
            return float(self.duration)
        return float(self.duration_L) * vessel.L / vessel.U0

    def encode(self, vessel, dt: float, nsteps: int, seed: int = 0):
        """Return (ctrl programme, command series of length nsteps + 1) for the integrator."""
        sign = SIDES[self.first]
        cmd = np.zeros(nsteps + 1)
        if self.type == "zigzag":
            ctrl = [CTRL_ZIGZAG, self.t_start, sign, 0.0, len(self.stages)]
            for st in self.stages:
                ctrl += [math.radians(st["amp_deg"]), math.radians(st["switch_deg"]), int(st["switches"])]
        elif self.type == "turning":
            ctrl = [CTRL_TURN, self.t_start, sign, math.radians(self.pullout_deg), 1,
                    math.radians(self.amp_deg), 0.0, 0.0]
        else:
            ctrl = list(open_loop_ctrl())
            rng = np.random.default_rng(seed)
            t = np.arange(nsteps + 1) * dt
            tc = self.t_start
            lo, hi = (float(h) * vessel.L / vessel.U0 for h in self.hold_L)
            amp = math.radians(self.amp_deg)
            while tc < t[-1]:
                hold = rng.uniform(lo, hi)
                cmd[(t >= tc) & (t < tc + hold)] = rng.uniform(-amp, amp)
                tc += hold
        return np.asarray(ctrl, dtype=np.float64), cmd


def get_maneuver(spec) -> Maneuver:
    """A Maneuver from a config name, a config dict, or a Maneuver."""
    if isinstance(spec, Maneuver):
        return spec
    if isinstance(spec, str):
        spec = read_config("maneuver", spec)
    spec = dict(spec)
    if "hold_L" in spec:
        spec["hold_L"] = tuple(spec["hold_L"])
    if "stages" in spec:
        spec["stages"] = [dict(s) for s in spec["stages"]]
    return Maneuver(**spec)
