"""One run of the study, independent of Hydra: simulate -> measure -> identify -> validate (or, with
``train=<files>``, read -> identify -> replay through the validation records:
``study.run.records_run``).

``run_study(conf)`` takes the resolved configuration as a plain dict (what the Hydra app passes, and
what tests build with ``compose``) and returns the run's result: metrics, per-parameter estimates
against truth, timings. :class:`SimulatedJob` is the same run for many independent datasets of one
configuration (``replicates=N``): the noise-free truth is simulated once, each dataset draws its own
measurement noise (and its own random rudder signal), and the identified models are replayed through
each validation manoeuvre in one batch. The executor (``study.run.executor``) claims, resumes and
records each dataset as a run of its own.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from study.sim import maneuvers as man_mod
from study.records.measure import NOISE_KINDS, MeasurementModel, sensor_sd
from study.records.metrics import prediction_metrics, standard_metrics
from study.run.common import estimator_config, known_vessel, run_estimators, shallow_water, skip_reason, trace_bytes
from study.sim import default_dt, load_vessel, simulate
from study.sim.effects import NotApplicable


def resolve_effects(effects: list, U0: float) -> list[dict]:
    """Copy effect configs, turning keys ending in ``_U0`` (fractions of the service speed) into
    m/s."""
    out = []
    for e in effects or []:
        e = dict(e)
        for k in [k for k in e if k.endswith("_U0")]:
            e[k[: -len("_U0")]] = float(e.pop(k)) * U0
        out.append(e)
    return out


def vessels_for(conf: dict):
    """(truth vessel with depth + environment, model vessel with depth only).

    The model vessel is what the engineer knows: the depth (measured) but not the current or wind,
    and not the coefficients being identified.
    """
    U0 = float(conf["vessel"]["operation"]["U0"])
    env_effects = resolve_effects((conf.get("environment") or {}).get("effects", []), U0)
    truth = load_vessel(conf["vessel"], [shallow_water(conf), *env_effects])
    return truth, known_vessel(conf)


def _level(x):
    """A noise level: one fraction for every channel, or a dict channel -> fraction."""
    return {k: float(v) for k, v in x.items()} if isinstance(x, dict) else float(x or 0.0)


def time_scale(vessel) -> float | None:
    """The ship's own time scale L/U0 [s] (the time it takes to travel its length), or None
    without a length."""
    L = ((getattr(vessel, "cfg", None) or {}).get("particulars") or {}).get("Lpp")
    U = float(getattr(vessel, "U0", 0.0) or 0.0)
    return float(L) / U if L and U > 0 else None


def sample_interval(conf: dict, vessel=None) -> float | None:
    """The records' sampling interval [s]: ``noise.sample_dt`` (seconds) or
    ``noise.sample_dt_LU`` (in the ship's time scale L/U0, so studies of ships of different size
    and speed sample alike), rounded to a whole multiple of the simulation step (records are
    decimated from the simulation, never interpolated between its steps). None: every step. Both
    given, or a value that is not positive, is an error naming the setting."""
    nz = conf.get("noise") or {}
    dt_s, dt_lu = nz.get("sample_dt"), nz.get("sample_dt_LU")
    if dt_s is not None and dt_lu is not None:
        raise ValueError(f"noise.sample_dt={dt_s} and noise.sample_dt_LU={dt_lu}: give one of them")
    if dt_lu is None:
        return None if dt_s is None else float(dt_s)
    if not float(dt_lu) > 0:
        raise ValueError(f"noise.sample_dt_LU={dt_lu}: expected a positive interval in units of L/U0")
    T = time_scale(vessel) if vessel is not None else None
    if T is None:
        raise ValueError(f"noise.sample_dt_LU={dt_lu}: vessel '{getattr(vessel, 'name', '?')}' has no length and "
                         f"speed (particulars.Lpp, operation.U0) to scale it; give noise.sample_dt in seconds")
    step = float((conf.get("sim") or {}).get("dt") or default_dt(vessel))
    return step * max(1, round(float(dt_lu) * T / step))


def vessel_scale(vessel) -> str:
    """``full`` or ``model``: the vessel config's ``scale`` (full when it says nothing)."""
    scale = str(((getattr(vessel, "cfg", None) or {}).get("scale")) or "full")
    if scale not in ("full", "model"):
        raise ValueError(f"vessel '{getattr(vessel, 'name', '?')}': scale={scale!r}; expected 'full' or 'model'")
    return scale


