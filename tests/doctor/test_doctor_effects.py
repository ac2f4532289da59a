"""Hidden-effect tests generated over every discovered effect (``conf/effect/*.yaml``), for the vessel's own
coefficients (``known``) and for a hull identified from the same records (``mmg_hull``, the user's normal case,
anchored to coefficients 20 % off the truth):
the hidden effect ranks first, adding it cuts the validation error at least by half, its parameters come out
near the truth. Effect sizes, directions and depths are the examples' own (other than tests/doctor/test_doctor.py's).
Nothing hidden gives no effect and two hidden effects are found one after the other, with the identified hull.
A user's effect, written outside the package (docs/examples/effects), is found through ``effect_path``.

Records: the 7 m KVLCC2 model (published MMG coefficients), 300 s at 10 Hz, 1 % noise on every channel;
training: 10/10 and 20/20 zigzags and a random rudder; validation: a 20/10 zigzag to port and a 35 deg turn.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from study.doctor.diagnose import Doctor, Options
from study.identify.effects import effect_config, list_effects
from study.sim import load_vessel

from doctor_cases import VESSEL, U0, check_expectations, make_records, model_for, perturbed_prior

EFFECTS = list_effects()
EXAMPLES_DIR = Path(__file__).resolve().parents[2] / "docs" / "examples" / "effects"
_RUNS = {}


def run_case(name: str, example: dict, identified: bool, **opt):
    key = (name, identified)
    if key not in _RUNS:
        terms = (effect_config("hull_nonlinear").get("options") or {}).get("terms", {}).get("mmg", {})
        train, val, truth_cfg = make_records(example)
        model = model_for(example, identified, terms)
        # an identified hull is anchored to the user's coefficients, which are 20 % off the truth here
        prior = perturbed_prior(VESSEL, model) if identified else VESSEL
        d = Doctor(prior, model, train, val, Options(**opt))
        d.run()
        _RUNS[key] = (d, d.report(), load_vessel(truth_cfg))
    return _RUNS[key]


def test_every_effect_has_an_example():
    missing = [e for e in EFFECTS if not effect_config(e).get("example")]
    assert not missing, f"effects without an example for the generated test: {missing}"


CASES = [pytest.param(e, ident, id=f"{e}-{'identified_hull' if ident else 'known'}")
         for e in EFFECTS for ident in (False, True)]


@pytest.mark.slow  # a doctor run each, 6-12 s with the published hull, 55-70 s with an identified one (2 cores)
@pytest.mark.parametrize("effect, identified", CASES)
def test_hidden_effect_is_found_first_halves_the_error_and_is_identified(effect, identified):
    example = effect_config(effect)["example"]
    # (hull_nonlinear on an identified hull: the model is the linear MMG hull, whose nonlinear terms it frees)
    d, rep, truth = run_case(effect, example, identified)
    assert rep["missing_effect"] == effect, (rep["verdict"], [(r["effect"], r["validation_error"])
                                                               for r in rep["ranking"]])
    assert rep["ranking"][0]["effect"] == effect and rep["ranking"][0]["significant"]
    ladder = rep["ladder"]
    assert ladder[1]["step"] == f"+ {effect}" and not ladder[1].get("rejected")
    # compared on the records where the baseline replay did not diverge (a diverged one is reported, not scored)
    assert ladder[0]["scored_records"], rep["verdict"]
    assert ladder[1]["scored_error"] <= 0.5 * ladder[0]["scored_error"], ladder
    bad = check_expectations(example.get("expect"), rep["ranking"][0]["parameters"], truth,
                             "identified" if identified else "known")
    assert not bad, bad


@pytest.mark.slow  # a doctor run at two depths: 6-12 s with the published hull, 60 s with an identified one
@pytest.mark.parametrize("identified", [False, True], ids=["known", "identified_hull"])
def test_a_validation_record_at_a_new_depth_is_predicted_at_its_own_depth(identified):
    """Training at h/T 2.2 and 1.8, validation at 1.4: shallow_water is named and each record's h/T (from its
    depth column) is the truth; with the identified hull too."""
    example = effect_config("shallow_water")["example"]
    d, rep, _ = run_case("shallow_water", example, identified)
    assert rep["missing_effect"] == "shallow_water", rep["verdict"]
    h = rep["depths_h_T"]
    assert h["validate_0_zigzag_20_10_port"] == pytest.approx(1.4, rel=1e-6)
    assert h["train_1_zigzag_20_20"] == pytest.approx(1.8, rel=1e-6)


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
def test_identified_hull_nothing_hidden_gives_no_effect():
    d, rep, _ = run_case("none", {}, True)
    assert rep["missing_effect"] is None and not rep["ambiguous"], rep["verdict"]
    assert not any(r["significant"] for r in rep["ranking"])
    assert "No significant missing effect" in rep["verdict"]


def _named_one_after_the_other(rep: dict, effects: set) -> None:
    """The ladder's first two accepted steps add the two hidden effects, each lowering the error."""
    accepted = [s for s in rep["ladder"] if not s.get("rejected")]
    assert {s["step"] for s in accepted[1:3]} == {f"+ {e}" for e in effects}, [s["step"] for s in accepted]
    errs = [s["scored_error"] for s in accepted]
    assert errs[2] < errs[1] < errs[0]


