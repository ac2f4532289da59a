"""How every command-line entry point reports a problem: one line, an exit status, a traceback only
when asked.

Every ``python -m study [command]`` runs through :func:`run` (argparse commands) or
:func:`run_hydra` (the Hydra apps: ``study`` itself, ``simulate``, ``diagnose``). A problem the user
can fix -- a setting, a file, an output that exists -- is printed as one line on stderr,
``<command>: error: <what, where, what was expected>``, and the command exits with status 2
(:data:`EXIT_USAGE`; nothing has been written). Anything else (a bug, a failed run) exits with
status 1 (:data:`EXIT_FAILED`), also with one line, and a hint how to see the traceback:
``--verbose`` on the command line or ``STUDY_VERBOSE=1`` in the environment (``HYDRA_FULL_ERROR=1``
as well, for Hydra's users).

Why not Hydra's own reporting: Hydra prints 15-40 lines of traceback with the message at the bottom.
The Hydra apps therefore run with ``HYDRA_FULL_ERROR=1`` set here, which makes Hydra re-raise
instead of printing, and errors inside a task are caught by :func:`reported`, which records the exit
status and lets Hydra finish (its callbacks still rebuild the results table).
"""
from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
import traceback

EXIT_OK = 0
EXIT_FAILED = 1  # the command ran and something failed: a failed run, an unexpected error
EXIT_USAGE = 2   # what was asked cannot be done (a setting, a file, an output): refused before any work
VERBOSE_FLAG = "--verbose"
VERBOSE_ENV = "STUDY_VERBOSE"


class UsageError(Exception):
    """A problem with what the user asked for, reported in one line with exit status 2."""


class ConfigError(UsageError, ValueError):
    """A setting whose value makes no sense (zero, negative, not finite, unknown name, required
    but missing). The message names the setting, the value given and what is expected."""


class OutputExistsError(UsageError, FileExistsError):
    """An output would replace a file or report already there (pass the command's overwrite
    option)."""


#: the exit status a task asked for (set by :func:`reported` and :func:`fail`; read by :func:`run_hydra`), and the
#: output folder Hydra made for a task that was then refused (removed by :func:`run_hydra`)
_status = {"code": EXIT_OK, "refused_dir": None}


def fail(code: int) -> None:
    """Make the command exit with ``code`` (the worst one asked for wins) once Hydra has
    finished."""
    _status["code"] = max(_status["code"], int(code))


