"""A study run's identification of a force model with ``model.effects`` (``study.pipeline``)."""
from __future__ import annotations

import math

from .problem import EffectsProblem


def identify_in_study(base, model_cfg: dict, records, structure_cfg, truth) -> dict:
    """A study run's identification of a force model with ``model.effects`` (``python -m study
    model.effects=[current]``): the doctor's variable projection, its outer parameters refined on the training
    replays. Returns ``estimates`` (the vessel's coefficients), ``params`` (rows for the table: coefficients and
    the effects' parameters, with the truth from the truth vessel), ``metrics`` and ``vessel`` (the identified
    model with its own steering gear, for closed-loop validation)."""
    effects = tuple(model_cfg.get("effects") or [])
    pb = EffectsProblem(base.cfg, model_cfg, records, structure_cfg)
    fit = pb.fit(effects, refine=True)
    env = dict(zip(truth.param_names, truth.params))
    q = pb.scale
    truth_eff = {"current_speed": env["current_speed"], "current_direction_deg": math.degrees(env["current_dir"]) % 360,
                 "wind_speed": env["wind_speed"], "wind_direction_deg": math.degrees(env["wind_dir"]) % 360,
                 "rudder_lag": env["rudder_lag"], "rudder_delay": env["rudder_delay"],
                 "yaw_bias_Y": env["ext_Y"] / q[1], "yaw_bias_N": env["ext_N"] / q[2]}
    names = base.param_names
    params = []
    freed = {c: fit.coefs[c] for c in pb.free_coefficients(effects) if c in fit.coefs}
    for k, v in {**pb.describe(fit), **freed}.items():
        if not isinstance(v, (int, float)):
            continue
        eq = pb.equation_of(k) if k in names else "effect"
        t = float(truth.params[names.index(k)]) if k in names else truth_eff.get(k)
        params.append({"equation": eq, "name": k, "estimate": float(v), "truth": t,
                       "truth_kind": "exact" if k in names else "hidden effect"})
    metrics = {"training_error": fit.training_error, "effect_evaluations": fit.evaluations}
    coefs = {k: v for k, v in fit.coefs.items() if k in names}
    return {"estimates": coefs, "params": params, "metrics": metrics,
            "vessel": pb.vessel(effects, fit.values, None, fit.coefs, replay=False)}