@pytest.mark.slow  # 80 s; the known-model case of two hidden effects runs by default (tests/doctor/test_doctor.py)
def test_identified_hull_two_hidden_effects_are_found_one_after_the_other():
    example = {"environment": [{"name": "current", "speed_U0": 0.12, "direction_deg": 200.0},
                               {"name": "yaw_bias", "Y": 0.0, "N": -7.0e-4}]}
    d, rep, truth = run_case("two", example, True)
    _named_one_after_the_other(rep, {"current", "yaw_bias"})
    p = rep["final"]["parameters"]
    assert p["current_speed"] == pytest.approx(0.12 * U0, rel=0.2)
    assert p["yaw_bias_N"] == pytest.approx(-7.0e-4, rel=0.3)


@pytest.mark.slow  # 140 s: the identified hull, two effects for which a third stands in
def test_identified_hull_two_effects_a_third_stands_in_for_are_named_together():
    """A current (8 % of the speed towards 120 deg) and a yaw bias (N' 5e-4) together: a wind ranks first alone
    (its drift and yaw moment mimic both; validation error 0.613 -> 0.254, the current alone 0.317), and the greedy
    ladder named the wind (32 % lower, refined) and stopped. The pair the wind stands in for is named at once:
    measured 0.613 -> 0.049 (-92 %), the current 0.095 m/s towards 121 deg, N' 6e-4."""
    example = {"environment": [{"name": "current", "speed_U0": 0.08, "direction_deg": 120.0},
                               {"name": "yaw_bias", "Y": 0.0, "N": 5.0e-4}]}
    _, rep, _ = run_case("stand_in", example, True)
    assert sorted(rep["missing_effects"]) == ["current", "yaw_bias"], rep["verdict"]
    assert "Missing effects: current and yaw_bias, together" in rep["verdict"]
    ladder = [s for s in rep["ladder"] if not s.get("rejected")]
    assert set(ladder[1]["effects"]) == {"current", "yaw_bias"} and "wind" not in rep["final"]["effects"]
    assert ladder[1]["scored_error"] <= 0.5 * ladder[0]["scored_error"]
    p = rep["final"]["parameters"]
    assert p["current_speed"] == pytest.approx(0.08 * U0, rel=0.2)
    assert abs((p["current_direction_deg"] - 120.0 + 180.0) % 360.0 - 180.0) < 12.0
    assert p["yaw_bias_N"] == pytest.approx(5.0e-4, rel=0.3)


