"""The named studies' figures and claims, one module per study, found by name.

A study is a Hydra experiment (``conf/experiment/<name>.yaml``, whose runs carry ``study: <name>``)
and a module here of the same name with ``NAME``, ``SEED`` (the seed paper whose claim it tests, or
None) and ``build(builder, runs, params, claims)``, which writes the study's figures and tables
through the builder (:class:`study.figures.plots.Builder`) and appends its claim, if it makes one,
to ``claims``. A new study is its YAML plus its module: :func:`discover` finds every module in this
package, nothing lists them.
"""
from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType

__all__ = ["discover"]


def discover(package: ModuleType | None = None) -> dict[str, ModuleType]:
    """name -> module of every study module in ``package`` (default: this one). A module without
    ``NAME`` (its file's name) and ``build`` is refused: a half-written study would otherwise vanish
    from the figures without a
    word."""
    path, prefix = (package.__path__, package.__name__) if package is not None else (__path__, __name__)
    out = {}
    for info in sorted(pkgutil.iter_modules(path), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{prefix}.{info.name}")
        if not callable(getattr(mod, "build", None)) or getattr(mod, "NAME", None) != info.name:
            raise ImportError(f"{mod.__file__}: a study module needs NAME = {info.name!r} and "
                              f"build(builder, runs, params, claims)")
        out[info.name] = mod
    return out
