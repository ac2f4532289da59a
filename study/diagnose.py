"""``python -m study.diagnose train=<file|folder|glob> [validate=...] vessel=<v> model=<m> out=<dir>``.

The model doctor (``study.doctor``): compares a model with measured records, shows where it fails, ranks the
candidate missing effects by out-of-sample improvement, adds them one after the other, and writes
``<out>/report.html`` (self-contained), ``<out>/report.json`` and ``<out>/figures/``; prints a short verdict.
Options in ``conf/diagnose.yaml``. Records: the schema's CSV/Parquet files (``python -m study.simulate``
makes them), HSVA's KVLCC2 ``.dat`` files and the Esso Osaka CSVs of ``../shared/data/real`` (read in place).
"""
from __future__ import annotations

import contextlib
import glob as globmod
import hashlib
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from .app import CONF_DIR
from .cli import reported, run_hydra


def _is_real(path: Path) -> bool:
    if path.suffix.lower() == ".dat":
        return True
    if path.suffix.lower() == ".csv":
        with open(path, encoding="utf-8", errors="replace") as fh:
            head = fh.readline()
        return "u_velo [m/s]" in head  # an Esso Osaka file
    return False


def load_records(spec, states: str = "measured", state_options: dict | None = None) -> list:
    """Records from a file, folder or glob, or a comma-separated list of them: schema files, or the real
    datasets' own formats. ``states`` (``measured | auto | ekf``) and ``state_options``: where u, v, r come from
    (``study.schema.read_record``; the real datasets' loaders always give u, v, r, which ``ekf`` refines)."""
    from .loaders import load_real
    from .schema import STATES, SUPPORTED, read_record, with_estimated_states

    if states not in STATES:
        raise ValueError(f"states={states}: expected one of {list(STATES)}")

    from .records_run import patterns

    files = []
    for pattern in patterns(spec):  # a comma-separated list, as ``python -m study train=...`` takes
        p = Path(pattern).expanduser()
        if p.is_file():
            found = [p]
        elif p.is_dir():
            found = sorted(f for f in p.iterdir() if f.suffix.lower() in SUPPORTED + (".dat",))
        else:
            found = sorted(Path(f) for f in globmod.glob(pattern) if Path(f).suffix.lower() in SUPPORTED + (".dat",))
        if not found:
            raise FileNotFoundError(f"{pattern}: no record files (.csv, .parquet, .dat) found")
        files += [f for f in found if f not in files]
    out = []
    for f in files:
        if _is_real(f):
            rec = load_real(f)
            if states == "ekf":
                rec = with_estimated_states(rec, state_options)
        else:
            rec = read_record(f, states=states, state_options=state_options)
        rec.meta.setdefault("name", f.stem)
        out.append(rec)
    return out


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
    """Effect parameters hidden in simulated records' metadata (a test or study can then compare)."""
    out = {}
    for r in records:
        for e in r.meta.get("hidden_effects") or []:
            out.setdefault(e.get("name"), e)
    return out


def log_runs(conf: dict, doctor, rep: dict, train, validate) -> list:
    """Each ladder step as one run of the results table (study 'doctor')."""
    from .results import ResultStore, run_guarded

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
                    else:
                        metrics[f"val_{rec}_{c}"] = float(e)
            return {"metrics": metrics, "params": params, "timings": {"fit": ev.seconds}}

        rec = run_guarded(store, cfg, result, seed=None)
        ids.append(rec["run_id"])
    store.collect()
    return ids


@contextlib.contextmanager
def claimed(out: Path, overwrite: bool):
    """Hold ``out`` for one doctor while it works: a second one writing into the same folder is refused at once
    (an exclusive lock, ``<out>/.report.lock``, released when the process ends however it ends), and the folder
    is checked again for a report under the lock (another run may have finished one meanwhile)."""
    from filelock import FileLock, Timeout

    from .cli import OutputExistsError
    from .settings import existing_report

    out.mkdir(parents=True, exist_ok=True)
    lock = FileLock(str(out / ".report.lock"))
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise OutputExistsError(f"out={out}: another python -m study.diagnose is writing a report there") from None
    try:
        there = existing_report(out)
        if there and not overwrite:
            raise OutputExistsError(f"out={out}: {out} already holds {', '.join(there)}; refusing to overwrite a "
                                    "report (overwrite=true to overwrite it, or another out=)")
        yield out
    finally:
        lock.release()


def run(conf: dict) -> dict:
    """Run the doctor from a resolved config (what the CLI and the tests call)."""
    from .doctor.diagnose import Doctor, Options, write_report
    from .settings import check_diagnose
    from .sim.effects import ShallowWater, apply_effects

    out = check_diagnose(conf)  # before any work: records and out given, no report there, thresholds in range
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
                  anchor=float(conf.get("anchor") or 0.0))
    with claimed(out, bool(conf.get("overwrite"))):
        doctor = Doctor(vessel_cfg, conf["model"], train, validate, opt)
        doctor.run()
        rep = write_report(doctor, conf["out"], conf["vessel"]["name"], conf["model"]["name"],
                           overwrite=bool(conf.get("overwrite")))
    truths = _truths(train + validate)
    if truths:
        rep["hidden_effects"] = truths
    if conf.get("log_runs", True):
        rep["run_ids"] = log_runs(conf, doctor, rep, train, validate)
    return rep


@hydra.main(config_path=CONF_DIR, config_name="diagnose", version_base="1.3")
def main(cfg: DictConfig) -> None:
    with reported("study.diagnose"):  # a problem: one line on stderr and the exit status (study.cli)
        _main(OmegaConf.to_container(cfg, resolve=True))


def _main(conf: dict) -> None:
    rep = run(conf)
    out = Path(conf["out"]).resolve()
    print(rep["verdict"])

    def step(s):
        e = s.get("scored_error", s["validation_error"])
        txt = f"{s['step']} " + (f"{e:.3g}" if e == e and e != float("inf") else "diverged")
        if s.get("diverged"):
            txt += f" (diverges on {', '.join(s['diverged'])})"
        return txt + (" [rejected]" if s.get("rejected") else "")

    lad = " -> ".join(step(s) for s in rep["ladder"])
    print(f"validation error: {lad}")
    for n in rep.get("notes") or []:
        print(f"note: {n}")
    print(f"report: {out / 'report.html'} (and report.json, figures/)")


if __name__ == "__main__":
    run_hydra(main, "study.diagnose")