@pytest.mark.slow  # two identified-hull doctor runs, 60-90 s each
@pytest.mark.parametrize("identified", [False, True], ids=["known", "identified_hull"])
def test_a_late_steering_gear_is_told_from_a_slow_one(identified):
    """A steering gear that is late (1.2 s dead time) rather than slow (no lag), the record logging the command:
    rudder_dynamics is named with the dead time near 1.2 s and a lag that stays small."""
    example = {"environment": [{"name": "rudder_dynamics", "lag": 0.0, "delay": 1.2}], "rudder_log": "command"}
    d, rep, _ = run_case("late_steering", example, identified)
    assert rep["missing_effect"] == "rudder_dynamics", rep["verdict"]
    p = rep["ranking"][0]["parameters"]
    assert p["rudder_delay"] == pytest.approx(1.2, abs=0.2) and p["rudder_lag"] < 0.5
    ladder = [s for s in rep["ladder"] if not s.get("rejected")]
    assert ladder[1]["scored_error"] <= 0.5 * ladder[0]["scored_error"]


@pytest.mark.slow  # 90 s: the identified hull, two effects of different kinds
def test_identified_hull_wind_and_a_late_steering_gear_are_both_named():
    example = {"environment": [{"name": "wind", "speed_U0": 5.0, "direction_deg": 250.0},
                               {"name": "rudder_dynamics", "lag": 0.0, "delay": 1.0}], "rudder_log": "command"}
    d, rep, _ = run_case("wind_late", example, True)
    _named_one_after_the_other(rep, {"wind", "rudder_dynamics"})
    p = rep["final"]["parameters"]
    assert p["wind_speed"] == pytest.approx(5.0 * U0, rel=0.25)
    assert p["rudder_delay"] == pytest.approx(1.0, abs=0.25)


@pytest.mark.slow  # 15-30 s with the published hull, 2-3 min with an identified one: five records through the filter
@pytest.mark.parametrize("identified", [False, True], ids=["known", "identified_hull"])
def test_a_current_is_named_from_positions_and_heading_only(identified):
    """Records as a sea trial gives them: positions and heading only, with u, v, r estimated by the extended Kalman
    filter and smoother, and the tests' relative noise (1 %: about 0.7 m on the positions of this 7 m model, a
    tenth of its length, and 0.15-0.25 deg on the heading; far noisier than a basin's tracking). The current is named,
    its speed and direction found, and the error falls by at least half (measured: 91 % with the published hull, 81 %
    with the identified one; 53 % and 27 % when replays started from the smoother's first estimates and were scored
    on u, v, r and psi alone). The report says the states were estimated; with measured ones it does not."""
    example = {**effect_config("current")["example"], "states": "estimated"}
    d, rep, _ = run_case("current_estimated_states", example, identified)
    assert rep["missing_effect"] == "current", rep["verdict"]
    p = rep["final"]["parameters"]
    assert p["current_speed"] == pytest.approx(0.12 * U0, rel=0.2)
    assert abs((p["current_direction_deg"] - 200.0 + 180.0) % 360.0 - 180.0) < 12.0
    ladder = [s for s in rep["ladder"] if not s.get("rejected")]
    assert ladder[1]["scored_error"] <= 0.5 * ladder[0]["scored_error"]
    assert any("estimated from positions and heading" in n for n in rep["notes"]), rep["notes"]
    assert not any("estimated from positions" in n for n in run_case("current", effect_config("current")["example"],
                                                                     False)[1]["notes"])