def verbose() -> bool:
    """Tracebacks wanted: ``--verbose`` was given (it sets ``STUDY_VERBOSE=1``), or
    ``STUDY_VERBOSE`` is set."""
    return os.environ.get(VERBOSE_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def _user_errors() -> tuple:
    """Exception types that are the user's to fix: the project's own (``UsageError``;
    ``ValueError`` is the project's convention for a bad value, and ``SchemaError``,
    ``RecordsInputError``, ``RecordCheckError`` derive from it), files (``OSError``: missing,
    existing, not writable), and Hydra's and OmegaConf's configuration errors (a misspelt option,
    an unknown key, a missing mandatory value)."""
    types = [UsageError, ValueError, OSError]
    try:
        from hydra.errors import HydraException
        from omegaconf.errors import OmegaConfBaseException

        types += [HydraException, OmegaConfBaseException]
    except ImportError:  # pragma: no cover - Hydra is a dependency
        pass
    return tuple(types)


def message(exc: BaseException) -> str:
    """One line: the exception's message with its lines joined (Hydra's list their options on
    lines of their own); an OS error as ``<file>: <reason>``."""
    if isinstance(exc, OSError) and exc.strerror and exc.filename and not isinstance(exc, UsageError):
        text = f"{exc.filename}: {exc.strerror}"
    else:
        text = str(exc)
        if isinstance(exc, KeyError) and exc.args:
            text = str(exc.args[0])
    text = text.split("\nConfig search path:")[0]  # Hydra's missing option: where it looked is noise here
    parts = []
    for ln in (ln.strip() for ln in text.splitlines()):
        if ln and parts and parts[-1].endswith(":") and "Available options" in parts[-1]:
            parts[-1] += " " + ln  # Hydra lists the options one per line: one list
        elif ln and parts and "Available options" in parts[-1] and ":" in parts[-1] and " " not in ln:
            parts[-1] += ", " + ln
        elif ln and not ln.startswith(("full_key:", "object_type=", "reference_type=")):  # OmegaConf's internals
            parts.append(ln)
    cause = exc.__cause__
    if cause is not None and type(exc).__module__.startswith(("hydra", "omegaconf")):
        extra = message(cause)  # e.g. Hydra's "Error merging override x=1" with OmegaConf's reason
        if extra and extra not in " ".join(parts):
            parts.append(extra)
    return "; ".join(p.rstrip(".") if i < len(parts) - 1 else p for i, p in enumerate(parts)) or type(exc).__name__


_OVERRIDE = re.compile(r"Could not override '([^']+)'")
_MISSING_OPTION = re.compile(r"Could not find '([^'/]+)/([^']+)'")


def did_you_mean(exc: BaseException) -> str | None:
    """For a misspelt setting or option, one line naming it and the closest names there are,
    instead of Hydra's advice to add ``+key`` (which would add the misspelt key as a new one):
    from the configuration node OmegaConf attaches to its error (a key) or the options Hydra
    lists (a group's option). None for any other error."""
    import difflib

    text = str(exc)
    m = _OVERRIDE.search(text)
    if m:
        key = m.group(1)
        node, c = None, exc
        while c is not None and node is None:
            node = getattr(c, "parent_node", None)
            c = c.__cause__ or c.__context__
        names = [str(k) for k in node.keys() if str(k) != "hydra"] if node is not None and hasattr(node, "keys") else []
        leaf = key.rsplit(".", 1)[-1]
        close = difflib.get_close_matches(leaf, names, n=3, cutoff=0.6)
        where = key.rsplit(".", 1)[0] + "." if "." in key else ""
        hint = (f"did you mean {', '.join(repr(where + c) for c in close)}?" if close else
                f"expected one of {', '.join(names)}" if names else "expected a setting of the configuration")
        return (f"{key}: no such setting; {hint} (a new key, not a misspelt one, is added with +{key}=...; "
                "--help lists the settings)")
    m = _MISSING_OPTION.search(text)
    if m:
        group, option = m.group(1), m.group(2)
        avail = text.split("\nConfig search path:")[0].split("Available options in", 1)
        options = re.findall(r"[\w.-]+", avail[1].split(":", 1)[1]) if len(avail) > 1 and ":" in avail[1] else []
        close = difflib.get_close_matches(option, options, n=3, cutoff=0.5)
        return (f"{group}={option}: no such option" + (f"; did you mean {', '.join(close)}?" if close else "")
                + (f" (expected one of {', '.join(options)})" if options else ""))
    return None


def report(exc: BaseException, prog: str) -> int:
    """Print ``exc`` for the user (the traceback too when :func:`verbose`); returns the exit
    status."""
    if verbose():
        traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
    if isinstance(exc, _user_errors()):
        print(f"{prog}: error: {did_you_mean(exc) or message(exc)}", file=sys.stderr, flush=True)
        return EXIT_USAGE
    hint = "" if verbose() else f" (unexpected; run again with {VERBOSE_FLAG} or {VERBOSE_ENV}=1 for the traceback)"
    print(f"{prog}: error: {type(exc).__name__}: {message(exc)}{hint}", file=sys.stderr, flush=True)
    return EXIT_FAILED


@contextlib.contextmanager
def reported(prog: str):
    """Inside a Hydra task: an exception is printed in one line and becomes the command's exit
    status, and the task returns normally (so Hydra runs its end-of-run callbacks and prints
    nothing of its own)."""
    try:
        yield
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - every error is reported, none is lost
        code = report(exc, prog)
        fail(code)
        if code == EXIT_USAGE:
            _status["refused_dir"] = _hydra_output_dir()


def _hydra_output_dir() -> str | None:
    """The output folder Hydra made for the running single (not swept) task, if any."""
    try:
        from hydra.core.hydra_config import HydraConfig

        hc = HydraConfig.get()
        if str(hc.mode) != "RunMode.RUN" or hc.output_subdir is None:
            return None
        return str(hc.runtime.output_dir)
    except Exception:  # noqa: BLE001 - not under Hydra
        return None


def _remove_refused_output(path: str | None, started: float) -> None:
    """A refusal writes nothing: the output folder Hydra made for a task that was then refused
    (its ``.hydra/`` and job log) is removed, with the parents it made (empty folders made since
    the command started). A folder holding anything else, or the launch folder itself, is left
    alone."""
    import shutil
    from pathlib import Path

    if not path:
        return
    run_dir, cwd = Path(path).resolve(), Path.cwd().resolve()
    if run_dir == cwd or cwd.is_relative_to(run_dir) or not run_dir.is_dir():
        return
    if any(not (e.name == ".hydra" or e.name.endswith(".log")) for e in run_dir.iterdir()):
        return
    if run_dir.stat().st_mtime < started - 1:
        return
    shutil.rmtree(run_dir, ignore_errors=True)
    parent = run_dir.parent
    while parent != cwd and parent != parent.parent and not cwd.is_relative_to(parent):
        try:
            if parent.stat().st_ctime < started - 1 or any(parent.iterdir()):
                break
            parent.rmdir()
        except OSError:
            break
        parent = parent.parent


def _take_verbose(argv: list) -> bool:
    """Remove ``--verbose`` from ``argv`` (in place: Hydra's parser does not know it); True if it
    was there."""
    found = VERBOSE_FLAG in argv
    argv[:] = [a for a in argv if a != VERBOSE_FLAG]
    return found


def _exit(code: int):
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    sys.exit(code)


#: marks HYDRA_FULL_ERROR as set by run_hydra (a command started by one is not thereby verbose)
_OURS = "STUDY_SET_HYDRA_FULL_ERROR"


#: Hydra's command-line flags that take a value (the rest of the command line is overrides)
_HYDRA_VALUE_FLAGS = ("--config-path", "-cp", "--config-name", "-cn", "--config-dir", "-cd", "--experimental-rerun",
                      "--package", "-p", "--info", "-i", "--cfg", "-c")


def overrides_of(argv: list) -> tuple[list, bool] | None:
    """``(overrides, multirun)`` of a Hydra command line, or None when it asks for something
    other than a run (``--help``, ``--cfg``, ``--info``, a shell completion, another config):
    those are Hydra's to answer."""
    over, multirun = [], False
    for a in argv:
        if a in ("-m", "--multirun"):
            multirun = True
        elif a.startswith("-"):
            return None
        else:
            over.append(a)
    return over, multirun


def check_overrides(overrides: list) -> None:
    """Each override parses (``key=value``); one that does not is refused naming it, with what
    was expected (Hydra's own message is a parser exception's name: an unquoted path with spaces,
    a stray word)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create()
    for i, o in enumerate(overrides):
        try:
            parser.parse_override(o)
        except Exception:  # noqa: BLE001 - Hydra raises its own or the lexer's exceptions
            hint = ""
            if "=" not in o and i > 0:
                hint = (f" (with {overrides[i - 1]!r} before it: a value with spaces must be quoted, "
                        f"'{overrides[i - 1]} {o}')")
            elif "=" not in o:
                hint = " (a setting is key=value)"
            raise ConfigError(f"command-line argument {o!r}: expected key=value, a Hydra override{hint}") from None


def run_hydra(hydra_main, prog: str, precheck=None):
    """Run a ``@hydra.main`` function as a command with one-line errors; exits the process.

    ``--verbose`` is taken off the command line (and exported as ``STUDY_VERBOSE=1``, so jobs in
    other processes see it too). ``HYDRA_FULL_ERROR=1`` makes Hydra re-raise what it would print as
    a traceback (a configuration that does not compose, an error in a sweep's job); it is reported
    here in one line.

    ``precheck(overrides, multirun)``, the command's checks of its composed configuration, runs
    before Hydra makes any folder or file: a refusal there writes nothing. A task refused later
    (status 2) has the output folder Hydra made for it removed again.
    """
    import time

    users = os.environ.get("HYDRA_FULL_ERROR") == "1" and os.environ.get(_OURS) != "1"  # not one we set
    if _take_verbose(sys.argv) or users:
        os.environ[VERBOSE_ENV] = "1"
    os.environ["HYDRA_FULL_ERROR"] = os.environ[_OURS] = "1"
    _status["code"], _status["refused_dir"] = EXIT_OK, None
    started = time.time()
    parsed = overrides_of(sys.argv[1:])
    if parsed is not None:
        def first():
            check_overrides(parsed[0])
            if precheck is not None:
                precheck(*parsed)
        _guarded(first, prog)  # a refusal exits here, before Hydra has made anything
    _guarded(hydra_main, prog)
    if _status["code"] == EXIT_USAGE:
        _remove_refused_output(_status["refused_dir"], started)
    _exit(_status["code"])


def _guarded(fn, prog: str):
    """``fn()`` with every exception reported in one line and turned into the process's exit
    status."""
    try:
        return fn()
    except BrokenPipeError:  # the reader went away (``| head``): no message, as other Unix tools
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(EXIT_FAILED)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        _exit(130)
    except SystemExit:
        raise
    except BaseException as exc:  # noqa: BLE001
        _exit(report(exc, prog))


def parser(prog: str, description: str, **kw) -> argparse.ArgumentParser:
    """An argument parser whose ``--help`` lists ``--verbose`` (which :func:`run` takes off the
    command line)."""
    ap = argparse.ArgumentParser(prog=f"python -m {prog}", description=description, **kw)
    ap.add_argument(VERBOSE_FLAG, action="store_true", help=f"print the traceback of an error (or {VERBOSE_ENV}=1)")
    return ap


def _one_line_usage(prog: str):
    """argparse's ``error`` as the other refusals: one line, ``<command>: error: <what>``, exit
    status 2 (argparse prints a usage block of several lines first)."""
    def error(self, msg):
        sub = self.prog.split()[3:] if self.prog.startswith("python -m ") else []  # a subcommand's parser
        where = " ".join([prog, *sub])
        print(f"{prog}: error: {msg}; expected the arguments `python -m {where} --help` lists",
              file=sys.stderr, flush=True)
        sys.exit(EXIT_USAGE)
    return error


def run(main, prog: str, argv: list | None = None):
    """Run an argparse command ``main(argv) -> exit status`` with one-line errors; exits the
    process."""
    args = list(sys.argv[1:] if argv is None else argv)
    if _take_verbose(args):
        os.environ[VERBOSE_ENV] = "1"
    argparse.ArgumentParser.error = _one_line_usage(prog)  # every parser and sub-parser of the command
    code = _guarded(lambda: main(args), prog)
    _exit(int(code or 0))


def status() -> int:
    """The exit status asked for so far."""
    return _status["code"]
