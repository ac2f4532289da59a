"""A constant side force and yaw moment: propeller walk, a rudder zero offset, hull asymmetry.

Non-dimensional as the MMG coefficients (Y' = Y / (0.5 rho L d U0^2), N' = N / (0.5 rho L^2 d
U0^2)), so one value means the same on any vessel. Assumption (labelled): independent of speed
within a record.
"""
from __future__ import annotations

from .base import Effect, unit_forces


class YawBias(Effect):
    physics = "constant side force and yaw moment: propeller walk, rudder zero offset, asymmetry"
    enters = "a constant column in the Y and N equations"
    source = "(assumption: independent of speed within a record)"
    # a constant moment on a model is mostly its set-up's (a rudder zero offset; HSVA's KVLCC2 report says its
    # rudder was deflected from the geometric zero): left out of predictions for another facility or scale
    setup_effect = True

    def linear(self, problem):
        return {"yaw_bias_Y": ("- (Y / 0.5 rho L d U0^2)", "Y"), "yaw_bias_N": ("- (N / 0.5 rho L^2 d U0^2)", "N")}

    def linear_forces(self, problem, nodes, values, vessel, info):
        n = len(nodes["u"])
        return {"yaw_bias_Y": unit_forces(problem, n, "Y"), "yaw_bias_N": unit_forces(problem, n, "N")}

    def replay_force(self, problem, values, info):
        return (0.0, values.get("yaw_bias_Y", 0.0) * problem.scale[1], values.get("yaw_bias_N", 0.0) * problem.scale[2])
