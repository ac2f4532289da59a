"""The candidate effects (conf/effect/*.yaml, study/identify/effects/): the contract, checked on every discovered
effect as tests/identify/test_estimators.py checks every estimator. Whether each effect is *found* when hidden in records
is tests/doctor/test_doctor_effects.py's (generated from each YAML's ``example``); here, fast, that each one is a
well-formed plugin: its YAML names it and a class following ``study.identify.effects.Effect``, its nonlinear
parameters have ordered bounds and a start grid inside them, and identification with it (one equation-error
solve at its grid's first point, on a short noise-free record of the 7 m KVLCC2) gives a finite estimate of
every unknown it declares, each reported in the user's terms with a unit, and a replay through a record.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.configuration.compose import read_config
from study.identify.effects import Effect, effect_config, list_effects, make_effect
from study.identify.with_effects import EffectsProblem, Fit
from study.records.schema import Record
from study.sim import simulate

VESSEL = read_config("vessel", "kvlcc2_l7")
KNOWN = {"name": "known", "type": "kind", "equations": {}}
EFFECTS = list_effects()


@pytest.fixture(scope="module")
def records():
    """Two short noise-free records (60 s at 10 Hz) with the water depth measured (h/T 2.0)."""
    out = []
    for m in ("zigzag_10_10", "turning_35"):
        df = simulate(VESSEL, m, duration=60.0, sample_dt=0.1)
        df = df.drop(columns="delta_cmd")
        df["depth"] = 2.0 * float(VESSEL["particulars"]["d"])
        out.append(Record(data=df, meta={"name": m}))
    return out


def test_the_catalogue_is_discovered_from_its_yaml_files():
    stems = sorted(p.stem for p in (Path(__file__).resolve().parents[2] / "conf" / "effect").glob("*.yaml"))
    assert sorted(EFFECTS) == stems


@pytest.mark.parametrize("name", EFFECTS)
def test_every_effect_follows_the_contract(name, records):
    cfg = effect_config(name)
    assert cfg["name"] == name == Path(cfg["_file"]).stem
    eff = make_effect(name)
    assert isinstance(eff, Effect) and eff.name == name and eff.config["_target_"] == cfg["_target_"]
    assert eff.physics and eff.enters and eff.source, "the report's catalogue shows physics, how it enters, source"
    pb = EffectsProblem(VESSEL, KNOWN, records, effects={name: eff})
    if eff.applies(pb) is not None:  # an effect that cannot act on this vessel says why, in words
        assert isinstance(eff.applies(pb), str) and eff.applies(pb).strip()
        return
    outer = pb.outer_params((name,))
    for pname, lo, hi, grid in outer:
        assert lo < hi and len(grid) >= 1 and all(lo <= g <= hi for g in grid), (pname, lo, hi, grid)
    variants = pb.variants((name,))
    assert variants and all(isinstance(v, dict) for v in variants)
    values = {**variants[0], **{p: grid[0] for p, _, _, grid in outer}}
    coefs, err, _ = pb.solve((name,), values)
    declared = set(pb.free_coefficients((name,))) | set(pb.linear_unknowns((name,)))
    assert declared <= set(coefs), f"unknowns declared but not estimated: {sorted(declared - set(coefs))}"
    assert all(math.isfinite(coefs[k]) for k in declared) and math.isfinite(err) and err >= 0
    fit = Fit((name,), values, coefs, err)
    described = pb.describe(fit)
    assert all(isinstance(v, (int, float, str)) for v in described.values())
    units = pb.units((name,))
    numbers = [k for k, v in described.items() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    assert not [k for k in numbers if k not in units], f"reported without a unit: {set(numbers) - set(units)}"
    pred = pb.predict(fit, records[0].data, pb.info_for(records[0].data, records[0].meta, "zz"))
    assert pred is None or (isinstance(pred, pd.DataFrame) and {"time", "u", "v", "r", "psi"} <= set(pred.columns)
                            and np.isfinite(pred[["u", "v", "r", "psi"]].to_numpy()).all())


def test_the_doctors_old_name_is_the_same_catalogue():
    """``study.doctor.effects`` (where effects lived before they moved to study.identify.effects) still gives the same classes, for effects
    written against it outside the package."""
    from study.doctor import effects as old
    from study.identify import effects as new

    assert old.Effect is new.Effect and old.list_effects() == new.list_effects()
