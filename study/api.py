"""The user's verbs: thin wrappers over the harness's own functions, offered by ``import study``.

Each verb reads its configurations by name from ``conf/`` (the same names as on the command line:
``vessel=kvlcc2`` is ``vessel="kvlcc2"``) and imports what it needs when it is called, so ``import
study`` stays fast. The names pair a verb with its object (``simulate_maneuver``,
``identify_model``): the bare verbs are taken by the package's modules and commands
(``study.identify``, ``study.records.measure``, ``python -m study simulate``, ``diagnose``).

=========================  ============================================================================
verb                       what it wraps
=========================  ============================================================================
``load_vessel``            ``study.sim.load_vessel``
``load_records``           ``study.records.loaders.load_records`` (schema files, HSVA ``.dat``, Esso Osaka CSVs)
``real_data_dir``          ``study.records.loaders.real_data_dir``
``simulate_maneuver``      ``study.sim.simulate``
``measure_record``         ``study.run.pipeline.measurement`` and ``study.records.measure.MeasurementModel.apply``
``identify_model``         ``study.identify.fit.identify`` with ``make_model`` and ``make_structure``
``predict``                ``study.sim.simulate`` of the identified model's vessel
``replay_record``          ``study.sim.replay``: open loop with a record's measured rudder and propeller
``diagnose_records``       ``study.doctor.run.run`` (what ``python -m study diagnose`` calls)
``read_results``           the results store's parquet tables
``read_posterior``         ``study.identify.posterior``: an emcee run's chains as ArviZ ``InferenceData``
=========================  ============================================================================
"""
from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Identified", "load_vessel", "load_records", "real_data_dir", "simulate_maneuver", "measure_record",
           "identify_model", "predict", "replay_record", "diagnose_records", "read_results",
           "read_posterior"]


def _vessel(vessel, effects=()):
    from .sim import Vessel, load_vessel as _load

    if isinstance(vessel, Identified):
        return vessel.vessel
    if isinstance(vessel, Vessel):
        if effects:
            raise ValueError("give effects with a vessel name or config, not with a loaded Vessel")
        return vessel
    return _load(vessel, effects)


def _frame(record):
    """The data of a record: a ``study.records.schema.Record`` or a DataFrame in the record
    schema."""
    return record.data if hasattr(record, "data") and hasattr(record, "meta") else record


def load_vessel(name, effects=()):
    """A vessel of ``conf/vessel/`` (or a config dict), with hidden effects applied in order.

    Parameters
    ----------
    name : str or dict
        A vessel config name (``kvlcc2``, ``kvlcc2_l7``, ``kcs``, ``usv_waterjet``, ``mariner``,
        ``auv``, ``kt_mariner``, ``kt1_mariner``, ``esso_osaka``) or a config dict.
    effects : sequence
        Effects of the simulator (``study.sim.effects``) or their configs, e.g.
        ``[{"name": "current", "speed": 0.1, "direction_deg": 45}]``.

    Returns
    -------
    study.sim.Vessel
        With ``name``, ``kind_name``, ``L`` (length between perpendiculars, m), ``U0`` (approach
        speed, m/s) and ``n0`` (propeller speed at U0, rps).

    Examples
    --------
    >>> import study
    >>> v = study.load_vessel("kvlcc2_l7")
    >>> v.kind_name, round(v.L, 3), round(v.U0, 3)
    ('mmg', 7.0, 1.179)
    """
    return _vessel(name, effects)


