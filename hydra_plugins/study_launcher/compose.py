"""A sweep job's configuration, as Hydra's launchers compose it, for less: what is the same for many
jobs is done once.

Every Hydra launcher composes each job's configuration again in the worker
(``ConfigLoader.load_sweep_config``: the primary config, its defaults list, every group option's
YAML and Hydra's own config groups, then the job's overrides): 0.1 s of CPU a job on this project's
configs, whatever the job. :class:`JobComposer` does two things once instead of every time, both
exact:

* **Loaded configs** (``cache_loaded``): each config file (or structured config) Hydra loads --
  read, parsed, its defaults list built -- is kept per process, and every later load gets a fresh
  copy of it (an unpickling, as if read again: Hydra is free to change what it gets). Hydra's
  composition is otherwise unchanged, and runs on a copy of the config loader, so the launching
  process's own loader is untouched. About 40 % of a composition.
* **Value overrides** (``share``): jobs that differ only in value overrides (``seed=3``,
  ``noise.sample_dt_LU=0.05``, ``vessel.operation.U0=8.23``) share everything up to the last step of
  a composition, so it is done once per distinct set of *group* overrides (``estimator=ls``) with
  Hydra's own ``load_sweep_config``; for each job that configuration is copied and the job's value
  overrides are applied with the call Hydra itself makes for them
  (``ConfigLoaderImpl._apply_overrides_to_config``), followed by Hydra's bookkeeping of the
  overrides (``hydra.overrides.task``, ``hydra.job.override_dirname``) as
  ``ConfigLoaderImpl._load_configuration_impl`` does it. Which overrides are group overrides is
  decided by Hydra's own classification (``hydra._internal.defaults_list.Overrides``) against the
  same config repository. Why this is the same configuration: Hydra's composition is ``defaults list
  (group overrides only) -> merge -> struct mode -> value overrides in order -> bookkeeping``; value
  overrides never enter the defaults list or the merge, so the state before them is a function of
  the group overrides alone. Anything else -- an override of ``hydra.*``, a sweep-syntax value, a
  job without value overrides -- is composed by ``load_sweep_config`` itself.

Hydra internals are used (private but pinned: hydra-core 1.3), and
``tests/plugins/test_launcher.py`` checks node by node (values, node types, flags, metadata) that
the result equals Hydra's own composition, on a sample of grand's and seed001's jobs in the default
test run and on every job of both with ``-m slow``.
"""
# no `from __future__ import annotations`: Hydra execs plugin modules outside sys.modules (see covering_sweeper)

import copy
import io
import pickle
from collections import OrderedDict
from typing import List, Optional, Sequence, Tuple

from hydra._internal.config_repository import IConfigRepository
from hydra.core.object_type import ObjectType
from omegaconf import DictConfig, OmegaConf


