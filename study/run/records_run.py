"""A study run on the user's own records: ``python -m study train=<files> [validate=<files>]
vessel=<v> model=<m> structure=<s> estimator=<e>``.

Nothing is simulated. The training records are read from files
(``study.records.schema.read_records``; HSVA's KVLCC2 ``.dat`` files and the Esso Osaka CSVs through
``study.records.loaders`` as the doctor reads them), checked against the vessel
(``study.records.vessel_checks``: rudder sign, speed against the vessel's scale, n in rps), the
model is identified on them with any structure and estimator exactly as in a simulated run (the
vessel config gives the known parts: mass, propeller, rudder, and the configured water depth
``depth``), and each validation record gets an open-loop replay of the identified model with its
measured rudder and propeller from its initial state (the doctor's replay,
``study.identify.with_effects.EffectsProblem.predict``).

What lands in the results table, and why:

- **The run's configuration** (hence its run id) holds each record's ``name`` and the ``sha256`` of
  its file's bytes under ``train`` / ``validate`` (and ``states``): a changed file is a new run, the
  same bytes moved to another folder are the same run (the paths are in the metrics ``train_files``
  / ``validate_files``). ``environment``, ``noise``, ``maneuvers`` and ``sim`` describe how a
  simulated run *makes* its data; they do not apply to files and are dropped from the configuration
  before hashing, so a sweep over them on the same files is one run, and ``cfg_noise.*`` is empty
  for file runs instead of claiming a noise level the data never had. ``checks`` decides whether a
  run starts, not what it computes: it is reported in the metric ``record_checks``. ``depth`` stays:
  it is the water depth the *model* assumes (as the doctor's ``depth``).
- **No truth**: params rows have ``truth`` None (NaN in the table) and ``truth_kind`` ``none
  (measured records)``; no ``drift_*`` and no ``truth_exact`` metric. ``config_rel_diff_median`` /
  ``_max`` give the relative difference of the estimates from the vessel config's own values (what
  the known model would use; derived K, T for a Nomoto model of a force-model vessel): a distance
  from the prior, not an error.
- **Validation**, per record ``<name>`` (file stem; parent folders added when two stems collide;
  characters other than letters, digits, ``_`` and ``-`` become ``_`` in metric names):
  ``val_<name>_diverged``, and for a replay that did not diverge (the doctor's envelope: 5 U0, 20
  U0/L) the metrics of ``study.records.metrics .prediction_metrics`` over the replayed span (the
  record's first segment up to a gap): ``val_<name>_rmse_<c>``, ``val_<name>_nrmse_<c>`` (RMSE over
  the **standard deviation of the measured channel** over that span; NaN when it is 0),
  ``_max_abs_error_<c>``, ``_cc_<c>``, ``_track_rmse``, ``_final_position_error``, for the model's
  channels (u, v, r, psi; r, psi for Nomoto); the manoeuvre metrics of
  ``study.records.maneuver_metrics`` (the replay-aware use of ``study.records.metrics``: turning
  circle: tactical diameter, advance, transfer, steady turning rate; zigzag: overshoots from the
  measured switch heading, period, initial turning time, time to check yaw) as
  ``val_<name>_measured_<metric>`` and ``val_<name>_model_<metric>``; summaries ``val_records``,
  ``val_diverged_records``, ``val_nrmse_mean`` (mean over the records that did not diverge of the
  mean NRMSE of the model's channels). Without ``validate``: ``val_skipped`` = 1 and
  ``val_skipped_reason`` says there was no held-out replay (the model is never validated on its own
  training records). A validation file with the same bytes as a training file is refused.
- **Depth**: the configured ``depth`` corrects the vessel's known parts and the model is identified
  and replayed at that one depth. A record's ``depth`` column or metadata is *not used* by the
  identification (it is by the doctor, and by ``model.effects=[shallow_water]`` here, which is the
  doctor's identification); when a record's measured h/T (below 4) differs from the configured one
  by more than 10 %, ``notes`` says so.
- **Bad input** (a pattern matching nothing, an unreadable file, a schema error, a record that fails
  the vessel checks) raises :class:`RecordsInputError` with one line naming the pattern or file, the
  column or value and what was expected, before the run starts: ``python -m study`` prints it and
  exits with status 2, and nothing is written. A run that fails after that is recorded as ``failed``
  by the store, as always.
"""
from __future__ import annotations

