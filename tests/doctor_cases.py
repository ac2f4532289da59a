"""Hidden-effect cases for the model doctor's tests, built from each effect's ``example`` block
(``conf/effect/*.yaml``): the truth simulator (``study.sim``, not the doctor's hooks) makes the records, so an
effect is found only if the doctor's physics matches the simulator's.

An ``example`` may give
- ``environment``: effects of the truth simulator (``study.sim.effects``; ``*_U0`` keys in units of U0);
- ``vessel``: changes to the truth vessel's config, ``{section: {key: {times: f} | {plus: x} | value}}``;
- ``rudder_log: command``: the records' rudder column holds the command (an autopilot log);
- ``depth_h_T: {train: [...], validate: [...]}``: each record at its own h/T, with a ``depth`` column;
- ``model_omits: terms``: the model lacks the effect's terms (hull_nonlinear's per-kind list);
- ``record_thrust: true``: the records carry the propeller thrust [N] (the simulator's own, ``study.sim.mmg.thrust``,
  at the true states, with the same relative noise as the other channels);
- ``expect``: parameter -> ``{value | value_U0 | truth: true, rel | abs | abs_deg, models}``.
"""
from __future__ import annotations

import copy
import math

from study.records.measure import DEFAULT_CHANNELS, MeasurementModel
from study.run.pipeline import resolve_effects
from study.records.schema import Record, with_estimated_states
from study.configuration.compose import read_config
from study.sim import load_vessel, simulate
from study.sim.effects import ShallowWater

VESSEL = read_config("vessel", "kvlcc2_l7")
U0 = float(VESSEL["operation"]["U0"])
TRAIN = ("zigzag_10_10", "zigzag_20_20", "random_rudder")
VALIDATE = ("zigzag_20_10_port", "turning_35")
KNOWN = {"name": "known", "type": "kind", "equations": {}}
MMG_HULL = read_config("model", "mmg_hull")


def changed_vessel(cfg: dict, changes: dict) -> dict:
    out = copy.deepcopy(cfg)
    for sec, kv in (changes or {}).items():
        for k, ch in kv.items():
            v = float(out[sec][k])
            if isinstance(ch, dict):
                v = v * float(ch.get("times", 1.0)) + float(ch.get("plus", 0.0))
            else:
                v = float(ch)
            out[sec][k] = v
    return out


def perturbed_prior(cfg: dict, model: dict, rel: float = 0.2) -> dict:
    """The vessel config a user would have: the model's free coefficients ``rel`` off the truth, alternately
    above and below (a published set is never exact), so an identified hull is not anchored to the truth."""
    from study.sim import get_kind

    out = copy.deepcopy(cfg)
    names = [c for eq in ("X", "Y", "N") for c in (model.get("equations") or {}).get(eq, [])]
    sec = get_kind(cfg["kind"]).COEFF_SECTION
    keys = {k.replace("_", ""): k for k in out[sec]}
    for i, c in enumerate(names):
        k = keys.get(c)
        if k is not None:
            out[sec][k] = float(out[sec][k]) * (1.0 + rel * (1 if i % 2 == 0 else -1))
    return out


def true_thrust(vessel, df):
    """The simulator's propeller thrust [N] (``study.sim.mmg.thrust``, eqs. 13-16 of Yasukawa & Yoshimura 2015)
    at a simulation's states."""
    import numpy as np

    from study.sim import mmg

    P = np.ascontiguousarray(vessel.params, dtype=np.float64).reshape(-1, 1)
    return np.array([mmg.thrust(u, v, r, n, P, 0)[0] for u, v, r, n in
                     df[["u", "v", "r", "n"]].to_numpy(float)])


def make_records(example: dict, seed: int = 0, duration: float = 300.0, vessel_cfg: dict = VESSEL):
    """(training Records, validation Records, truth vessel config) of a hidden-effect example."""
    cfg = changed_vessel(vessel_cfg, example.get("vessel"))
    env = resolve_effects(example.get("environment") or [], float(cfg["operation"]["U0"]))
    depths = example.get("depth_h_T") or {}
    out = []
    for role, mans in (("train", TRAIN), ("validate", VALIDATE)):
        hs = depths.get(role) or [None] * len(mans)
        for i, (m, h) in enumerate(zip(mans, hs)):
            effects = ([ShallowWater(h_T=float(h))] if h else []) + list(env)
            clean = simulate(load_vessel(cfg, effects), m, duration=duration)
            if example.get("rudder_log") == "command":
                clean["delta"] = clean["delta_cmd"]
            if example.get("record_thrust"):
                clean["thrust"] = true_thrust(load_vessel(cfg, effects), clean)
            chans = DEFAULT_CHANNELS + (("thrust",) if "thrust" in clean.columns else ())
            estimated = example.get("states") == "estimated"  # a sea trial's record: positions and heading only
            if estimated:
                chans = ("psi", "x0", "y0", "delta")
            df = MeasurementModel(dt=0.1, noise_level=0.01, seed=seed + len(out),
                                  channels=chans).apply(clean.drop(columns="delta_cmd"))
            if h:
                df["depth"] = float(h) * float(cfg["particulars"]["d"])
            rec = Record(data=df, meta={"name": f"{role}_{i}_{m}"})
            if estimated:  # u, v, r from the extended Kalman filter and smoother, as states=auto reads them
                rec = with_estimated_states(Record(data=df.drop(columns=["u", "v", "r"]), meta=rec.meta))
            out.append((role, rec))
    return [r for k, r in out if k == "train"], [r for k, r in out if k == "validate"], cfg


def model_for(example: dict, identified: bool, terms: dict) -> dict:
    """The model of a case: ``known`` or the identified MMG hull; without the effect's terms if it omits them."""
    if not example.get("model_omits"):
        return MMG_HULL if identified else KNOWN
    omit = {eq: list(cs) for eq, cs in terms.items()}
    if not identified:
        return {"name": "linear_hull", "type": "kind", "equations": {}, "omit": omit}
    drop = {c for cs in terms.values() for c in cs}
    eqs = {eq: [c for c in cs if c not in drop] for eq, cs in MMG_HULL["equations"].items()}
    return {"name": "mmg_linear_hull", "type": "kind", "kind": "mmg", "equations": eqs, "omit": omit}


def check_expectations(expect: dict, params: dict, truth_vessel, model: str = "known") -> list:
    """Failures (strings) of a case's expectations on the reported parameters (an expectation with ``models``
    applies to those models only: ``known``, ``identified``)."""
    bad = []
    names = truth_vessel.param_names
    for k, e in (expect or {}).items():
        if "models" in e and model not in e["models"]:
            continue
        if k not in params:
            bad.append(f"{k} not reported (have {sorted(params)})")
            continue
        got = params[k]
        if isinstance(e.get("value"), str):
            if got != e["value"]:
                bad.append(f"{k} = {got}, expected {e['value']}")
            continue
        if e.get("truth"):
            want = float(truth_vessel.params[names.index(k)])
        elif "value_U0" in e:
            want = float(e["value_U0"]) * float(truth_vessel.U0)
        else:
            want = float(e["value"])
        if "abs_deg" in e:
            err = abs((float(got) - want + 180.0) % 360.0 - 180.0)
            ok = err <= float(e["abs_deg"])
        elif "abs" in e:
            ok = abs(float(got) - want) <= float(e["abs"])
        else:
            ok = abs(float(got) - want) <= float(e.get("rel", 0.2)) * abs(want)
        if not (ok and math.isfinite(float(got))):
            bad.append(f"{k} = {float(got):.4g}, truth {want:.4g} ({e})")
    return bad
