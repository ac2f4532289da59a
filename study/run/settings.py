"""Settings checked before any work: a value that makes no sense is refused, naming the setting.

Zero does not mean "unset" (``null`` does): ``sim.dt=0`` or ``sim.duration=0`` used to run silently
with the defaults, and a negative value failed deep inside numpy ("negative dimensions are not
allowed") naming nothing. Each check here raises :class:`study.configuration.cli.ConfigError` (a
``ValueError``) with ``<setting>=<value>: expected <what>``, so every command refuses in one line
with exit status 2 before it simulates, reads or writes anything.

- :func:`check_run`: a study run (``python -m study``; the sweeper checks every composed job of a
  sweep with it before launching any).
- :func:`check_simulate`: ``python -m study simulate`` (also that ``out=`` is given, is a record
  file and is not there already).
- :func:`check_diagnose`: ``python -m study diagnose`` (``train=`` and ``out=`` given, the doctor's
  thresholds).

Every enumerated setting of every command is in one table, :data:`ENUMS`, checked by
:func:`check_enums` (a value outside it used to act like another one: the doctor's ``checks=eror``
as ``warn``). Settings that make a run impossible together (an integration step longer than the
ship's time scale, a sampling interval shorter than the step) are checked against each other
(:func:`check_together`), and the folders a command writes are proven writable (:func:`writable`)
before any work.
"""
from __future__ import annotations

import math
import numbers
from pathlib import Path

from study.configuration.cli import ConfigError, OutputExistsError

#: Hydra's marker of a mandatory value nobody gave
MISSING = "???"


