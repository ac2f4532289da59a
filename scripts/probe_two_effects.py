"""The doctor on two hidden effects of different kinds at once: an identified MMG hull (anchored to coefficients
20 % off the truth) on records that hide two effects, sizes and directions other than the tests'. Both should be
named. Prints, per case, the verdict, the ladder and the first candidates.

Records as ``tests/doctor_cases.py`` makes them (the truth simulator, 1 % noise on every channel, measured u, v, r;
training: 10/10 and 20/20 zigzags and a random rudder, validation: a 20/10 zigzag to port and a 35 deg turn).

Run from the repository's root: ``python scripts/probe_two_effects.py [case ...]`` (default: every case); 2-9 min a
case on one core.
"""
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the hidden-effect records of the doctor's tests

from doctor_cases import VESSEL, make_records, model_for, perturbed_prior  # noqa: E402

from study.doctor.diagnose import Doctor, Options  # noqa: E402
from study.identify.effects import effect_config  # noqa: E402

STEERING = {"name": "rudder_dynamics", "lag": 1.0, "delay": 0.5}
#: name -> the hidden effects, as the effects' YAML examples give them (``environment``, ``vessel``)
CASES = {
    "current_wind": {"environment": [{"name": "current", "speed_U0": 0.12, "direction_deg": 200.0},
                                     {"name": "wind", "speed_U0": 5.0, "direction_deg": 60.0}]},
    "wind_yaw_bias": {"environment": [{"name": "wind", "speed_U0": 5.0, "direction_deg": 250.0},
                                      {"name": "yaw_bias", "Y": 0.0, "N": -7.0e-4}]},
    "wind_steering": {"environment": [{"name": "wind", "speed_U0": 3.0, "direction_deg": 300.0}, STEERING],
                      "rudder_log": "command"},
    "current_yaw_bias": {"environment": [{"name": "current", "speed_U0": 0.08, "direction_deg": 120.0},
                                         {"name": "yaw_bias", "Y": 0.0, "N": 5.0e-4}]},
    "yaw_bias_steering": {"environment": [{"name": "yaw_bias", "Y": 0.0, "N": 5.0e-4}, STEERING],
                          "rudder_log": "command"},
    "current_inflow": {"environment": [{"name": "current", "speed_U0": 0.06, "direction_deg": 30.0}],
                       "vessel": {"rudder": {"gamma_R_neg": 0.7, "gamma_R_pos": 0.35}}},
    "yaw_bias_interaction": {"environment": [{"name": "yaw_bias", "Y": 0.0, "N": -4.0e-4}],
                             "vessel": {"rudder": {"a_H": {"times": 1.8}, "x_R": {"times": 1.08}}}},
    "current_wake": {"environment": [{"name": "current", "speed_U0": 0.08, "direction_deg": 300.0}],
                     "vessel": {"propeller": {"w_P0": {"plus": -0.15}}}},
}


def run(name: str) -> None:
    t0 = time.perf_counter()
    example = CASES[name]
    terms = (effect_config("hull_nonlinear").get("options") or {}).get("terms", {}).get("mmg", {})
    train, val, _ = make_records(example)
    model = model_for(example, True, terms)
    d = Doctor(perturbed_prior(VESSEL, model), model, train, val, Options())
    d.run()
    rep = d.report()
    print(f"== {name} ({time.perf_counter() - t0:.0f} s): {rep['verdict']}")
    print("   ladder:", ", ".join(f"{s['step']} {s['scored_error']:.3g}" + (" (rejected)" if s.get("rejected") else "")
                                   for s in rep["ladder"]))
    print("   first candidates:", ", ".join(f"{r['effect']} {r['validation_error']:.3g}" for r in rep["ranking"][:4]),
          flush=True)


if __name__ == "__main__":
    for case in sys.argv[1:] or list(CASES):
        run(case)