def load_records(spec, states: str = "measured", state_options: dict | None = None) -> list:
    """Records from files: a file, folder, glob, a comma-separated string of them, or a list.

    Schema files (CSV or Parquet, ``docs/schema.md``) and the real datasets' own formats (HSVA's
    ``.dat`` files, Osaka University's Esso Osaka CSVs) are read and checked for the unit mistakes
    their channels give
    away.

    Parameters
    ----------
    spec : str, path or list
        What to read.
    states : {"measured", "auto", "ekf"}
        Where u, v, r come from: the record (``measured``), estimated from positions and heading
        when the record lacks them (``auto``), or always estimated, measured ones refined (``ekf``;
        extended Kalman filter and Rauch-Tung-Striebel smoother).
    state_options : dict, optional
        The state estimator's options (``study.records.state_estimation``).

    Returns
    -------
    list of study.records.schema.Record
        Each with ``data`` (a DataFrame in the record schema), ``meta`` and ``path``.

    Examples
    --------
    HSVA's free-running KVLCC2 zigzags, where the project's shared data folder holds them
    (:func:`real_data_dir`):

    >>> import study
    >>> folder = study.real_data_dir() / "kvlcc2_hsva" / "raw_data"
    >>> recs = study.load_records(str(folder / "*Z_10_10_P.dat"))
    >>> [r.name for r in recs]
    ['HSVA_CPMC_KVLCC2_Z_10_10_P']
    >>> all(c in recs[0].data for c in ("time", "u", "v", "r", "psi", "delta", "n"))
    True
    """
    from study.records.loaders import load_records as _load

    return _load(spec, states=states, state_options=state_options)


def real_data_dir():
    """The folder of the measured records: ``$STUDY_REAL_DATA``, else the first ``shared/data/real``
    beside the checkout or a folder above it.

    Returns
    -------
    pathlib.Path
        The folder (it may not exist: the loaders then say where they looked).

    Examples
    --------
    >>> import study
    >>> study.real_data_dir().name
    'real'
    """
    from study.records.loaders import real_data_dir as _dir

    return _dir()


def simulate_maneuver(vessel, maneuver, *, effects=(), duration: float | None = None, dt: float | None = None,
                      sample_dt: float | None = None, seed: int = 0):
    """Simulate one manoeuvre: a clean record (no measurement noise) in the record schema.

    Parameters
    ----------
    vessel : str, dict, study.sim.Vessel or Identified
        A vessel config name, a config, a loaded vessel, or an identified model (its vessel).
    maneuver : str or dict
        A manoeuvre of ``conf/maneuver/`` (``zigzag_10_10``, ``zigzag_20_20``, ``turning_35``,
        ``random_rudder``, ...) or its config.
    effects : sequence
        Hidden effects of the truth (with a vessel name or config only).
    duration : float, optional
        Seconds; default: the manoeuvre's own duration for this vessel.
    dt, sample_dt : float, optional
        Integration step (default: about 1 % of L/U0, at most 0.1 s) and sampling interval (a
        multiple of it).
    seed : int
        Seed of a random rudder sequence.

    Returns
    -------
    pandas.DataFrame
        Columns ``time``, ``u``, ``v``, ``r``, ``x0``, ``y0``, ``psi``, ``delta``, ``n`` and the
        rest of the simulator's outputs, SI units and radians (``docs/conventions.md``).

    Examples
    --------
    >>> import study
    >>> rec = study.simulate_maneuver("kt_mariner", "zigzag_10_10", duration=60.0)
    >>> list(rec.columns[:8])
    ['time', 'u', 'v', 'r', 'x0', 'y0', 'psi', 'delta']
    >>> float(rec["time"].iloc[-1])
    60.0
    """
    from .sim import simulate

    v = _vessel(vessel, effects)
    return simulate(v, maneuver, dt=dt, sample_dt=sample_dt, duration=duration, seed=seed)