class JobComposer:
    """Compose sweep jobs' configurations for one sweep (one master config), in one process."""

    def __init__(self, config_loader, master_config: DictConfig, share: bool = True, cache_loaded: bool = True,
                 keep: int = 8) -> None:
        self.loader = config_loader
        if cache_loaded:  # a copy: the launching process's loader (its sweeper's) stays Hydra's own
            self.loader = copy.copy(config_loader)
            self.loader.repository = _LoadedConfigs(config_loader.repository, {})
        self.master = master_config
        self.share = share
        self.keep = keep  # composed bases kept (jobs come grouped by their group overrides: a few suffice)
        self._bases: "OrderedDict[Tuple[str, ...], _Frozen]" = OrderedDict()
        self._repo = None
        self._parser = None
        self.composed = 0  # Hydra compositions made (for the benchmark and tests)
        self.shared = 0    # jobs composed from a base

    # ------------------------------------------------------------------ classification
    def _setup(self) -> None:
        from hydra._internal.config_loader_impl import ConfigLoaderImpl  # noqa: F401  (checked below)
        from hydra.core.override_parser.overrides_parser import OverridesParser

        self._parser = OverridesParser.create()
        # the repository Hydra composes against: the search path of the primary config and of the hydra
        # overrides (a hydra.searchpath adds sources), made the way Hydra makes it for every composition
        hydra_overrides = list(OmegaConf.to_container(self.master.hydra.overrides.hydra))
        _, self._repo = self.loader._parse_overrides_and_create_caching_repo(
            self.master.hydra.job.config_name, hydra_overrides)

    def split(self, overrides: Sequence[str]) -> Optional[Tuple[Tuple[str, ...], list, list]]:
        """``(group override lines, value overrides, all parsed overrides)`` of a job, by Hydra's
        own classification; None when the job is not composed from a shared base (see the
        module's docstring)."""
        from hydra._internal.defaults_list import Overrides

        if self._parser is None:
            self._setup()
        parsed = self._parser.parse_overrides(list(overrides))
        if any(o.is_hydra_override() or o.is_sweep_override() for o in parsed):
            return None
        try:
            values = Overrides(self._repo, parsed).config_overrides
        except Exception:  # noqa: BLE001 - Hydra's own composition reports it
            return None
        if not values:
            return None
        ids = {id(o) for o in values}
        groups = tuple(o.input_line for o in parsed if id(o) not in ids)
        return groups, values, parsed

    def group_key(self, overrides: Sequence[str]) -> Tuple[str, ...]:
        """The jobs that can share a composition have the same key (the launchers group jobs by
        it)."""
        if not self.share:
            return tuple(overrides)
        s = self.split(overrides)
        return tuple(overrides) if s is None else s[0]

    # ------------------------------------------------------------------ composition
    def hydra_compose(self, overrides: Sequence[str]) -> DictConfig:
        """Hydra's own composition of a sweep job (what its joblib and submitit launchers call)."""
        self.composed += 1
        return self.loader.load_sweep_config(self.master, list(overrides))

    def compose(self, overrides: Sequence[str], alone: bool = False) -> DictConfig:
        """The job's configuration, equal to :meth:`hydra_compose`'s. ``alone``: no other job to
        come shares its group overrides (a base kept for it would cost its pickling for nothing)."""
        s = self.split(overrides) if self.share and not alone else None
        if s is None:
            return self.hydra_compose(overrides)
        groups, values, parsed = s
        base = self._bases.get(groups)
        if base is None:
            base = _Frozen(self.hydra_compose(list(groups)))
            self._bases[groups] = base
            while len(self._bases) > self.keep:
                self._bases.popitem(last=False)
        else:
            self._bases.move_to_end(groups)
        self.shared += 1
        cfg = base.copy()
        return self._apply(cfg, values, parsed)

    def _apply(self, cfg: DictConfig, values: list, parsed: list) -> DictConfig:
        """Hydra's last steps of a composition (``ConfigLoaderImpl._load_configuration_impl``
        after the merge, and ``load_sweep_config``'s cache copy), on a configuration composed
        from the group overrides."""
        from hydra._internal.config_loader_impl import ConfigLoaderImpl, get_overrides_dirname
        from hydra.errors import ConfigCompositionException
        from omegaconf.errors import OmegaConfBaseException

        try:
            ConfigLoaderImpl._apply_overrides_to_config(values, cfg)
            task = cfg.hydra.overrides.task
            while len(task):  # the base holds the group overrides only: the job's, in its order
                task.pop()
            for o in parsed:
                task.append(o.input_line)
            dirname = cfg.hydra.job.config.override_dirname
            cfg.hydra.job.override_dirname = get_overrides_dirname(
                overrides=parsed, kv_sep=dirname.kv_sep, item_sep=dirname.item_sep,
                exclude_keys=dirname.exclude_keys)
        except OmegaConfBaseException as e:  # as ConfigLoaderImpl.load_configuration reports it
            raise ConfigCompositionException().with_traceback(e.__traceback__) from e
        OmegaConf.copy_cache(from_config=self.master, to_config=cfg)
        return cfg


class _Frozen:
    """An object (a configuration, Hydra's result of loading one) kept as a pickle, copied by
    unpickling it (1-2 ms; OmegaConf's deepcopy costs ten times that). Classes and functions
    (structured configs' types) are kept by identity, not by name: Hydra re-executes plugin
    modules when it rebuilds its plugin registry (``Singleton.set_state`` in a worker), after
    which a class found by its name is another object than the one the configuration holds."""

    def __init__(self, cfg) -> None:
        self.objects: list = []
        buf = io.BytesIO()
        pickler = pickle.Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL)
        pickler.persistent_id = self._persistent_id
        pickler.dump(cfg)
        self.data = buf.getvalue()

    def _persistent_id(self, obj):
        if isinstance(obj, type) or callable(obj) and hasattr(obj, "__qualname__"):
            self.objects.append(obj)
            return len(self.objects) - 1
        return None

    def copy(self):
        unpickler = pickle.Unpickler(io.BytesIO(self.data))
        unpickler.persistent_load = self.objects.__getitem__
        return unpickler.load()