import glob as globmod
import hashlib
import inspect
import json
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Top-level keys of conf/config.yaml that only a run on files uses; left out of a simulated run's
#: configuration so that its run id is what it was before they existed.
FILE_KEYS = ("train", "validate", "states", "checks")
#: How a simulated run makes its data: not part of a run on files (dropped before hashing).
SIMULATION_KEYS = ("environment", "noise", "maneuvers", "sim")
#: Below this h/T a record's measured depth matters for the model (shallow-water corrections); above it a
#: mismatch with the configured depth is not noted.
SHALLOW_H_T = 4.0
DEPTH_TOLERANCE = 0.10
CHECK_MODES = ("error", "warn", "off")
TRUTH_KIND = "none (measured records)"


class RecordsInputError(ValueError):
    """The records cannot be used: one line naming the pattern or file, the column or value, and
    what was
    expected."""


@dataclass
class RecordSet:
    """The records of one role (``train`` or ``validate``): their names, files, checksums and
    contents."""

    role: str
    patterns: list
    paths: list = field(default_factory=list)
    names: list = field(default_factory=list)
    sha256: list = field(default_factory=list)
    records: list = field(default_factory=list)

    def config(self) -> list:
        return [{"name": n, "sha256": h} for n, h in zip(self.names, self.sha256)]


@dataclass
class FileData:
    """What ``load`` read: the training and validation records, the check results, the reading
    time."""

    train: RecordSet
    validate: RecordSet | None
    checks: str
    problems: list
    seconds: float


# ------------------------------------------------------------------------------------------------ reading
def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _files(role: str, pattern: str) -> list:
    """The record files of one pattern: a file, every file of a folder, or the files a glob
    matches."""
    from study.records.schema import SUPPORTED

    ok_ext = SUPPORTED + (".dat",)
    p = Path(pattern).expanduser()
    if p.is_file():
        found = [p]
    elif p.is_dir():
        found = sorted(f for f in p.iterdir() if f.is_file())
        if not found:
            raise RecordsInputError(f"{role}={pattern}: the folder holds no files; expected record files "
                                    f"({', '.join(ok_ext)})")
    else:
        found = sorted(Path(f) for f in globmod.glob(str(p)) if Path(f).is_file())
        if not found:
            raise RecordsInputError(f"{role}={pattern}: no file matches this pattern; expected record files "
                                    f"({', '.join(ok_ext)}) as a file, a folder, a glob or a comma-separated list")
    files = [f for f in found if f.suffix.lower() in ok_ext]
    if not files:
        raise RecordsInputError(f"{role}={pattern}: {len(found)} file(s) ({found[0]}, ...) but none with a record "
                                f"suffix; expected {', '.join(ok_ext)} (see docs/schema.md)")
    return files


def _read_kwargs(conf: dict) -> dict:
    """Options passed to ``study.records.schema.read_records``: ``states`` once it takes it
    (records lacking u, v, r)."""
    from study.records.schema import read_records

    states = conf.get("states") or "measured"
    if "states" in inspect.signature(read_records).parameters:
        return {"states": states}
    if states != "measured":
        raise RecordsInputError(f"states={states}: this version of study.records.schema.read_records reads measured "
                                "u, v, r only; expected states=measured")
    return {}


def _read(path: Path, read_kw: dict):
    """One record file, with any failure turned into a one-line message naming the file."""
    from study.records.loaders import is_real, load_real
    from study.records.schema import read_records

    try:
        rec = load_real(path) if is_real(path) else read_records(path, **read_kw)[0]
    except UnicodeDecodeError as e:
        raise RecordsInputError(f"{path}: not a text CSV file (undecodable byte at position {e.start}); expected "
                                "a CSV or Parquet record (docs/schema.md)") from e
    except OSError as e:
        raise RecordsInputError(f"{path}: cannot be read ({e.strerror or e})") from e
    except Exception as e:  # noqa: BLE001 - SchemaError and whatever a parser raises: the user's file is wrong
        msg = _one_line(e)
        raise RecordsInputError(msg if str(path) in msg else f"{path}: {msg}") from e
    return rec


def _unique_names(paths: list) -> list:
    """Each file's stem, with as many parent folders as it takes to tell two equal stems apart."""
    full = [Path(p).resolve().with_suffix("").parts for p in paths]
    out = []
    for i, parts in enumerate(full):
        k = 1
        while k < len(parts) and any(j != i and full[j][-k:] == parts[-k:] for j in range(len(full))):
            k += 1
        out.append("/".join(parts[-k:]))
    return out


def metric_key(name: str) -> str:
    """A record's name as it appears in metric names (``val_<key>_rmse_r``)."""
    return re.sub(r"[^0-9A-Za-z_-]+", "_", str(name)).strip("_") or "record"