def measure_record(record, noise: str | dict = "low", *, vessel=None, sample_dt: float | None = None,
                   seed: int = 0):
    """Measure a clean record: sampling, sensor noise, bias, coloured noise, outliers and dropouts.

    Parameters
    ----------
    record : pandas.DataFrame or study.records.schema.Record
        A record in the schema, e.g. from :func:`simulate_maneuver`.
    noise : str or dict
        A noise config of ``conf/noise/`` (``none``, ``low``, ``medium``, ``high``,
        ``low_relative``, ...; ``docs/noise.md``) or its dict. The absolute ones choose their
        sensors by the vessel's scale.
    vessel : str, study.sim.Vessel or Identified, optional
        Needed by absolute noise (full-scale or model-scale sensors) and by ``sample_dt_LU``.
    sample_dt : float, optional
        Sampling interval [s]; default: the noise config's (``null``: the record's own).
    seed : int
        Seed of every random stream.

    Returns
    -------
    pandas.DataFrame
        The measured record.

    Examples
    --------
    >>> import study
    >>> clean = study.simulate_maneuver("kt_mariner", "zigzag_10_10", duration=60.0)
    >>> noisy = study.measure_record(clean, "low_relative", sample_dt=0.5, seed=1)
    >>> len(clean), len(noisy)
    (601, 121)
    >>> bool((noisy["psi"] != clean["psi"].iloc[::5].to_numpy()).all())
    True
    """
    from study.configuration.compose import read_config
    from study.run.pipeline import measurement

    nz = dict(read_config("noise", noise) if isinstance(noise, str) else noise)
    if sample_dt is not None:
        nz.update(sample_dt=float(sample_dt), sample_dt_LU=None)
    v = _vessel(vessel) if vessel is not None else None
    return measurement({"noise": nz}, seed=seed, vessel=v).apply(_frame(record))


@dataclass
class Identified:
    """An identified model: what :func:`identify_model` returns.

    Attributes
    ----------
    estimates : dict
        Physical parameter name -> estimate (Nomoto models: ``K``, ``T``, ``alpha``, ...; force
        models their non-dimensional coefficients).
    params : pandas.DataFrame
        One row per identified coefficient, the columns of ``params.parquet``: ``equation``,
        ``name``, ``estimate``, ``truth`` (the vessel config's value), ``rel_error``, interval
        columns when the estimator gives one.
    metrics : dict
        The run's metrics (``m_*`` columns of ``runs.parquet`` without the prefix), e.g.
        ``drift_median``.
    vessel : study.sim.Vessel or None
        The model as a vessel to simulate (None when an estimate is not finite).
    model : object
        The identification model (``study.identify.models``).
    draws : dict
        Posterior draws per parameter (emcee), at most 200.
    """

    estimates: dict
    params: object
    metrics: dict
    vessel: object
    model: object
    draws: dict = field(default_factory=dict)