def noise_sd(conf: dict, vessel=None) -> dict | None:
    """The absolute white-noise standard deviation per channel (SI, rad) of a ``kind: absolute``
    noise config: its ``full_scale`` or ``model_scale`` sensors, by the vessel's ``scale``; None
    for the relative kind."""
    nz = conf.get("noise") or {}
    kind = nz.get("kind", "relative")
    if kind not in NOISE_KINDS:
        raise ValueError(f"noise.kind={kind!r}: expected one of {list(NOISE_KINDS)}")
    if kind == "relative":
        return None
    if nz.get("level"):
        raise ValueError(f"noise '{nz.get('name')}': kind absolute takes standard deviations per sensor "
                         f"(full_scale, model_scale), not level={nz.get('level')}; use kind: relative for that")
    key = f"{vessel_scale(vessel)}_scale"
    if key not in nz:
        raise ValueError(f"noise '{nz.get('name')}': no '{key}' sensors for vessel "
                         f"'{getattr(vessel, 'name', '?')}' (scale: {vessel_scale(vessel)})")
    return sensor_sd(nz[key], where=f"noise.{key}")


def measurement(conf: dict, seed: int, vessel=None) -> MeasurementModel:
    """The measurement model of a run: ``conf['noise']`` of ``kind: relative`` (``level``:
    fractions of each channel's RMS) or ``kind: absolute`` (sensor standard deviations in
    physical units, at the vessel's scale)."""
    nz = dict(conf.get("noise") or {})
    sd = noise_sd(conf, vessel)
    return MeasurementModel(
        dt=sample_interval(conf, vessel), noise_level=0.0 if sd is not None else _level(nz.get("level", 0.0)),
        noise_sd=sd, bias=nz.get("bias") or {}, colored=nz.get("colored"), outliers=nz.get("outliers"),
        dropouts=nz.get("dropouts"), seed=seed,
    )


def simulate_set(vessel, names, conf, seed_base, only=None):
    """Each manoeuvre of ``names`` (only those in ``only``, when given), manoeuvre ``i``
    simulated with seed ``seed_base + i`` (its random signal, where it has one)."""
    sim = conf.get("sim") or {}
    dt = sim.get("dt") or default_dt(vessel)
    out = {}
    for i, name in enumerate(names):
        if only is not None and name not in only:
            continue
        man = man_mod.get_maneuver(name)
        T = man.duration_for(vessel) * float(sim.get("duration_scale", 1.0))
        out[name] = simulate(vessel, man, dt=dt, duration=T, seed=seed_base + i)
    return out