@pytest.mark.slow  # 40 s: the identified hull, five records through the state estimator
def test_a_late_steering_gear_is_named_from_positions_and_heading_only():
    """The effect the doctor misnamed on such records (as a rudder-hull interaction, 43 % lower) while replays
    started from the smoother's first estimates: the rudder_dynamics example (1.5 s lag, 0.8 s dead time, the
    records logging the command), the hull identified, positions and heading only with the tests' 1 % noise.
    Measured: named, the error 94 % lower. The steering gear's total response time (lag + dead time) comes out
    within 4 % (2.38 s against 2.3), but its split less well than from measured u, v, r: lag 1.38 s, dead time
    1.00 s (the smoothed estimates blur what tells a lag from a delay). The test holds the total to 10 %."""
    example = {**effect_config("rudder_dynamics")["example"], "states": "estimated"}
    _, rep, _ = run_case("rudder_dynamics_estimated_states", example, True)
    assert rep["missing_effect"] == "rudder_dynamics", rep["verdict"]
    ladder = [s for s in rep["ladder"] if not s.get("rejected")]
    assert ladder[1]["scored_error"] <= 0.5 * ladder[0]["scored_error"]
    p = rep["final"]["parameters"]
    assert p["rudder_lag"] + p["rudder_delay"] == pytest.approx(1.5 + 0.8, rel=0.10), p


def test_a_users_own_effect_from_outside_the_package(monkeypatch):
    """docs/examples/effects: a yaw moment c n^2, class and YAML outside the package, found through
    effect_path. The truth: the simulator's constant yaw moment of the same size (n is constant in these
    records, so yaw_bias would be the same physics: it is left out of the candidates)."""
    monkeypatch.syspath_prepend(str(EXAMPLES_DIR))
    assert "n2_yaw" in list_effects(EXAMPLES_DIR) and "n2_yaw" not in EFFECTS
    v = load_vessel(VESSEL)
    c = 0.05  # N m s^2
    p = VESSEL["particulars"]
    qL = 0.5 * float(p["rho"]) * float(p["Lpp"]) ** 2 * float(p["d"]) * U0 ** 2
    example = {"environment": [{"name": "yaw_bias", "Y": 0.0, "N": c * v.n0 ** 2 / qL}]}
    cands = ("current", "wind", "rudder_dynamics", "n2_yaw")
    d, rep, _ = run_case("n2_yaw", example, False, candidates=cands, effect_path=(str(EXAMPLES_DIR),))
    assert rep["missing_effect"] == "n2_yaw", rep["verdict"]
    assert rep["ladder"][1]["scored_error"] <= 0.5 * rep["ladder"][0]["scored_error"]
    assert rep["ranking"][0]["parameters"]["yaw_n2"] == pytest.approx(c, rel=0.3)
    assert rep["units"]["yaw_n2"] == "N m s^2"
    sys.modules.pop("n2_yaw", None)


@pytest.mark.slow  # the slow tier: .ci/run runs it after the README's test command
@pytest.mark.parametrize("vessel,model", [("mariner", "abkowitz"), ("usv_waterjet", "usv_full"), ("auv", "auv")])
def test_every_force_model_kind_is_diagnosed(vessel, model):
    """The doctor with the other force models, identified and anchored to the vessel config: a hidden current
    (12 % of the speed towards 200 deg) on the Abkowitz Mariner and the waterjet USV is found; the AUV's hull
    identified from zigzags diverges in the 35 deg turn, and the report says so rather than naming anything."""
    from study.configuration.compose import read_config

    v = read_config("vessel", vessel)
    example = {"environment": [{"name": "current", "speed_U0": 0.12, "direction_deg": 200.0}]}
    train, val, _ = make_records(example, vessel_cfg=v)
    d = Doctor(v, read_config("model", model), train, val)
    d.run()
    rep = d.report()
    assert {"rudder_interaction", "propeller_wake"} <= set(rep["not_applicable"])  # MMG-only candidates
    if rep["baseline"]["diverged"]:
        assert rep["verdict"].startswith("Diverged:") and vessel == "auv", rep["verdict"]
        return
    assert rep["missing_effect"] == "current", rep["verdict"]
    assert rep["ladder"][1]["scored_error"] <= 0.5 * rep["ladder"][0]["scored_error"]
    p = rep["ranking"][0]["parameters"]
    assert p["current_speed"] == pytest.approx(0.12 * float(v["operation"]["U0"]), rel=0.2)
