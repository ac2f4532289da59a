"""``python -m study simulate vessel=<v> maneuver=<m> out=<file>``: write one simulated, measured
record.

Effects (depth, environment) and noise are Hydra overrides (see ``conf/simulate.yaml``). The
record's metadata names the vessel, the manoeuvre, the effects that were applied (so a test can know
the hidden truth) and the noise.
"""
from __future__ import annotations

from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from study.configuration.compose import CONF_DIR
from study.configuration.cli import reported, run_hydra


def make_record(conf: dict):
    """Simulate and measure one manoeuvre from a resolved simulate config; returns a schema
    Record."""
    from study.sim import maneuvers as man_mod
    from study.run.pipeline import measurement, vessels_for
    from study.records.schema import Record
    from study.sim import default_dt, simulate

    from study.run.settings import check_simulation

    check_simulation(conf)  # zero, negative or non-finite settings are refused, naming the setting
    log = conf.get("rudder_log", "both")
    if log not in ("both", "actual", "command"):
        raise ValueError(f"rudder_log={log!r}: expected 'both', 'actual' or 'command'")
    truth, _ = vessels_for(conf)
    man = man_mod.get_maneuver(conf["maneuver"])
    sim = conf.get("sim") or {}
    dt = sim.get("dt") or default_dt(truth)
    T = sim.get("duration") or man.duration_for(truth) * float(sim.get("duration_scale", 1.0))
    seed = int(conf.get("seed", 0))
    clean = simulate(truth, man, dt=dt, duration=T, seed=seed)
    df = measurement(conf, seed=seed, vessel=truth).apply(clean)
    if log == "command":  # the measured 'delta' of an autopilot log is what the steering gear was told
        df["delta"] = np.interp(df["time"], clean["time"], clean["delta_cmd"])
    if log != "both":
        df = df.drop(columns=["delta_cmd"])
    h_T = (conf.get("depth") or {}).get("h_T")
    if h_T is not None and np.isfinite(float(h_T)):  # the measured water depth, as an echo sounder logs it
        df["depth"] = float(h_T) * float(truth.cfg["particulars"]["d"])
    meta = {
        "name": f"{truth.name}_{man.name}",
        "source": "simulated by python -m study simulate",
        "vessel": truth.name,
        "maneuver": man.name,
        "depth": conf.get("depth"),
        "hidden_effects": (conf.get("environment") or {}).get("effects", []),
        "noise": conf.get("noise"),
        "seed": seed,
        "dt": dt,
        "n0": truth.n0,
        "rudder_log": log,
    }
    return Record(data=df.reset_index(drop=True), meta=meta)


@hydra.main(config_path=str(CONF_DIR), config_name="simulate", version_base="1.3")
def main(cfg: DictConfig) -> None:
    with reported("study simulate"):  # a problem: one line on stderr and the exit status (study.configuration.cli)
        _write(OmegaConf.to_container(cfg, resolve=True))


def _write(conf: dict) -> None:
    from study.records.schema import write_record
    from study.run.settings import check_simulate

    path = check_simulate(conf).resolve()  # out= given, a record type, not there: checked before simulating
    rec = make_record(conf)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_record(rec, path, overwrite=bool(conf.get("overwrite", False)))  # created exclusively
    print(f"wrote {path} ({len(rec.data)} samples, {rec.data['time'].iloc[-1]:.1f} s)")


def precheck(overrides: list, multirun: bool) -> None:
    """Every check of ``python -m study simulate`` on its composed configuration, before Hydra
    starts and before anything is simulated: the settings, the classes the configuration names,
    ``out=`` (given, a record file, not there, its folder writable)."""
    from study.configuration.compose import check_targets, compose
    from study.run.settings import check_simulate

    conf = compose("simulate", overrides, hydra=True)
    check_targets(conf)
    check_simulate({k: v for k, v in conf.items() if k != "hydra"})


def command() -> None:
    """Run the command on ``sys.argv`` and exit with its status."""
    run_hydra(main, "study simulate", precheck)