def _predictive_band(model, draws: dict, maneuver: str, meas, conf, seed, max_rows: int = 600):
    """The posterior-predictive band of one validation manoeuvre: every draw simulated in one
    batch call (each closing its own controller), the 5 %, 50 % and 95 % quantiles of each
    predicted channel, as CSV. None when no draw can be simulated."""
    from study.sim import simulate_batch

    names = list(draws)
    n = len(draws[names[0]])
    vessels = []
    for i in range(n):
        d = {k: float(draws[k][i]) for k in names}
        if all(np.isfinite(list(d.values()))):
            try:
                vessels.append(model.model_vessel(d))
            except ValueError:  # e.g. a draw with a negative time constant the model cannot take
                continue
    if not vessels:
        return None
    P = np.column_stack([v.params for v in vessels])
    man = man_mod.get_maneuver(maneuver)
    sim = conf.get("sim") or {}
    T = man.duration_for(vessels[0]) * float(sim.get("duration_scale", 1.0))
    t, out = simulate_batch(vessels[0], man, P, dt=sim.get("dt") or default_dt(vessels[0]), duration=T,
                            seed=1000 * seed + 500)
    step = max(1, int(np.ceil(len(t) / max_rows)))
    cols = {"time": t[::step]}
    from study.sim.core import OUT_NAMES

    tm = meas["time"].to_numpy()
    for c in model.channels:
        Y = out[::step, OUT_NAMES.index(c), :]
        ok = np.all(np.isfinite(Y), axis=0)
        if not ok.any():
            return None
        q = np.quantile(Y[:, ok], [0.05, 0.5, 0.95], axis=1)
        cols[f"truth_{c}"] = np.interp(t[::step], tm, meas[c].to_numpy())
        cols[f"q05_{c}"], cols[f"q50_{c}"], cols[f"q95_{c}"] = q
    cols["draws"] = np.full(len(cols["time"]), int(len(vessels)))
    return pd.DataFrame(cols).to_csv(index=False, float_format="%.7g").encode("utf-8")


def study_config(conf: dict) -> tuple[dict, object]:
    """``(run configuration, records)`` of a composed configuration: what the results store records
    (and hashes into the run id), and the records read from files (None for a simulated run).

    Without ``train`` the run configuration is ``conf`` without the file keys (``train``,
    ``validate``, ``states``, ``checks``: ``study.run.records_run.FILE_KEYS``), so a simulated run
    keeps the run id it had before they existed. With ``train`` the files are read, checksummed and
    checked (``study.run.records_run.load``; a problem raises ``RecordsInputError``, one line) and
    the configuration holds the records' names and sha256 instead of the simulation's axes
    (``study.run.records_run.run_config``).
    """
    from study.run.records_run import FILE_KEYS, RecordsInputError, check_study_name, load, run_config

    if conf.get("train") is None:
        if conf.get("validate") is not None:
            raise RecordsInputError(f"validate={conf['validate']}: validation records need training records "
                                    "(train=<files>); a simulated run validates on maneuvers.validate")
        return {k: v for k, v in conf.items() if k not in FILE_KEYS}, None
    check_study_name(conf)
    data = load(conf)
    return run_config(conf, data), data


def _skipped(why: str) -> dict:
    return {"status": "skipped", "error": why, "metrics": {}, "params": [], "timings": {}}


@dataclass
class _Identified:
    """One dataset identified: what :meth:`SimulatedJob.finish` validates."""

    rep: object
    ident: object
    metrics: dict
    timings: dict
    artefacts: dict
    vessel: object = None  # the identified model's vessel when the fit made one (a model with effects)