def _vessel_check(conf: dict, sets: list) -> tuple[str, list]:
    """(mode, problems) of the doctor's record checks against the vessel; raises under
    ``checks=error``."""
    from study.records.vessel_checks import RecordCheckError, check_envelope, check_records

    mode = str(conf.get("checks") or "error")
    if mode not in CHECK_MODES:
        raise RecordsInputError(f"checks={mode}: expected one of {', '.join(CHECK_MODES)}")
    recs = [r for s in sets for r in s.records]
    paths = [str(p) for s in sets for p in s.paths]
    try:  # a value outside its channel's physical envelope is refused whatever checks= says
        check_envelope(conf["vessel"], recs, names=paths)
    except RecordCheckError as e:
        raise RecordsInputError(str(e)) from None
    if mode == "off":
        return mode, []
    problems = [_one_line(p) for p in check_records(conf["vessel"], recs, names=paths, strict=False)]
    if problems and mode == "error":
        others = list(dict.fromkeys(Path(p.split(": ")[0]).name for p in problems[1:]))
        more = (f" (and {len(problems) - 1} more problem(s) in {', '.join(others)}; checks=warn runs and lists "
                "them in the metric record_checks)" if others else "")
        raise RecordsInputError(f"{problems[0]}{more} [vessel={conf['vessel'].get('name')}; checks=off skips "
                                "the checks]")
    return mode, problems


def load(conf: dict) -> FileData:
    """Read, checksum and check the records named by ``conf['train']`` and ``conf['validate']``.

    Raises :class:`RecordsInputError` (one line) on any problem with the files, before anything is
    run.
    """
    from study.records.loaders import patterns

    t0 = time.perf_counter()
    read_kw = _read_kwargs(conf)
    sets = []
    for role in ("train", "validate"):
        pats = patterns(conf.get(role))
        if role == "train" and not pats:
            raise RecordsInputError(f"train={conf.get('train')!r}: no pattern given; expected a file, folder, glob "
                                    "or comma-separated list of record files")
        if not pats:
            continue
        s = RecordSet(role, pats)
        seen = {str(p.resolve()) for other in sets for p in other.paths}
        for pat in pats:
            for f in _files(role, pat):
                key = str(f.resolve())
                if key in seen:
                    continue  # the same file named twice (two patterns, or in both roles: refused below by content)
                seen.add(key)
                s.paths.append(f)
        if not s.paths:
            raise RecordsInputError(f"{role}={conf.get(role)}: every file it names is already a training record; "
                                    "expected records the model is not identified on")
        sets.append(s)
    names = _unique_names([p for s in sets for p in s.paths])
    keys = {}
    i = 0
    for s in sets:
        for p in s.paths:
            s.names.append(names[i])
            k = metric_key(names[i])
            if k in keys:
                raise RecordsInputError(f"{p}: its name '{names[i]}' reads as '{k}' in metric names, like {keys[k]}; "
                                        "rename one of the files")
            keys[k] = p
            i += 1
            try:
                s.sha256.append(hashlib.sha256(p.read_bytes()).hexdigest())
            except OSError as e:
                raise RecordsInputError(f"{p}: cannot be read ({e.strerror or e})") from e
            s.records.append(_read(p, read_kw))
    train, validate = sets[0], (sets[1] if len(sets) > 1 else None)
    if validate is not None:
        for p, h in zip(validate.paths, validate.sha256):
            if h in train.sha256:
                tp = train.paths[train.sha256.index(h)]
                raise RecordsInputError(f"validate: {p} has the same content (sha256 {h[:12]}...) as the training "
                                        f"record {tp}; expected held-out records the model is not identified on")
    mode, problems = _vessel_check(conf, sets)
    return FileData(train, validate, mode, problems, time.perf_counter() - t0)


def run_config(conf: dict, data: FileData) -> dict:
    """The configuration a run on files is stored (and its run id computed) under: the composed
    one without the simulation's axes and ``checks``, with each record's name and sha256 (see the
    module docstring)."""
    out = {k: v for k, v in conf.items() if k not in SIMULATION_KEYS + FILE_KEYS}
    out["train"] = data.train.config()
    out["validate"] = data.validate.config() if data.validate is not None else None
    out["states"] = conf.get("states") or "measured"
    return out


def check_study_name(conf: dict) -> None:
    """A run on files must not join a simulated study: its figures assume a truth and the
    simulated axes."""
    from study.configuration.compose import simulated_studies

    name = conf.get("study")
    if name in simulated_studies():
        raise RecordsInputError(f"study={name}: a simulated study (python -m study figures builds its figures from "
                                "runs with a truth); expected your own name (study=<name>) or none for a run on files")


# ---------------------------------------------------------------------------------------------- the run
def _skipped(why: str) -> dict:
    return {"status": "skipped", "error": why, "metrics": {}, "params": [], "timings": {}}


