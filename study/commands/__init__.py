"""The commands: ``python -m study [command] [arguments]``.

Without a command word, ``python -m study`` is the Hydra app (:mod:`study.commands.app`: one run, or
a sweep with ``-m``). Every other module of this package is a command of its own name (``python -m
study diagnose ...``); each defines ``command()``, which runs it on ``sys.argv`` and exits with its
status. A new command is one module here, found without being listed.
"""
from __future__ import annotations

import importlib
import pkgutil
import sys

#: the module that runs when no command word is given
DEFAULT = "app"


def names() -> list[str]:
    """The command words: every module of this package but the default app."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if m.name != DEFAULT and not m.name.startswith("_"))


def dispatch(argv: list[str]) -> None:
    """Run the command ``argv[1]`` names (removed from ``sys.argv``), or the Hydra app when
    ``argv[1]`` is an override, an option or absent. A bare word that is neither a command nor an
    override is refused in one line."""
    word = argv[1] if len(argv) > 1 else ""
    if word in names():
        sys.argv = [f"{argv[0]} {word}"] + argv[2:]
        importlib.import_module(f"{__name__}.{word}").command()
        return
    if word and not word.startswith("-") and "=" not in word:
        print(f"study: error: {word!r} is neither a command ({', '.join(names())}) nor a Hydra override "
              "(key=value)", file=sys.stderr)
        raise SystemExit(2)
    importlib.import_module(f"{__name__}.{DEFAULT}").command()