class SimulatedJob:
    """Simulate -> measure -> identify -> validate, for any number of datasets of one configuration.

    The shared work (:meth:`prepare`: vessels, model, structure, estimator, the noise-free training
    records of every manoeuvre that has no random signal, the validation truth and its metrics) is
    done once; each dataset (:meth:`identify`) re-simulates only the random-rudder manoeuvres with
    its own signal, measures every record with its own noise and identifies; :meth:`finish` replays
    the identified models of a chunk of datasets through each validation manoeuvre in one batch call
    of the integrator.

    Seeds: dataset seed ``s`` (``study.run.executor.dataset_seed``; the configuration's ``seed`` for
    replicate 0) draws the random rudder signal of training manoeuvre ``i`` from ``1000 s + i`` and
    its measurement noise from ``7919 s + i``; the estimator's own randomness from ``s``. The
    validation manoeuvres are the configuration's (``1000 seed + 500``), the same for every dataset.
    """

    def __init__(self, conf: dict):
        self.conf = conf
        self.seed = int(conf.get("seed", 0))

    # -- shared by every dataset
    def prepare(self) -> dict | None:
        from study.identify.models import make_model
        from study.identify.structures import make_structure

        conf, t0 = self.conf, time.perf_counter()
        try:
            self.truth, self.base = vessels_for(conf)
        except NotApplicable as e:  # e.g. shallow water on a Nomoto model: nothing for the effect to act on
            return _skipped(str(e))
        self.model = make_model(conf["model"], self.base)
        self.structure = make_structure(conf["structure"])
        self.est_cfg = estimator_config(conf)
        why = skip_reason(self.model, self.structure, *run_estimators(self.model, self.est_cfg))
        if why:
            return _skipped(why)
        mans = conf["maneuvers"]
        self.train_names = list(mans["train"])
        self.random = {n for n in self.train_names if man_mod.get_maneuver(n).type == "random"}
        fixed = [n for n in self.train_names if n not in self.random]
        # a manoeuvre without a random signal is the same truth for every dataset: simulated once
        clean = simulate_set(self.truth, self.train_names, conf, seed_base=1000 * self.seed, only=fixed)
        self.clean_fixed = clean
        step = float((conf.get("sim") or {}).get("dt") or default_dt(self.truth))
        sample_dt = sample_interval(conf, self.truth) or step
        T_ship = time_scale(self.truth)
        self.sampling = {"sample_dt": sample_dt, "sample_dt_LU": sample_dt / T_ship if T_ship else float("nan")}
        self.t_simulate_fixed = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.truth_val = simulate_set(self.truth, mans["validate"], conf, seed_base=1000 * self.seed + 500)
        self.truth_val_metrics = {name: _standard(df, self.truth.L) for name, df in self.truth_val.items()}
        self.t_validate_truth = time.perf_counter() - t0
        return None

    # -- one dataset
    def dataset(self, dseed: int) -> tuple[list, dict]:
        """The measured training records of dataset seed ``dseed`` and their timings."""
        conf, timings = self.conf, {}
        t0 = time.perf_counter()
        clean = dict(self.clean_fixed)
        if self.random:
            clean.update(simulate_set(self.truth, self.train_names, conf, seed_base=1000 * dseed,
                                      only=sorted(self.random)))
        timings["simulate_train"] = time.perf_counter() - t0 + self.t_simulate_fixed
        t0 = time.perf_counter()
        records = [measurement(conf, seed=dseed * 7919 + i, vessel=self.truth).apply(clean[name])
                   for i, name in enumerate(self.train_names)]
        timings["measure"] = time.perf_counter() - t0
        return records, timings

    def identify(self, rep) -> _Identified:
        from study.identify.fit import identify

        dseed = int(getattr(rep, "dataset_seed", self.seed))
        records, timings = self.dataset(dseed)
        metrics = {"n_samples": int(sum(len(r) for r in records)), **self.sampling}
        ident = identify(self.model, self.structure, self.est_cfg, records, seed=dseed,
                         progress=bool(self.conf.get("progress", False)), truth_vessel=self.truth)
        timings.update(ident.timings)
        metrics.update(ident.metrics)
        return _Identified(rep, ident, metrics, timings, dict(ident.artefacts), ident.vessel)

    # -- validation of a chunk of datasets
    def finish(self, done: list) -> list[dict]:
        conf = self.conf
        names = list(self.truth_val)
        chans = self.model.channels
        keep_traces = bool((conf.get("artefacts") or {}).get("traces", True))
        t0 = time.perf_counter()
        for d in done:
            bad = sorted(k for k, v in d.ident.estimates.items() if v is None or not np.isfinite(v))
            if bad:  # e.g. Nomoto T1, T2 of a complex pole pair, or T = -1/0 when a selector dropped r
                d.metrics["val_skipped"] = 1.0
                d.metrics["val_skipped_reason"] = f"no finite estimate of {bad}: the identified model cannot be " \
                                                  "simulated"
        live = [d for d in done if "val_skipped" not in d.metrics]
        vessels = [d.vessel or self.model.model_vessel(d.ident.estimates) for d in live]
        preds = self._replay(vessels, names)
        share = (time.perf_counter() - t0) / max(1, len(done))
        for d, pred_val in zip(live, preds):
            t1 = time.perf_counter()
            for name in names:
                meas, pred = self.truth_val[name], pred_val[name]
                m = d.metrics
                if not np.all(np.isfinite(pred[list(chans)].to_numpy())):
                    m[f"val_{name}_diverged"] = 1.0
                    continue
                m[f"val_{name}_diverged"] = 0.0
                for k, v in prediction_metrics(meas, pred, channels=chans).items():
                    if np.isscalar(v):
                        m[f"val_{name}_{k}"] = float(v)
                for k, v in self.truth_val_metrics[name].items():
                    m[f"val_{name}_truth_{k}"] = v
                for k, v in _standard(pred, self.truth.L).items():
                    m[f"val_{name}_model_{k}"] = v
                if keep_traces:
                    d.artefacts[f"validation/{name}.csv"] = trace_bytes(meas, pred, chans)
                if d.ident.draws and keep_traces:
                    band = _predictive_band(self.model, d.ident.draws, name, meas, conf, self.seed)
                    if band is not None:
                        d.artefacts[f"validation/{name}_band.csv"] = band
            d.timings["validate"] = share + time.perf_counter() - t1 + self.t_validate_truth
        for d in done:
            d.timings.setdefault("validate", share)
        return [{"metrics": d.metrics, "params": d.ident.params, "timings": d.timings, "artefacts": d.artefacts}
                for d in done]

    def _replay(self, vessels: list, names: list) -> list[dict]:
        """Each identified model through each validation manoeuvre: one batch call of the
        integrator per manoeuvre when the models differ only in their parameters (a model with
        effects is replayed alone)."""
        if not vessels:
            return []
        v0 = vessels[0]
        same = all(v.kind_name == v0.kind_name and len(v.params) == len(v0.params) and v.U0 == v0.U0
                   and v.n0 == v0.n0 and np.array_equal(np.asarray(v.env), np.asarray(v0.env)) for v in vessels)
        if not same:
            return [simulate_set(v, names, self.conf, seed_base=1000 * self.seed + 500) for v in vessels]
        from study.sim import simulate_batch, to_frame

        sim = self.conf.get("sim") or {}
        P = np.column_stack([v.params for v in vessels])
        out: list = [dict() for _ in vessels]
        for i, name in enumerate(names):
            man = man_mod.get_maneuver(name)
            T = man.duration_for(vessels[0]) * float(sim.get("duration_scale", 1.0))
            t, Y = simulate_batch(vessels[0], man, P, dt=sim.get("dt") or default_dt(vessels[0]), duration=T,
                                  seed=1000 * self.seed + 500 + i)
            for j in range(len(vessels)):
                out[j][name] = to_frame(Y, t, j)
        return out


def _standard(df, L) -> dict:
    """The standard manoeuvre metrics of a record as floats (those it cannot carry, e.g. too
    short, absent)."""
    try:
        return {k: float(v) for k, v in standard_metrics(df, L=L).items()
                if np.isscalar(v) and not isinstance(v, str)}
    except ValueError:
        return {}


def run_study(conf: dict, data=None) -> dict:
    """Run one configuration on one dataset; returns ``{'metrics', 'params', 'timings',
    'artefacts'}`` or a skipped result ``{'status': 'skipped', 'error': reason}`` for a combination
    that makes no sense.

    With ``conf['train']`` set the run is on the user's records (``study.run.records_run``):
    ``data`` are the records ``study_config`` read (read here when None)."""
    from study.run.settings import check_run

    check_run(conf)  # a setting that makes no sense is refused, named (the app checks it before any work too)
    if conf.get("train") is not None:
        from study.run.records_run import load, run_on_records

        return run_on_records(conf, data if data is not None else load(conf))
    job = SimulatedJob(conf)
    skipped = job.prepare()
    if skipped is not None:
        return skipped
    return job.finish([job.identify(None)])[0]
