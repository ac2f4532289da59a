"""The model doctor run from a resolved configuration (``conf/diagnose.yaml``): what ``python -m
study diagnose``, its worked examples (``study.doctor.examples``) and the tests call.

``run(conf)`` checks the settings, reads the records (``study.records.loaders.load_records``), holds
the output folder (``claimed``), runs the doctor (``study.doctor.diagnose``), writes its report and
logs each ladder step as a run of the results table (``log_runs``, study ``doctor``);
``diagnose_conf(**over)`` composes the configuration as the command does.
"""
from __future__ import annotations

import contextlib
import hashlib
from pathlib import Path

from study.configuration.compose import compose
from study.records.loaders import load_records


def diagnose_conf(**over) -> dict:
    """The doctor's configuration as ``python -m study diagnose`` composes it (``vessel``,
    ``model`` as its overrides), the other keys of ``over`` set on it; its runs are not logged in
    the results table."""
    conf = compose("diagnose", [f"{k}={v}" for k, v in over.items() if k in ("vessel", "model")])
    conf.update(log_runs=False, overwrite=False)
    conf.update({k: v for k, v in over.items() if k not in ("vessel", "model")})
    return conf


def _digest(records) -> list:
    out = []
    for r in records:
        h = hashlib.sha256(r.data.to_csv(index=False).encode()).hexdigest()[:16]
        out.append({"name": r.meta.get("name"), "path": r.path, "sha256_16": h})
    return out


def _use_rudder(records, column: str) -> None:
    if column == "delta":
        return
    for r in records:
        if column not in r.data.columns:
            raise ValueError(f"{r.path or r.meta.get('name')}: rudder={column} but the record has no '{column}' "
                             f"column (it has {list(r.data.columns)})")
        r.data["delta"] = r.data[column]


def _truths(records) -> dict:
    """Effect parameters hidden in simulated records' metadata (a test or study can then
    compare)."""
    out = {}
    for r in records:
        for e in r.meta.get("hidden_effects") or []:
            out.setdefault(e.get("name"), e)
    return out


def log_runs(conf: dict, doctor, rep: dict, train, validate) -> list:
    """Each ladder step as one run of the results table (study 'doctor')."""
    from study.run.executor import run_guarded
    from ..store import ResultStore

    store = ResultStore(conf.get("results_dir") or Path(conf["out"]) / "results")
    ids = []
    for step in rep["ladder"]:
        effects = tuple(step["effects"])
        key = [k for k in doctor.evaluations if k[0] == effects]
        ev = doctor.evaluations[[k for k in key if k[2]][0] if any(k[2] for k in key) else key[0]]
        cfg = {"study": "doctor", "vessel": conf["vessel"], "depth": conf.get("depth"),
               "model": {**conf["model"], "effects": list(effects)}, "train": _digest(train),
               "validate": _digest(validate), "structure": doctor.problem.structure.name,
               "options": {k: conf[k] for k in ("min_improvement", "alpha", "tie", "rudder")}}

        def result(ev=ev):
            pb = doctor.problem
            params = [{"equation": pb.equation_of(k) if k in pb.base.param_names else "effect", "name": k,
                       "estimate": float(v), "truth": None}
                      for k, v in pb.describe(ev.fit).items() if isinstance(v, (int, float))]
            metrics = {"validation_error": ev.validation_error, "training_error": ev.training_error,
                       "diverged_records": float(len(ev.diverged))}
            for rec, chans in ev.errors.items():
                for c, e in chans.items():
                    if isinstance(e, dict):
                        metrics[f"val_{rec}_nrmse_{c}"] = e["nrmse"]
                    elif isinstance(e, (bool, int, float)):  # 'diverged' ('scored' names channels)
                        metrics[f"val_{rec}_{c}"] = float(e)
            return {"metrics": metrics, "params": params, "timings": {"fit": ev.seconds}}

        rec = run_guarded(store, cfg, result, seed=None)
        ids.append(rec["run_id"])
    store.collect()
    return ids


def _check_place(conf: dict) -> None:
    """The vessel config's ``facility`` (one of ``study.records.facility.FACILITIES``) and
    ``keep_setup_effects`` (a boolean), refused in one line before any work."""
    from study.configuration.cli import ConfigError
    from study.records.facility import check

    vessel = conf.get("vessel") or {}
    check(vessel.get("facility"), f"conf/vessel/{vessel.get('name')}.yaml")
    keep = conf.get("keep_setup_effects", False)
    if not isinstance(keep, bool):
        raise ConfigError(f"keep_setup_effects={keep!r}: expected true or false")


