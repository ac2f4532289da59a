"""A slow or late steering gear: first-order lag and dead time between the command and the rudder.

IMO MSC.137(76) (steering gear); ITTC 7.5-04-02-01 asks for the actual rudder angle to be recorded
because it is not the command. With this effect the record's rudder column is taken as the COMMAND:
the rows use the angle the vessel's steering gear (rate limit, lag, dead time: the integrator's own
actuator) makes of it.
"""
from __future__ import annotations

from .base import Effect


class RudderDynamics(Effect):
    physics = "a slow or late steering gear: first-order lag and dead time between command and rudder"
    enters = "the recorded rudder angle taken as the command, passed through the steering gear"
    source = "IMO MSC.137(76) steering gear; ITTC 7.5-04-02-01 (record the actual rudder angle)"
    rudder_is_command = True

    def transform(self, problem, t, data, values, vessel, info):
        data["delta"] = problem.actual_rudder(vessel, t, data["delta"], data["n"])
        return ["delta"]

    def vessel_changes(self, problem, values, info):
        return {"rudder_lag": values["rudder_lag"], "rudder_delay": values["rudder_delay"]}