def identify_model(records, vessel, model: str | dict = "mmg_hull", structure: str | dict = "central",
                   estimator: str | dict = "ls", *, params: dict | None = None, seed: int = 0,
                   progress: bool = False) -> Identified:
    """Identify a model from records with a sample structure and an estimator, as one run of
    ``python -m study``.

    Parameters
    ----------
    records : list of pandas.DataFrame or study.records.schema.Record
        Training records in the schema (measured, or from :func:`measure_record`).
    vessel : str, dict or study.sim.Vessel
        The vessel whose known parts (mass, propeller, rudder) the model keeps; its coefficients are
        the ``truth`` column (exact when the records were simulated from it).
    model : str or dict
        What is identified: ``mmg_hull``, ``mmg_simplified``, ``usv_full``, ``abkowitz``, ``auv``,
        ``nomoto1``, ``nomoto1_nl``, ``nomoto2``, ``nomoto2_nl`` (``conf/model/``).
    structure : str or dict
        How records become samples: ``euler``, ``central``, ``integral``, ``smoothed``,
        ``diff_center``, ``output_error`` (``conf/structure/``).
    estimator : str or dict
        ``ls``, ``ridge``, ``lasso``, ``lssvm``, ``tlssvm``, ``lssvm_online``, ``svr_eps``,
        ``svr_nu``, ``sindy``, ``de``, ``emcee``, ``map`` (``conf/estimator/``).
    params : dict, optional
        Hyper-parameters merged into the estimator's ``params`` (e.g. ``{"target_ess": 400}``).
    seed : int
        Seed of the estimator's random streams.
    progress : bool
        A progress bar for DE and emcee.

    Returns
    -------
    Identified

    Raises
    ------
    ValueError
        When the combination cannot run (e.g. a regression estimator on ``output_error``), with the
        reason.

    Examples
    --------
    The first-order nonlinear Nomoto model of the Mariner (``kt1_mariner``: that model is its truth)
    from a noise-free 10/10 zigzag, least squares on central differences:

    >>> import study
    >>> rec = study.simulate_maneuver("kt1_mariner", "zigzag_10_10")
    >>> fit = study.identify_model([rec], "kt1_mariner", model="nomoto1_nl", structure="central")
    >>> sorted(fit.estimates)
    ['K', 'T', 'alpha']
    >>> bool(fit.params["rel_error"].abs().max() < 0.01)
    True
    """
    import pandas as pd

    from study.configuration.compose import read_config
    from .identify.estimators import make_estimator
    from .identify.fit import identify
    from .identify.models import make_model
    from .identify.structures import make_structure
    from study.run.common import skip_reason

    base = _vessel(vessel)
    mdl = make_model(model, base)
    st = make_structure(structure)
    est_cfg = dict(read_config("estimator", estimator) if isinstance(estimator, str) else estimator)
    if params:
        est_cfg["params"] = {**(est_cfg.get("params") or {}), **params}
    why = skip_reason(mdl, st, make_estimator(est_cfg))
    if why:
        raise ValueError(f"model {mdl.name if hasattr(mdl, 'name') else model} with structure {st.name} and "
                         f"estimator {est_cfg.get('name')}: {why}")
    res = identify(mdl, st, est_cfg, [_frame(r) for r in records], seed=seed, progress=progress)
    rows = pd.DataFrame(res.params)
    if "truth" in rows:  # as params.parquet has it (python -m study results): NaN where the truth is unknown or zero
        t = pd.to_numeric(rows["truth"], errors="coerce")
        rows["rel_error"] = (pd.to_numeric(rows["estimate"], errors="coerce") - t) / t.abs().where(t != 0)
    finite = all(v is not None and v == v and abs(v) != float("inf") for v in res.estimates.values())
    return Identified(estimates=dict(res.estimates), params=rows, metrics=dict(res.metrics),
                      vessel=mdl.model_vessel(res.estimates) if finite else None, model=mdl, draws=dict(res.draws))


def predict(identified: Identified, maneuver, *, duration: float | None = None, dt: float | None = None,
            seed: int = 0):
    """Simulate an identified model through a manoeuvre (closed loop: its own zigzag or turn).

    Parameters
    ----------
    identified : Identified
        From :func:`identify_model`.
    maneuver : str or dict
        A manoeuvre of ``conf/maneuver/``, e.g. a held-out ``zigzag_35_35`` or ``turning_35``.
    duration, dt : float, optional
        As in :func:`simulate_maneuver`.
    seed : int
        Seed of a random rudder sequence.

    Returns
    -------
    pandas.DataFrame
        The predicted record.

    Examples
    --------
    >>> import study
    >>> rec = study.simulate_maneuver("kt1_mariner", "zigzag_10_10")
    >>> fit = study.identify_model([rec], "kt1_mariner", model="nomoto1_nl", structure="central")
    >>> pred = study.predict(fit, "zigzag_20_20", duration=200.0)
    >>> truth = study.simulate_maneuver("kt1_mariner", "zigzag_20_20", duration=200.0)
    >>> bool(abs(pred["psi"] - truth["psi"]).max() < 0.01)  # rad
    True
    """
    if identified.vessel is None:
        raise ValueError("the identified model has a non-finite estimate and cannot be simulated: "
                         f"{identified.estimates}")
    return simulate_maneuver(identified.vessel, maneuver, duration=duration, dt=dt, seed=seed)