def _depth_notes(base, conf: dict, data: FileData) -> list:
    from study.identify.with_effects import record_h_T

    want = (conf.get("depth") or {}).get("h_T")
    draft = float(base.cfg["particulars"]["d"])
    notes = []
    for s in [x for x in (data.train, data.validate) if x is not None]:
        for name, rec in zip(s.names, s.records):
            h = record_h_T(rec.data, rec.meta, draft)
            if h is None or not math.isfinite(h) or h >= SHALLOW_H_T:
                continue
            if want is None or abs(h / float(want) - 1.0) > DEPTH_TOLERANCE:
                notes.append(f"record {name} was measured at h/T = {h:.3g} but the model assumes "
                             f"{'deep water' if want is None else f'h/T = {float(want):.3g}'} (depth=...; a record's "
                             "depth is not used here, model.effects=[shallow_water] uses it)")
    return notes


def _replayer(model, base, estimates: dict, records: list, names: list):
    """``replay(record, name) -> DataFrame or None``: the identified model through a record by
    the doctor's replay (measured rudder and propeller, the record's initial state; None when it
    diverged)."""
    from study.identify.with_effects import EffectsProblem, Fit

    if model.type == "kind":
        vcfg, coefs, omit = base.cfg, dict(estimates), model.cfg.get("omit") or []
    else:  # a Nomoto model: its own vessel config carries K, T, alpha
        vcfg, coefs, omit = model.model_vessel(estimates).cfg, {}, []
    pb = EffectsProblem(vcfg, {"name": model.name, "type": "kind", "equations": {}, "omit": omit},
                       [r.data for r in records], effects={}, names=names)
    fit = Fit((), {}, coefs, math.nan)
    return lambda rec, name: pb.predict(fit, rec.data, pb.info_for(rec.data, rec.meta, name))


def _validate(replay, data: FileData, channels, L: float, keep_traces: bool, metrics: dict, artefacts: dict):
    from study.records.maneuver_metrics import maneuver_metrics
    from study.records.metrics import prediction_metrics
    from study.run.common import trace_bytes

    errs, diverged = [], 0
    for name, rec in zip(data.validate.names, data.validate.records):
        key = metric_key(name)
        pred = replay(rec, name)
        if pred is None or not np.all(np.isfinite(pred[list(channels)].to_numpy())):
            metrics[f"val_{key}_diverged"] = 1.0
            diverged += 1
            continue
        metrics[f"val_{key}_diverged"] = 0.0
        pm = prediction_metrics(rec.data, pred, channels=channels)
        for k, v in pm.items():
            if np.isscalar(v):
                metrics[f"val_{key}_{k}"] = float(v)
        nr = [pm.get(f"nrmse_{c}") for c in channels]
        if all(x is not None and np.isfinite(x) for x in nr):
            errs.append(float(np.mean(nr)))
        for row in maneuver_metrics(name, rec.data, pred, None, L):
            if np.isfinite(row["measured"]) or np.isfinite(row["baseline"]):
                metrics[f"val_{key}_measured_{row['metric']}"] = float(row["measured"])
                metrics[f"val_{key}_model_{row['metric']}"] = float(row["baseline"])
        if keep_traces:
            artefacts[f"validation/{key}.csv"] = trace_bytes(rec.data, pred, channels, label="measured")
    metrics["val_records"] = float(len(data.validate.records))
    metrics["val_diverged_records"] = float(diverged)
    metrics["val_nrmse_mean"] = float(np.mean(errs)) if errs else math.nan


def _components(conf: dict):
    """The run's known vessel, model, structure and estimator configuration, as a tuple; or the
    reason the run is skipped (a str)."""
    from study.identify.models import make_model
    from study.identify.structures import make_structure
    from study.run.common import estimator_config, known_vessel, run_estimators, skip_reason
    from study.sim.effects import NotApplicable

    try:
        base = known_vessel(conf)
    except NotApplicable as e:
        return str(e)
    model = make_model(conf["model"], base)
    structure = make_structure(conf["structure"])
    est_cfg = estimator_config(conf)
    why = skip_reason(model, structure, *run_estimators(model, est_cfg))
    if why:
        return why
    return base, model, structure, est_cfg


def _records_metrics(data: FileData) -> dict:
    """The metrics that say which records the run read and how they were checked."""
    train = data.train.records
    metrics = {"data_source": "files", "train_records": float(len(train)),
               "n_samples": int(sum(len(r.data) for r in train)),
               "train_files": json.dumps([str(p) for p in data.train.paths]),
               "record_checks": data.checks + (": " + "; ".join(data.problems) if data.problems else
                                               (": passed" if data.checks != "off" else ""))}
    if data.validate is not None:
        metrics["validate_files"] = json.dumps([str(p) for p in data.validate.paths])
    return metrics