class _LoadedConfigs(IConfigRepository):
    """Hydra's config repository with every loaded config kept (per search path and config path) and
    handed out as a fresh copy. Hydra copies its repository for every composition
    (``CachingConfigRepository`` deep-copies it, so that a ``hydra.searchpath`` can re-initialise
    the copy's sources): the copy shares the kept configs, and the wrapped repository is copied
    shallowly (re-initialising its sources rebinds its list, never changes a
    source)."""

    def __init__(self, inner, kept: dict, counts: Optional[dict] = None) -> None:
        self.inner = inner
        self.kept = kept
        self.counts = {"loaded": 0, "reused": 0} if counts is None else counts

    def __deepcopy__(self, memo):
        return _LoadedConfigs(copy.copy(self.inner), self.kept, self.counts)

    def load_config(self, config_path: str):
        key = (tuple((s.provider, s.path) for s in self.inner.get_sources()), config_path)
        kept = self.kept.get(key)
        if kept is None:
            ret = self.inner.load_config(config_path=config_path)
            if ret is None:
                return None
            kept = self.kept[key] = _Frozen(ret)
            self.counts["loaded"] += 1
        else:
            self.counts["reused"] += 1
        return kept.copy()

    def get_schema_source(self):
        return self.inner.get_schema_source()

    def initialize_sources(self, config_search_path) -> None:
        self.inner.initialize_sources(config_search_path)

    def group_exists(self, config_path: str) -> bool:
        return self.inner.group_exists(config_path=config_path)

    def config_exists(self, config_path: str) -> bool:
        return self.inner.config_exists(config_path=config_path)

    def get_group_options(self, group_name: str, results_filter: Optional[ObjectType] = ObjectType.CONFIG):
        return self.inner.get_group_options(group_name=group_name, results_filter=results_filter)

    def get_sources(self):
        return self.inner.get_sources()


def config_differences(a, b, path: str = "", out: Optional[List[str]] = None, limit: int = 20) -> List[str]:
    """Where two OmegaConf trees differ, node by node: node class, metadata (reference and object
    types, optional, key, flags, resolver cache, key and element types), and raw values
    (interpolations unresolved). Empty when they are the same configuration. Used by the tests
    against Hydra's own composition."""
    from omegaconf import ListConfig, Node
    from omegaconf.basecontainer import BaseContainer

    out = [] if out is None else out
    if len(out) >= limit:
        return out
    if type(a) is not type(b):
        out.append(f"{path or '<root>'}: node {type(a).__name__} != {type(b).__name__}")
        return out
    if isinstance(a, Node):
        ma, mb = a._metadata, b._metadata
        for f in ma.__dataclass_fields__:
            va, vb = getattr(ma, f), getattr(mb, f, None)
            if va != vb:
                out.append(f"{path or '<root>'}: metadata {f} {va!r} != {vb!r}")
    if isinstance(a, BaseContainer):
        ca, cb = a.__dict__["_content"], b.__dict__["_content"]
        if not isinstance(ca, (dict, list)) or not isinstance(cb, (dict, list)):  # None, missing, interpolation
            if ca != cb:
                out.append(f"{path or '<root>'}: {ca!r} != {cb!r}")
            return out
        if isinstance(a, ListConfig):
            if len(ca) != len(cb):
                out.append(f"{path}: {len(ca)} items != {len(cb)}")
                return out
            for i, (x, y) in enumerate(zip(ca, cb)):
                config_differences(x, y, f"{path}[{i}]", out, limit)
        else:
            if list(ca) != list(cb):
                out.append(f"{path or '<root>'}: keys {list(ca)} != {list(cb)}")
                return out
            for k in ca:
                config_differences(ca[k], cb[k], f"{path}.{k}" if path else str(k), out, limit)
    elif isinstance(a, Node):
        va, vb = a._value(), b._value()
        if type(va) is not type(vb) or va != vb:
            out.append(f"{path}: {va!r} != {vb!r}")
    elif a != b:
        out.append(f"{path}: {a!r} != {b!r}")
    return out