@contextlib.contextmanager
def claimed(out: Path, overwrite: bool):
    """Hold ``out`` for one doctor while it works: a second one writing into the same folder is
    refused at once (an exclusive lock, ``<out>/.report.lock``, released when the process ends
    however it ends), and the folder is checked again for a report under the lock (another run
    may have finished one meanwhile)."""
    import shutil

    from filelock import FileLock, Timeout

    from study.configuration.cli import OutputExistsError
    from study.run.settings import existing_report

    made = [p for p in (out, *out.parents) if not p.exists()]  # what this doctor creates (removed if refused)
    out.mkdir(parents=True, exist_ok=True)
    lock = FileLock(str(out / ".report.lock"))
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise OutputExistsError(f"out={out}: another python -m study diagnose is writing a report there") from None
    refused = True
    try:
        there = existing_report(out)
        if there and not overwrite:
            raise OutputExistsError(f"out={out}: {out} already holds {', '.join(there)}; refusing to overwrite a "
                                    "report (overwrite=true to overwrite it, or another out=)")
        partial = out / PARTIAL_FIGURES  # a doctor stopped while it wrote its figures (none holds the lock now)
        if partial.exists():
            shutil.rmtree(partial, ignore_errors=True)
        yield out
        refused = False
    finally:
        lock.release()
        if refused and made:  # a refusal or a failure leaves nothing behind in a folder it made
            shutil.rmtree(out / PARTIAL_FIGURES, ignore_errors=True)
            (out / ".report.lock").unlink(missing_ok=True)
            for p in made:
                try:
                    p.rmdir()
                except OSError:
                    break


#: where the doctor writes its figures before they are moved to ``figures/`` (see report.write_report)
PARTIAL_FIGURES = ".figures.partial"


def run(conf: dict) -> dict:
    """Run the doctor from a resolved config (what the CLI and the tests call)."""
    from study.run.settings import check_diagnose
    from ..sim.effects import ShallowWater, apply_effects
    from .diagnose import Doctor, Options
    from .report import write_report

    out = check_diagnose(conf)  # before any work: records and out given, no report there, thresholds in range
    _check_place(conf)
    read = {"states": conf.get("states") or "measured", "state_options": conf.get("state_options") or None}
    train = load_records(conf["train"], **read)
    validate = load_records(conf["validate"], **read) if conf.get("validate") else []
    _use_rudder(train + validate, conf.get("rudder", "delta"))
    depth = conf.get("depth") or {}
    vessel_cfg = conf["vessel"]
    if depth.get("h_T"):
        vessel_cfg, _ = apply_effects(vessel_cfg, [ShallowWater(h_T=depth["h_T"], formula=depth.get("formula",
                                                                                                  "kijima_1990"))])
    cands = conf.get("candidates")
    path = conf.get("effect_path") or ()
    opt = Options(min_improvement=float(conf["min_improvement"]), alpha=float(conf["alpha"]),
                  tie=float(conf["tie"]), max_steps=int(conf["max_steps"]),
                  candidates=tuple(cands) if cands is not None else None, structure=conf.get("structure"),
                  effect_path=tuple([path] if isinstance(path, str) else path), checks=str(conf.get("checks", "error")),
                  anchor=float(conf.get("anchor") or 0.0),
                  keep_setup_effects=bool(conf.get("keep_setup_effects", False)))
    # every check of the records against the vessel and of the candidates runs here, before the report folder
    # is made or held: a refusal leaves nothing behind
    doctor = Doctor(vessel_cfg, conf["model"], train, validate, opt)
    with claimed(out, bool(conf.get("overwrite"))):
        doctor.run()
        rep = write_report(doctor, conf["out"], conf["vessel"]["name"], conf["model"]["name"],
                           overwrite=bool(conf.get("overwrite")))
    truths = _truths(train + validate)
    if truths:
        rep["hidden_effects"] = truths
    if conf.get("log_runs", True):
        rep["run_ids"] = log_runs(conf, doctor, rep, train, validate)
    return rep