def replay_record(vessel, record, *, substeps: int = 1):
    """Replay a model open loop through a record: its measured rudder (as the steering gear's
    command) and propeller speed, from its first state.

    Parameters
    ----------
    vessel : str, dict, study.sim.Vessel or Identified
        The model to replay.
    record : pandas.DataFrame or study.records.schema.Record
        A uniformly sampled record with ``time``, ``u``, ``v``, ``r``, ``x0``, ``y0``, ``psi``,
        ``delta`` and ``n`` (without ``n``: the vessel's ``n0``).
    substeps : int
        Integration steps per sampling interval.

    Returns
    -------
    pandas.DataFrame
        The replay on the record's time base.

    Examples
    --------
    A vessel replayed through its own simulated turn follows it:

    >>> import study
    >>> rec = study.simulate_maneuver("kvlcc2_l7", "turning_35", duration=60.0)
    >>> rep = study.replay_record("kvlcc2_l7", rec)
    >>> bool(abs(rep["r"] - rec["r"]).max() < 1e-3)
    True
    """
    import numpy as np

    from .sim import replay, to_frame

    v = _vessel(vessel)
    df = _frame(record)
    t = df["time"].to_numpy(float)
    n = df["n"].to_numpy(float) if "n" in df else np.full(len(t), v.n0)
    state0 = [float(df[c].iloc[0]) for c in ("u", "v", "r", "x0", "y0", "psi")]
    out = replay(v, t, df["delta"].to_numpy(float), n, state0, substeps=substeps)
    return to_frame(out, t)


def diagnose_records(train, validate=None, *, vessel: str = "kvlcc2_l7", model: str = "known",
                     out="doctor_report", overwrite: bool = False, candidates=None, **settings) -> dict:
    """The model doctor: where a model fails against measured records, and which physical effect is
    missing.

    The same as ``python -m study diagnose train=... validate=... vessel=... model=... out=...``:
    the report is written to ``out`` (``report.json``, ``report.html``, ``figures/``) and returned
    as a dict. Its runs are not logged in a results table unless ``log_runs=True`` is given.

    Parameters
    ----------
    train, validate : str or list
        Record files: a file, folder, glob or a list (as :func:`load_records`); without ``validate``
        each training record is held out in turn.
    vessel : str
        The vessel config whose coefficients are the model (or its prior).
    model : str
        ``known`` (the vessel config as it is) or a force model to identify (``mmg_hull``, ...),
        anchored to the vessel config's coefficients (``anchor=0.3``).
    out : str or path
        The report folder; one holding a report is refused unless ``overwrite=True``.
    candidates : list of str, optional
        The candidate effects (``conf/effect/``); default: every one found.
    **settings
        Any other key of ``conf/diagnose.yaml`` (``anchor``, ``min_improvement``, ``max_steps``,
        ``states``, ``effect_path``, ...).

    Returns
    -------
    dict
        The report: ``verdict``, ``missing_effect``, ``baseline``, ``ranking``, ``ladder``, ...

    Examples
    --------
    Two short records of the 7 m KVLCC2 with a hidden yaw bias, the doctor choosing between a yaw
    bias and a
    current:

    >>> import tempfile, pathlib
    >>> import study
    >>> from study.records.schema import Record, write_record
    >>> bias = [{"name": "yaw_bias", "Y": 0.0, "N": -7e-4}]
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for m in ("zigzag_20_20", "turning_35"):
    ...     rec = study.measure_record(study.simulate_maneuver("kvlcc2_l7", m, effects=bias, duration=120.0),
    ...                                "low_relative", sample_dt=0.2)
    ...     _ = write_record(Record(rec, {"name": m}), d / f"{m}.csv")
    >>> rep = study.diagnose_records(str(d / "zigzag*.csv"), str(d / "turning*.csv"), vessel="kvlcc2_l7",
    ...                              out=d / "report", candidates=["yaw_bias", "current"])
    >>> rep["missing_effect"]
    'yaw_bias'
    """
    from .doctor.run import diagnose_conf, run

    conf = diagnose_conf(vessel=vessel, model=model)
    conf.update(train=train if isinstance(train, (list, tuple)) else str(train),
                validate=None if validate is None else (validate if isinstance(validate, (list, tuple))
                                                        else str(validate)),
                out=str(out), overwrite=bool(overwrite), candidates=None if candidates is None else list(candidates))
    conf.update(settings)
    return run(conf)


