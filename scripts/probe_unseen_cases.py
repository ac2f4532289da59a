"""The doctor on cases its tests do not hold: an identified MMG hull (anchored to coefficients 20 % off the truth)
on records with a hidden effect of another size or direction, on records with positions and heading only
(u, v, r estimated by the loader's Kalman filter and smoother), at full scale as a sea trial, and with a change no
candidate models. Prints, per case, the verdict, the first candidates and the ladder.

Records as ``tests/doctor_cases.py`` makes them (the truth simulator, 1 % noise on every channel; training: 10/10
and 20/20 zigzags and a random rudder, validation: a 20/10 zigzag to port and a 35 deg turn). Positions and
heading only: white noise of 1.5 cm and 0.15 deg on the 7 m model, 0.5 m and 0.1 deg on the 320 m ship (a
differential GNSS and a gyro compass), no u, v, r.

Run from the repository's root: ``python scripts/probe_unseen_cases.py [case ...]`` (default: every case); 15 s
to 2 min a case on one core.
"""
import sys
import time
from pathlib import Path
from tempfile import TemporaryDirectory

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the hidden-effect records of the doctor's tests

import numpy as np  # noqa: E402
from doctor_cases import MMG_HULL, VESSEL, make_records, perturbed_prior  # noqa: E402

from study.configuration.compose import read_config
from study.doctor.diagnose import Doctor, Options  # noqa: E402
from study.records.measure import MeasurementModel
from study.run.pipeline import resolve_effects
from study.records.schema import read_records
from study.sim import load_vessel, simulate  # noqa: E402

FULL = read_config("vessel", "kvlcc2")
#: name -> (example as the effects' YAML gives one, vessel config, positions and heading only, record length [s])
CASES = {
    "current_small": ({"environment": [{"name": "current", "speed_U0": 0.06, "direction_deg": 80.0}]},
                      VESSEL, False, 300.0),
    "wind_300": ({"environment": [{"name": "wind", "speed_U0": 3.0, "direction_deg": 300.0}]}, VESSEL, False, 300.0),
    "wind_300_pose": ({"environment": [{"name": "wind", "speed_U0": 3.0, "direction_deg": 300.0}]},
                      VESSEL, True, 300.0),
    # two effects of different kinds at once, positions and heading only: both must be named
    "wind_and_current_pose": ({"environment": [{"name": "wind", "speed_U0": 3.0, "direction_deg": 300.0},
                                               {"name": "current", "speed_U0": 0.06, "direction_deg": 80.0}]},
                              VESSEL, True, 300.0),
    "sea_trial_current_pose": ({"environment": [{"name": "current", "speed_U0": 0.08, "direction_deg": 135.0}]},
                               FULL, True, 1800.0),
    "nothing_hidden": ({}, VESSEL, False, 300.0),
    # no candidate frees the added mass and inertia
    "added_mass": ({"vessel": {"hull": {"J_z": {"times": 1.6}, "m_y": {"times": 1.3}}}}, VESSEL, False, 300.0),
    # the records log the rudder's actual angle: a slow steering gear is in the input, nothing is missing
    "slow_rudder_rate": ({"vessel": {"actuator": {"rudder_rate_deg": 4.0}}}, VESSEL, False, 300.0),
}


def pose_only(records, truth_cfg: dict, example: dict, duration: float, folder: Path, seed: int) -> list:
    """The same manoeuvres of the truth vessel, measured as positions and heading only, read back with
    ``states='auto'`` (the loader's Kalman filter and smoother)."""
    U0 = float(truth_cfg["operation"]["U0"])
    vessel = load_vessel(truth_cfg, resolve_effects(example.get("environment") or [], U0))
    full = float(truth_cfg["particulars"]["Lpp"]) > 50.0
    dt, pos_sd, psi_sd = (1.0, 0.5, np.radians(0.1)) if full else (0.1, 0.015, np.radians(0.15))
    folder.mkdir(parents=True)
    for i, rec in enumerate(records):
        man = rec.meta["name"].split("_", 2)[2]
        clean = MeasurementModel(dt=dt).apply(simulate(vessel, man, duration=duration)).drop(columns="delta_cmd")
        rng = np.random.default_rng(seed + i)
        out = clean.drop(columns=["u", "v", "r"])
        for c, sd in (("x0", pos_sd), ("y0", pos_sd), ("psi", psi_sd)):
            out[c] = out[c] + sd * rng.standard_normal(len(out))
        out.to_csv(folder / f"{rec.meta['name']}.csv", index=False)
    return read_records(folder, states="auto")


def run(name: str) -> None:
    example, vessel_cfg, pose, duration = CASES[name]
    t0 = time.perf_counter()
    train, val, truth = make_records(example, duration=duration, vessel_cfg=vessel_cfg)
    if pose:
        with TemporaryDirectory() as tmp:
            train = pose_only(train, truth, example, duration, Path(tmp) / "train", 10)
            val = pose_only(val, truth, example, duration, Path(tmp) / "validate", 20)
    doctor = Doctor(perturbed_prior(vessel_cfg, MMG_HULL), MMG_HULL, train, val, Options())
    doctor.run()
    rep = doctor.report()
    print(f"== {name} ({time.perf_counter() - t0:.0f} s): {rep['verdict']}")
    for r in rep["ranking"][:3]:
        par = ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in r["parameters"].items())
        print(f"   {r['effect']:<20} validation error {r['validation_error']:.4f}"
              f"{' (significant)' if r['significant'] else ''}: {par}")
    fin = rep["final"]["parameters"]
    print("   final: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in fin.items()))
    for s in rep["ladder"]:
        print(f"   ladder {s['step']:<22} validation {s['scored_error']:.4f}, training {s['training_error']:.4f}"
              f"{' REJECTED: ' + str(s.get('reason')) if s.get('rejected') else ''}")


if __name__ == "__main__":
    for case in sys.argv[1:] or list(CASES):
        run(case)
