"""Settings checked before any work: a value that makes no sense is refused, naming the setting.

Zero does not mean "unset" (``null`` does): ``sim.dt=0`` or ``sim.duration=0`` used to run silently with the
defaults, and a negative value failed deep inside numpy ("negative dimensions are not allowed") naming nothing.
Each check here raises :class:`study.cli.ConfigError` (a ``ValueError``) with ``<setting>=<value>: expected
<what>``, so every command refuses in one line with exit status 2 before it simulates, reads or writes anything.

- :func:`check_run`: a study run (``python -m study``; the sweeper checks every composed job of a sweep with it
  before launching any).
- :func:`check_simulate`: ``python -m study.simulate`` (also that ``out=`` is given, is a record file and is not
  there already).
- :func:`check_diagnose`: ``python -m study.diagnose`` (``train=`` and ``out=`` given, the doctor's thresholds).
"""
from __future__ import annotations

import math
import numbers
from pathlib import Path

from .cli import ConfigError, OutputExistsError

#: Hydra's marker of a mandatory value nobody gave
MISSING = "???"


def _is_number(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def number(conf: dict, key: str, *, minimum: float | None = None, above: float | None = None,
           below: float | None = None, optional: bool = True, integer: bool = False) -> None:
    """Check the setting ``key`` (dotted) of ``conf``: a finite number (an integer if ``integer``), ``>= minimum``,
    ``> above`` and ``< below`` where given; ``None``/absent passes when ``optional``."""
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


# ------------------------------------------------------------------------------------------ shared parts

#: effect parameters that are speeds, times or rates: negative makes no sense (a rate limit of 0: none at all)
_EFFECT_NONNEG = ("speed", "speed_U0", "lag", "delay")
_EFFECT_POSITIVE = ("rate_deg",)


def check_simulation(conf: dict) -> None:
    """What a simulated record depends on: seed, integration step and length, noise, depth, hidden effects."""
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


def _estimator_params(name: str, cfg: dict | None = None) -> list[str]:
    """The hyper-parameters the estimator ``name`` (or its config ``cfg``) accepts: its class's constructor."""
    from .config import read_config
    from .identify.estimators import estimator_class, list_estimators

    if cfg is None:
        if name not in list_estimators():
            raise ConfigError(f"estimator_overrides.{name}: no estimator '{name}'; expected one of "
                              f"{list_estimators()} (conf/estimator/)")
        cfg = read_config("estimator", name)
    return sorted(estimator_class(cfg)._get_param_names())


def check_estimator(conf: dict) -> None:
    """``estimator.params`` and ``estimator_overrides``: every name must be an estimator and one of its
    hyper-parameters (a misspelt one used to be ignored, or to fail the run only when that estimator ran)."""
    est = conf.get("estimator") or {}
    if est.get("_target_"):
        known = _estimator_params(est.get("name"), est)
        bad = sorted(set(est.get("params") or {}) - set(known))
        if bad:
            raise ConfigError(f"estimator.params: estimator '{est.get('name')}' has no hyper-parameter "
                              f"{', '.join(bad)}; expected some of {known}")
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


# ---------------------------------------------------------------------------------------------- commands

def check_run(conf: dict) -> None:
    """A study run's configuration (``python -m study``)."""
    check_replicates(conf)
    check_simulation(conf)
    check_estimator(conf)


def check_replicates(conf: dict) -> None:
    """``replicates``: how many independent datasets a job identifies, a whole number >= 1; the user's own
    records (``train=``) are one dataset."""
    n = conf.get("replicates", 1)
    if n is None or isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ConfigError(f"replicates={n!r}: expected a whole number >= 1 (independent datasets of the run)")
    if n > 1 and conf.get("train") is not None:
        raise ConfigError(f"replicates={n}: the records given by train= are one dataset; expected replicates=1 "
                          "with train= (replicates draw new measurement noise of a simulated run)")


def check_simulate(conf: dict) -> Path:
    """``python -m study.simulate``: the simulation's settings and the output file (given, a record file type,
    not there unless ``overwrite=true``). Returns the output path."""
    from .schema import SUPPORTED

    required(conf, "out", "the record file to write (out=<file.csv|file.parquet>)")
    check_simulation(conf)
    log = conf.get("rudder_log", "both")
    if log not in ("both", "actual", "command"):
        raise ConfigError(f"rudder_log={log!r}: expected 'both', 'actual' or 'command'")
    path = Path(str(conf["out"])).expanduser()
    if path.suffix.lower() not in SUPPORTED:
        raise ConfigError(f"out={conf['out']}: unsupported file type '{path.suffix}'; expected one of "
                          f"{list(SUPPORTED)}")
    if path.exists() and not conf.get("overwrite"):
        raise OutputExistsError(f"out={conf['out']}: {path} exists; refusing to overwrite it (overwrite=true to "
                                "replace it)")
    if path.is_dir():
        raise ConfigError(f"out={conf['out']}: is a folder; expected a record file")
    return path


#: what a doctor's report folder holds; any of them there means a report would be replaced
REPORT_FILES = ("report.json", "report.html", "figures")


def existing_report(out: Path) -> list[str]:
    """The report files already in ``out`` (empty when there are none)."""
    return [n for n in REPORT_FILES if (out / n).exists()]


def check_diagnose(conf: dict) -> Path:
    """``python -m study.diagnose``: records and output given, the output folder holds no report (unless
    ``overwrite=true``), the doctor's thresholds in range. Returns the output folder."""
    required(conf, "train", "the training records (train=<file|folder|glob>)")
    required(conf, "out", "the report folder to write (out=<folder>)")
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
    return out
