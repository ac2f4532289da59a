"""A user's own candidate effect, written outside the package: a yaw moment that grows with n^2.

Physics (an assumption to test against the data, as a user would): an asymmetric propeller race on the hull or
rudder gives a yaw moment N = c n^2, c [N m s^2] unknown. It enters the regression rows as one linear unknown
(its force per unit c is n^2 in the yaw equation); in a replay the integrator takes a constant body force, so
the record's mean n^2 is used (exact for a record run at constant propeller speed, labelled as such).

Use: ``python -m study diagnose ... effect_path=docs/examples/effects`` with this folder on ``PYTHONPATH``.
"""
import numpy as np

from study.identify.effects import Effect


class YawFromPropeller(Effect):
    physics = "a yaw moment that grows with the propeller speed squared (asymmetric propeller race)"
    enters = "one linear column n^2 in the yaw equation"
    source = "(user's assumption, docs/examples/effects)"

    def linear(self, problem):
        return {"yaw_n2": ("N m s^2", "N")}

    def linear_forces(self, problem, nodes, values, vessel, info):
        col = np.zeros((len(nodes["n"]), 3))
        col[:, 2] = np.asarray(nodes["n"]) ** 2
        return {"yaw_n2": col}

    def replay_force(self, problem, values, info):
        n2 = float(np.mean(np.asarray(info.data["n"], float) ** 2))
        return (0.0, 0.0, values.get("yaw_n2", 0.0) * n2)