def read_results(results_dir="results", table: str = "runs"):
    """A table of the results store: ``runs`` (one row per run) or ``params`` (one row per
    identified coefficient), safe to read while a sweep is writing.

    Parameters
    ----------
    results_dir : str or path
        The results folder (``results/`` in the folder the commands run from, or ``results_dir=`` /
        ``STUDY_RESULTS_DIR``).
    table : {"runs", "params"}
        Which table.

    Returns
    -------
    pandas.DataFrame
        ``runs``: ``run_id``, ``status``, ``cfg_*`` (the configuration), ``m_*`` (metrics), ``t_*``
        (timings); ``params``: ``run_id``, ``equation``, ``name``, ``estimate``, ``truth``,
        ``rel_error``, ...

    Raises
    ------
    FileNotFoundError
        When the folder has no such table (no run finished there yet).

    Examples
    --------
    The table of the study ``seed000_svr_mmg``, committed with its figures in ``paper_figs/``:

    >>> import pathlib
    >>> import study
    >>> table = pathlib.Path(study.__file__).parents[1] / "paper_figs" / "seed000_svr_mmg" / "table"
    >>> runs = study.read_results(table)
    >>> int((runs["status"] == "ok").sum()) > 0 and "m_drift_median" in runs
    True
    >>> params = study.read_results(table, "params")
    >>> {"run_id", "name", "estimate", "truth", "rel_error"} <= set(params.columns)
    True
    """
    from pathlib import Path

    from .store import read_table

    if table not in ("runs", "params"):
        raise ValueError(f"table={table!r}: expected 'runs' or 'params'")
    path = Path(results_dir) / f"{table}.parquet"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no {table} table (no run has finished in {results_dir})")
    return read_table(path)


def read_posterior(results_dir, run_id: str):
    """An emcee run's posterior as ArviZ ``InferenceData``: every equation's chain joined into one
    posterior (``<equation>.<coefficient>``; walkers as chains, as ``arviz.from_emcee`` takes them),
    the log posterior in ``sample_stats``, the run id in the attributes. ``arviz.summary(idata)``
    gives r-hat and ESS; ``idata.to_netcdf(path)`` writes it (``python -m study results posterior
    <run id> --out file.nc`` does both).

    Parameters
    ----------
    results_dir : str or path
        The results folder (or a study's committed table folder, which keeps its runs' chains).
    run_id : str
        The run (``runs.parquet``'s ``run_id``).

    Raises
    ------
    FileNotFoundError
        The run saved no chain (not an emcee run, or its artefacts are not in this folder).

    Examples
    --------
    An emcee run of the committed study ``emcee_kt`` (Nomoto K, T, alpha of the KT Mariner):

    >>> import pathlib, warnings
    >>> import study
    >>> table = pathlib.Path(study.__file__).parents[1] / "paper_figs" / "emcee_kt" / "table"
    >>> run = sorted(p.name for p in (table / "artefacts").iterdir() if (p / "chain.npz").exists())[0]
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     idata = study.read_posterior(table, run)
    >>> {"K", "T", "alpha"} <= set(idata.posterior.data_vars)
    True
    >>> idata.attrs["run_id"] == run
    True
    """
    from pathlib import Path

    from .identify.posterior import inference_data, run_chains

    folder = Path(results_dir) / "artefacts" / str(run_id)
    chains = run_chains(folder)
    if not chains:
        raise FileNotFoundError(f"{folder}: no chain.npz (run {run_id} is not an emcee run, or its artefacts are "
                                f"not in {results_dir})")
    return inference_data(chains, {"run_id": str(run_id)})