def _is_number(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def number(conf: dict, key: str, *, minimum: float | None = None, above: float | None = None,
           below: float | None = None, optional: bool = True, integer: bool = False) -> None:
    """Check the setting ``key`` (dotted) of ``conf``: a finite number (an integer if
    ``integer``), ``>= minimum``, ``> above`` and ``< below`` where given; ``None``/absent passes
    when ``optional``."""
    node = conf
    for part in key.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    value(key, node, minimum=minimum, above=above, below=below, optional=optional, integer=integer)


def value(key: str, node, *, minimum: float | None = None, above: float | None = None, below: float | None = None,
          optional: bool = True, integer: bool = False) -> None:
    """Check one value, named ``key`` in the message (see :func:`number`)."""
    if node is None:
        if optional:
            return
        raise ConfigError(f"{key} is not set: expected {_expect(minimum, above, below, integer)}")
    ok = _is_number(node) and math.isfinite(float(node)) and (not integer or float(node) == int(node))
    ok = ok and (minimum is None or node >= minimum) and (above is None or node > above) \
        and (below is None or node < below)
    if not ok:
        null = " (null for the default)" if optional else ""
        raise ConfigError(f"{key}={node!r}: expected {_expect(minimum, above, below, integer)}{null}")


def _expect(minimum, above, below, integer) -> str:
    what = "an integer" if integer else "a finite number"
    cond = []
    if above is not None:
        cond.append("> 0" if above == 0 else f"> {above:g}")
    if minimum is not None:
        cond.append(">= 0" if minimum == 0 else f">= {minimum:g}")
    if below is not None:
        cond.append(f"< {below:g}")
    return what + (" " + " and ".join(cond) if cond else "")


def required(conf: dict, key: str, what: str) -> None:
    """A mandatory setting (``???`` in the YAML) must be given on the command line."""
    v = conf.get(key)
    if v is None or (isinstance(v, str) and v.strip() in ("", MISSING)):
        raise ConfigError(f"{key}= is required: {what}")


# --------------------------------------------------------------------------------------- enumerated settings

BOOLEAN = (True, False)
CHECK_MODES = ("error", "warn", "off")          # study.run.records_run.CHECK_MODES, the doctor's checks
STATES = ("measured", "auto", "ekf")            # study.records.schema.STATES
RESUME_MODES = ("code", "config")               # study.run.executor.RESUME_MODES
RUDDER_LOGS = ("both", "actual", "command")
NOISE_KINDS = ("relative", "absolute")          # study.records.measure.NOISE_KINDS
SHALLOW_FORMULAS = ("kijima_1990", "ankudinov")  # study.sim.effects.LINEAR_FORMULAS

#: every enumerated setting of each command: dotted key -> (allowed values, None allowed: it means the default)
ENUMS = {
    "study": {"resume": (RESUME_MODES, True), "checks": (CHECK_MODES, True), "states": (STATES, True),
              "force": (BOOLEAN, False), "progress": (BOOLEAN, False), "noise.kind": (NOISE_KINDS, True),
              "depth.formula": (SHALLOW_FORMULAS, True)},
    "study simulate": {"rudder_log": (RUDDER_LOGS, True), "overwrite": (BOOLEAN, False),
                       "noise.kind": (NOISE_KINDS, True), "depth.formula": (SHALLOW_FORMULAS, True)},
    "study diagnose": {"checks": (CHECK_MODES, True), "states": (STATES, True), "rudder": (("delta", "delta_cmd"), True),
                       "overwrite": (BOOLEAN, False), "log_runs": (BOOLEAN, False),
                       "state_options.use_velocities": (BOOLEAN, True), "depth.formula": (SHALLOW_FORMULAS, True)},
}


def _get(conf: dict, key: str, absent=None):
    node = conf
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return absent
        node = node[part]
    return node


def check_enums(conf: dict, command: str) -> None:
    """Each enumerated setting of ``command`` (:data:`ENUMS`) holds one of its values (a boolean
    a boolean: ``force=maybe`` is not true)."""
    for key, (allowed, nullable) in ENUMS[command].items():
        v = _get(conf, key, absent=_ABSENT)
        if v is _ABSENT or (v is None and nullable):
            continue
        ok = (isinstance(v, bool) and v in allowed) if allowed is BOOLEAN else \
            (isinstance(v, str) and v in allowed)
        if not ok:
            what = "true or false" if allowed is BOOLEAN else "one of " + ", ".join(allowed)
            raise ConfigError(f"{key}={v!r}: expected {what}")


_ABSENT = object()


def check_state_options(conf: dict) -> None:
    """The doctor's state estimator options: each standard deviation ``auto`` or a finite number
    > 0, the process noise ``ml`` or ``{q_uv: ..., q_r: ...}``."""
    so = conf.get("state_options")
    if so is None:
        return
    if not isinstance(so, dict):
        raise ConfigError(f"state_options={so!r}: expected a mapping of the state estimator's options")
    known = ("position_std", "heading_std", "u_std", "v_std", "r_std", "use_velocities", "process")
    bad = sorted(set(so) - set(known))
    if bad:
        raise ConfigError(f"state_options.{bad[0]}: no such option; expected some of {list(known)}")
    for k in known[:5]:
        if so.get(k) not in (None, "auto"):
            value(f"state_options.{k}", so[k], above=0)
    proc = so.get("process")
    if proc not in (None, "ml"):
        if not isinstance(proc, dict) or set(proc) != {"q_uv", "q_r"}:
            raise ConfigError(f"state_options.process={proc!r}: expected ml or {{q_uv: m^2/s^5, q_r: rad^2/s^5}}")
        for k in proc:
            value(f"state_options.process.{k}", proc[k], above=0)


# --------------------------------------------------------------------------------------- writable folders

def writable(path, setting: str, folder: bool = True) -> None:
    """Prove that the folder ``path`` (a file's folder when not ``folder``) can be written,
    before any work: a real file is created and removed in it or, when it is not there yet, in
    its nearest existing ancestor (nothing is left behind). Refused naming the setting, the
    folder and the reason."""
    import os
    import tempfile

    target = Path(str(path)).expanduser().absolute()
    d = target if folder else target.parent
    while not d.exists() and d != d.parent:
        d = d.parent
    try:
        if not d.is_dir():
            raise NotADirectoryError(20, "not a folder", str(d))
        fd, probe = tempfile.mkstemp(prefix=".study-write-probe-", dir=d)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise ConfigError(f"{setting}={path}: folder {d} cannot be written ({e.strerror or e}); expected a folder "
                          "this user can create files in") from None


# ------------------------------------------------------------------------------------------ shared parts

#: effect parameters that are speeds, times or rates: negative makes no sense (a rate limit of 0: none at all)
_EFFECT_NONNEG = ("speed", "speed_U0", "lag", "delay")
_EFFECT_POSITIVE = ("rate_deg",)


def check_simulation(conf: dict) -> None:
    """What a simulated record depends on: seed, integration step and length, noise, depth,
    hidden effects."""
    number(conf, "seed", minimum=0, integer=True)
    number(conf, "sim.dt", above=0)
    number(conf, "sim.duration", above=0)
    if "duration_scale" in (conf.get("sim") or {}):
        number(conf, "sim.duration_scale", above=0, optional=False)
    noise = conf.get("noise") or {}
    level = noise.get("level")
    if isinstance(level, dict):
        for ch in level:
            number(conf, f"noise.level.{ch}", minimum=0)
    else:
        number(conf, "noise.level", minimum=0)
    for block in ("full_scale", "model_scale"):  # absolute noise: a standard deviation per sensor, in its units
        sensors = noise.get(block)
        if sensors is not None and not isinstance(sensors, dict):
            raise ConfigError(f"noise.{block}={sensors!r}: expected a mapping sensor -> standard deviation")
        for name in sensors or {}:
            number(conf, f"noise.{block}.{name}", minimum=0)
    number(conf, "noise.sample_dt", above=0)
    number(conf, "noise.sample_dt_LU", above=0)
    number(conf, "depth.h_T", above=0)
    effects = (conf.get("environment") or {}).get("effects") or []
    if not isinstance(effects, list):
        raise ConfigError(f"environment.effects={effects!r}: expected a list of effects ({{name: ..., ...}})")
    for i, e in enumerate(effects):
        if not isinstance(e, dict) or not e.get("name"):
            raise ConfigError(f"environment.effects[{i}]={e!r}: expected a mapping with a name")
        for k, v in e.items():
            key = f"environment.effects[{i}].{k}"
            if k == "name":
                continue
            if k in _EFFECT_NONNEG:
                value(key, v, minimum=0)
            elif k in _EFFECT_POSITIVE:
                value(key, v, above=0)
            elif _is_number(v) and not math.isfinite(float(v)):
                raise ConfigError(f"{key}={v!r}: expected a finite number")


def _time_scale(conf: dict) -> tuple[float | None, float | None]:
    """``(L/U0 [s], default integration step [s])`` of the configured vessel, (None, None) when
    it has no length and speed."""
    L, U0 = _get(conf, "vessel.particulars.Lpp"), _get(conf, "vessel.operation.U0")
    if not (_is_number(L) and _is_number(U0) and L > 0 and U0 > 0 and math.isfinite(L / U0)):
        return None, None
    from types import SimpleNamespace

    from study.sim import default_dt

    return L / U0, default_dt(SimpleNamespace(L=float(L), U0=float(U0)))


def check_together(conf: dict) -> None:
    """Settings that make a simulation impossible together, checked against each other before any
    work: an integration step longer than a tenth of the ship's time scale L/U0 (a manoeuvre is
    not resolved; the default is about 1 %), a sampling interval shorter than the step (records
    are decimated from the simulation), or both sampling intervals given."""
    nz = conf.get("noise") or {}
    if isinstance(nz, dict) and nz.get("sample_dt") is not None and nz.get("sample_dt_LU") is not None:
        raise ConfigError(f"noise.sample_dt={nz['sample_dt']} and noise.sample_dt_LU={nz['sample_dt_LU']}: expected "
                          "one of them (the other null)")
    T, default = _time_scale(conf)
    if T is None:
        return
    name = _get(conf, "vessel.name") or "the vessel"
    dt = _get(conf, "sim.dt")
    if _is_number(dt) and dt > 0.1 * T:
        raise ConfigError(f"sim.dt={dt!r}: expected at most {0.1 * T:.3g} s, a tenth of {name}'s time scale L/U0 = "
                          f"{T:.3g} s (null for the default, {default:g} s)")
    step = float(dt) if _is_number(dt) and dt > 0 else default
    sdt = nz.get("sample_dt") if isinstance(nz, dict) else None
    if _is_number(sdt) and sdt < step * (1 - 1e-9):
        raise ConfigError(f"noise.sample_dt={sdt!r}: expected at least the integration step, {step:g} s (records "
                          "are sampled from the simulation; null samples every step)")
    dur = _get(conf, "sim.duration")
    if _is_number(dur) and dur < 2 * step:
        raise ConfigError(f"sim.duration={dur!r}: expected at least two integration steps, {2 * step:g} s")


#: hyper-parameters that count something: an integer >= this (when not null)
_COUNTS = {"n_splits": 2, "cv": 2}
_COUNT_NAMES = ("n_", "max_", "min_steps", "maxiter", "popsize", "target_ess", "check_every")


def check_hyper_parameters(name: str, cls, params: dict, where: str) -> None:
    """An estimator's hyper-parameters, of the kind its constructor's defaults say, before any
    work: a count (``n_splits``, ``max_iter``, ``n_*``) a positive integer (cross-validation at
    least 2 folds), a boolean a boolean, a number where the default is a number (or text where
    text is allowed), finite."""
    import inspect

    defaults = {k: p.default for k, p in inspect.signature(cls.__init__).parameters.items()
                if k != "self" and p.default is not inspect.Parameter.empty}
    for k, v in (params or {}).items():
        key = f"{where}.{k}"
        d = defaults.get(k, _ABSENT)
        if v is None:
            continue
        if isinstance(d, bool):
            if not isinstance(v, bool):
                raise ConfigError(f"{key}={v!r}: expected true or false (estimator '{name}')")
            continue
        count = k in _COUNTS or k.startswith(_COUNT_NAMES)
        if count and (_is_number(d) or d is None):
            value(key, v, minimum=_COUNTS.get(k, 1), integer=True)
        elif _is_number(d):
            if isinstance(v, str) or isinstance(v, bool) or (not _is_number(v) and not isinstance(v, (list, tuple))):
                raise ConfigError(f"{key}={v!r}: expected a number (estimator '{name}', default {d!r})")
            if _is_number(v):
                value(key, v)
        elif _is_number(v):
            value(key, v)


def _estimator_params(name: str, cfg: dict | None = None) -> list[str]:
    """The hyper-parameters the estimator ``name`` (or its config ``cfg``) accepts: its class's
    constructor."""
    from study.configuration.compose import read_config
    from study.identify.estimators import estimator_class, list_estimators

    if cfg is None:
        if name not in list_estimators():
            raise ConfigError(f"estimator_overrides.{name}: no estimator '{name}'; expected one of "
                              f"{list_estimators()} (conf/estimator/)")
        cfg = read_config("estimator", name)
    return sorted(estimator_class(cfg)._get_param_names())


def check_estimator(conf: dict) -> None:
    """``estimator.params`` and ``estimator_overrides``: every name must be an estimator and one
    of its hyper-parameters (a misspelt one used to be ignored, or to fail the run only when that
    estimator ran)."""
    from study.identify.estimators import estimator_class

    est = conf.get("estimator") or {}
    if est.get("_target_"):
        known = _estimator_params(est.get("name"), est)
        bad = sorted(set(est.get("params") or {}) - set(known))
        if bad:
            raise ConfigError(f"estimator.params: estimator '{est.get('name')}' has no hyper-parameter "
                              f"{', '.join(bad)}; expected some of {known}")
        check_hyper_parameters(est.get("name"), estimator_class(est), est.get("params"), "estimator.params")
    over = conf.get("estimator_overrides") or {}
    if not isinstance(over, dict):
        raise ConfigError(f"estimator_overrides={over!r}: expected {{<estimator name>: {{param: value}}}}")
    for name, params in over.items():
        known = _estimator_params(str(name))
        if params is None:
            continue
        if not isinstance(params, dict):
            raise ConfigError(f"estimator_overrides.{name}={params!r}: expected {{param: value}}")
        bad = sorted(set(params) - set(known))
        if bad:
            raise ConfigError(f"estimator_overrides.{name}: estimator '{name}' has no hyper-parameter "
                              f"{', '.join(bad)}; expected some of {known}")
        from study.configuration.compose import read_config

        check_hyper_parameters(str(name), estimator_class(read_config("estimator", str(name))), params,
                               f"estimator_overrides.{name}")


# ---------------------------------------------------------------------------------------------- commands

def check_run(conf: dict) -> None:
    """A study run's configuration (``python -m study``): every value, the enumerated settings,
    the number of replicates, the settings that must fit together (a simulated run), the
    estimator's hyper-parameters and the classes the configuration names (the trusted-code
    boundary, before anything is imported)."""
    from study.configuration.compose import check_targets

    check_targets({k: v for k, v in conf.items() if k != "hydra"})
    check_enums(conf, "study")
    check_replicates(conf)
    check_simulation(conf)
    if conf.get("train") is None:
        check_together(conf)
    check_estimator(conf)


def check_replicates(conf: dict) -> None:
    """``replicates``: how many independent datasets a job identifies, a whole number >= 1; the
    user's own records (``train=``) are one dataset."""
    n = conf.get("replicates", 1)
    if n is None or isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ConfigError(f"replicates={n!r}: expected a whole number >= 1 (independent datasets of the run)")
    if n > 1 and conf.get("train") is not None:
        raise ConfigError(f"replicates={n}: the records given by train= are one dataset; expected replicates=1 "
                          "with train= (replicates draw new measurement noise of a simulated run)")


def check_simulate(conf: dict) -> Path:
    """``python -m study simulate``: the simulation's settings and the output file (given, a
    record file type, not there unless ``overwrite=true``). Returns the output path."""
    from study.records.schema import SUPPORTED

    required(conf, "out", "the record file to write (out=<file.csv|file.parquet>)")
    check_enums(conf, "study simulate")
    check_simulation(conf)
    check_together(conf)
    path = Path(str(conf["out"])).expanduser()
    if path.suffix.lower() not in SUPPORTED:
        raise ConfigError(f"out={conf['out']}: unsupported file type '{path.suffix}'; expected one of "
                          f"{list(SUPPORTED)}")
    if path.exists() and not conf.get("overwrite"):
        raise OutputExistsError(f"out={conf['out']}: {path} exists; refusing to overwrite it (overwrite=true to "
                                "replace it)")
    if path.is_dir():
        raise ConfigError(f"out={conf['out']}: is a folder; expected a record file")
    writable(path, "out", folder=False)
    return path


#: what a doctor's report folder holds; any of them there means a report would be replaced
REPORT_FILES = ("report.json", "report.html", "figures")


def existing_report(out: Path) -> list[str]:
    """The report files already in ``out`` (empty when there are none). An empty ``figures/`` is
    no report (a doctor stopped before it wrote one left it; the figures are written to a
    temporary folder and moved in)."""
    def there(n):
        p = out / n
        return p.is_dir() and any(p.iterdir()) if n == "figures" else p.exists()
    return [n for n in REPORT_FILES if there(n)]


def check_diagnose(conf: dict) -> Path:
    """``python -m study diagnose``: records and output given, the output folder holds no report
    (unless ``overwrite=true``), the doctor's thresholds in range. Returns the output folder."""
    required(conf, "train", "the training records (train=<file|folder|glob>)")
    required(conf, "out", "the report folder to write (out=<folder>)")
    check_enums(conf, "study diagnose")
    check_state_options(conf)
    number(conf, "min_improvement", minimum=0, below=1, optional=False)
    number(conf, "alpha", above=0, below=1, optional=False)
    number(conf, "tie", minimum=0, optional=False)
    number(conf, "max_steps", minimum=0, integer=True, optional=False)
    number(conf, "anchor", minimum=0)
    number(conf, "depth.h_T", above=0)
    out = Path(str(conf["out"])).expanduser()
    if out.exists() and not out.is_dir():
        raise ConfigError(f"out={conf['out']}: is a file; expected a folder for the report")
    there = existing_report(out)
    if there and not conf.get("overwrite"):
        raise OutputExistsError(f"out={conf['out']}: {out} already holds {', '.join(there)}; refusing to overwrite "
                                "a report (overwrite=true to overwrite it, or another out=)")
    check_candidates(conf)
    writable(out, "out")
    if conf.get("log_runs", True):
        res = conf.get("results_dir")
        writable(res if res else out / "results", "results_dir" if res else "out")
    return out


def check_candidates(conf: dict) -> None:
    """The doctor's effect folders exist, its candidates and the model's effects are effects of
    the catalogue, and each names a class of the package or of an effect folder (checked before
    anything is imported)."""
    from study.configuration.compose import check_target
    from study.identify.effects import effect_config, effect_dirs, list_effects

    path = conf.get("effect_path") or ()
    path = [path] if isinstance(path, str) else list(path)
    for p in path:
        if not Path(str(p)).expanduser().is_dir():
            raise ConfigError(f"effect_path={p}: no such folder; expected folders of effect YAMLs")
    try:
        dirs = effect_dirs(path)
    except ValueError as e:
        raise ConfigError(str(e)) from None
    known = list_effects(path)
    cands = conf.get("candidates")
    if cands is not None and not isinstance(cands, (list, tuple)):
        raise ConfigError(f"candidates={cands!r}: expected a list of effect names (or null: all)")
    given = list(_get(conf, "model.effects") or [])
    for where, names in (("candidates", cands or []), ("model.effects", given)):
        for n in names:
            if isinstance(n, dict):
                check_target(n.get("_target_"), f"{where}: _target_", plugin_dirs=dirs[1:])
                continue
            if n not in known:
                raise ConfigError(f"{where}: {n!r}: no such effect; expected one of {known} (conf/effect/, "
                                  "effect_path or STUDY_EFFECT_PATH)")
    for n in (cands if cands is not None else known):
        if isinstance(n, str):
            cfg = effect_config(n, path)
            check_target(cfg.get("_target_"), f"{cfg.get('_file', n)}: _target_", plugin_dirs=dirs[1:])