def _identify_without_truth(model, structure, est_cfg: dict, conf: dict, data: FileData, seed: int, metrics: dict,
                            timings: dict, artefacts: dict):
    """The model identified as in a simulated run, with what that run measures against a truth
    dropped (the vessel config is no truth): the params rows, the estimates and the fit's own
    ``replay(record, name)`` (None where the model is replayed from its estimates: every fit but
    that of a model with effects)."""
    from study.identify.fit import identify

    ident = identify(model, structure, est_cfg, data.train.records, seed=seed,
                     progress=bool(conf.get("progress", False)))
    timings.update(ident.timings)
    artefacts.update(ident.artefacts)
    ref = {p["name"]: p["truth"] for p in ident.params}
    # identify() measured against the vessel config as if it were a truth: those figures are dropped (the
    # term's weight on the user's records, term_scale, stays)
    params = [{**{k: v for k, v in p.items() if k != "scaled_error"}, "truth": None,
               "truth_kind": p["truth_kind"] if str(p.get("truth_kind", "")).startswith("candidate")
               else TRUTH_KIND} for p in ident.params]
    drop = ("drift_median", "drift_max", "drift_mean", "truth_exact", "prior_is_truth")  # about a truth
    metrics.update({k: v for k, v in ident.metrics.items()
                    if k not in drop and not k.startswith(("drift_", "scaled_drift_"))})
    rel = [abs(v - ref[k]) / abs(ref[k]) for k, v in ident.estimates.items()
           if v is not None and np.isfinite(v) and ref.get(k)]
    metrics["config_rel_diff_median"] = float(np.median(rel)) if rel else math.nan
    metrics["config_rel_diff_max"] = float(np.max(rel)) if rel else math.nan
    estimates = ident.estimates
    bad = sorted(k for k, v in estimates.items() if v is None or not np.isfinite(v))
    if bad:
        metrics["val_skipped"] = 1.0
        metrics["val_skipped_reason"] = f"no finite estimate of {bad}: the identified model cannot be simulated"
    replay = None if ident.replay is None else (lambda rec, name: ident.replay(rec.data, rec.meta, name))
    return params, estimates, replay


def _validate_or_skip(conf: dict, data: FileData, model, base, estimates: dict, replay, metrics: dict,
                      artefacts: dict):
    """The validation records replayed (by ``replay``, else the model with ``estimates``), or the
    metrics that say why not."""
    if data.validate is None:
        metrics["val_skipped"] = 1.0
        metrics["val_skipped_reason"] = ("no validation records (validate=null): no held-out replay was made; pass "
                                         "validate=<files> to replay the model through records it was not "
                                         "identified on")
    elif "val_skipped" not in metrics:
        if replay is None:
            replay = _replayer(model, base, estimates, data.validate.records, data.validate.names)
        keep = bool((conf.get("artefacts") or {}).get("traces", True))
        _validate(replay, data, model.channels, base.L, keep, metrics, artefacts)


def run_on_records(conf: dict, data: FileData) -> dict:
    """One run on the records ``data`` (from :func:`load`) with the composed configuration
    ``conf``; the same result dict as ``study.run.pipeline.run_study``."""
    timings = {"read": data.seconds}
    seed = int(conf.get("seed", 0))
    parts = _components(conf)
    if isinstance(parts, str):
        return _skipped(parts)
    base, model, structure, est_cfg = parts
    notes = ["data from files: nothing simulated; environment, noise, maneuvers and sim do not apply and are not in "
             "this run's configuration; no truth (params truth empty, no drift metrics)"]
    notes += _depth_notes(base, conf, data)
    metrics = _records_metrics(data)
    artefacts = {}
    estimates, replay = {}, None
    if model.type == "kind" and not model.equations and not model.effects:  # model=known: nothing to identify
        params = []
        metrics["n_params"] = 0
        notes.append("nothing identified: the model has no free coefficients (the vessel config's model is "
                     "replayed as it is)")
    else:
        params, estimates, replay = _identify_without_truth(model, structure, est_cfg, conf, data, seed, metrics,
                                                            timings, artefacts)
    metrics["notes"] = "; ".join(notes)

    t0 = time.perf_counter()
    _validate_or_skip(conf, data, model, base, estimates, replay, metrics, artefacts)
    timings["validate"] = time.perf_counter() - t0
    return {"metrics": metrics, "params": params, "timings": timings, "artefacts": artefacts}
