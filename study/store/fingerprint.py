"""The code fingerprint of a run: a hash of the source of the components it used, so that resume can
tell a result computed by today's code from one computed before, say, an estimator was fixed
(benchopt keys its cache the same way, on the source files of the solver, dataset and objective of a
result).

The components of a run, and the modules each starts from (:func:`entries`):

=============  ======================================================================================================
``simulator``  ``study.sim`` (the compiled integrator and the effects), the vessel kind's module (``vessel.kind``),
               ``study.records.measure``, ``study.sim.maneuvers``, and the YAML of every manoeuvre
               the run simulates (``conf/maneuver/<name>.yaml``: read at run time by its name, so
               not part of the configuration)
``model``      ``study.identify.models``, ``study.identify.regression``; with ``model.effects``: identification
               with effects, ``study.identify.with_effects``, every module of
               ``study.identify.effects`` and
               ``conf/effect/<name>.yaml``
``structure``  ``study.identify.structures``
``estimator``  the module of ``estimator._target_`` and ``study.identify.estimators`` (the factory); a module
               outside the repository (a user's own class) is hashed under its module name
``pipeline``   ``study.run.pipeline`` (a simulated run); a run on files (``train`` given): also ``study.run.records_run``,
               ``study.records.schema``, ``study.records.loaders``, ``study.records.vessel_checks``,
               ``study.records.maneuver_metrics`` and identification with effects (its replay); a
               doctor ladder step (``study: doctor``): ``study.commands.diagnose``, the doctor and
               identification with effects
=============  ======================================================================================================

A component is its entry modules **plus every module of the ``study`` package they import**, found
statically (the import lines of its source, those inside functions too), transitively:
``study.identify.fit`` is in the ``pipeline`` component because ``study.run.pipeline`` imports it.
An import *into* one of the :data:`OPTIONAL_PACKAGES` from a module outside it is not followed:
those packages run only when the configuration says so (``model.effects``, ``train``, ...), and they
are then entries. So editing the SVR estimator changes the fingerprint of SVR runs only, editing
``study/sim/mmg.py`` that of runs on MMG vessels, and editing the figures or the results store
changes none.

What is hashed is what Python executes (:data:`SCHEME` ``executed``): a module's source without its
comments, docstrings (and any other statement that is a bare string), blank lines and trailing
spaces (:func:`executed_source`), so that documenting a component leaves its results current while
any change to a statement stales them. Other files (YAML) are hashed on their contents. Line endings
are normalised to ``\\n`` and mtimes never enter: the same checkout gives the same fingerprint on
every machine, operating system and Python version (the positions come from :mod:`tokenize` and
:mod:`ast`, the text from the file). Each file is read and hashed once per process. A record written
before this rule (its ``code`` has no ``scheme``) was hashed on the files' bytes; it is compared
with the bytes' fingerprint (``code['bytes']``), so it stays current until a file of its components
changes at all. Not included: the versions of numpy, scipy, ... (they are in the record's
``provenance``) and the configuration (it is in the run id); ``resume=config`` reuses results
whatever code made
them.
"""
from __future__ import annotations

import ast
import hashlib
import importlib.util
import io
import re
import tokenize
from functools import lru_cache
from pathlib import Path

#: The folder holding the ``study`` package and ``conf/``; file keys are paths relative to it.
REPO_ROOT = Path(__file__).resolve().parents[2]
PACKAGE = "study"

#: Packages that run only when a run's configuration asks for them: imports into them from outside are not
#: followed (``study.run.pipeline`` imports ``study.identify.with_effects`` inside a function, for ``model.effects``
#: only).
OPTIONAL_PACKAGES = ("study.doctor", "study.identify.with_effects", "study.identify.effects", "study.run.records_run",
                     "study.commands", "study.figures", "study.store", "study.run.executor", "study.api")

#: How a Python file is hashed (stored as ``code['scheme']``): its executed source, :func:`executed_source`.
SCHEME = "executed"

COMPONENTS = ("simulator", "model", "structure", "estimator", "pipeline")
#: Hex digits kept of each file's hash in a record (48 bits: a collision between two versions of one file is
#: not a practical concern) and of each component's and the run's fingerprint.
FILE_DIGITS = 12
DIGITS = 16

_FILE_RUN_MODULES = ("study.run.records_run", "study.records.schema", "study.records.loaders", "study.records.vessel_checks",
                     "study.records.maneuver_metrics", "study.identify.with_effects", "study.identify.effects")


# ------------------------------------------------------------------------------------------------ modules
@lru_cache(maxsize=None)
def _module_file(module: str) -> Path | None:
    """The source file of a module of the ``study`` package (found on disk, never imported), else
    None."""
    if module != PACKAGE and not module.startswith(PACKAGE + "."):
        return None
    parts = module.split(".")
    if not all(p.isidentifier() for p in parts):  # a malformed name in a config (vessel.kind, _target_)
        return None
    base = REPO_ROOT.joinpath(*parts)
    for cand in (base.with_suffix(".py"), base / "__init__.py"):
        if cand.is_file():
            return cand
    return None


def _external_file(module: str) -> Path | None:
    """The source file of a module outside ``study`` (a user's own estimator class).
    ``find_spec`` of a dotted name imports its parent packages (not the module itself)."""
    if not all(p.isidentifier() for p in module.split(".")):
        return None
    try:
        spec = importlib.util.find_spec(module)
    except Exception:  # ImportError, ValueError, or whatever a parent package raises on import
        return None
    origin = getattr(spec, "origin", None) if spec is not None else None
    return Path(origin) if origin and origin.endswith(".py") and Path(origin).is_file() else None


def _optional_root(module: str) -> str | None:
    for pkg in OPTIONAL_PACKAGES:
        if module == pkg or module.startswith(pkg + "."):
            return pkg
    return None


# an import statement at the start of a line: `from <module> import <names or (names over lines)>`, `import <modules>`
_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+(\.*[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#;]*)|import[ \t]+([^\n#;]*))",
                     re.MULTILINE)


@lru_cache(maxsize=None)
def _imports(module: str) -> tuple:
    """The ``study`` modules that ``module`` imports anywhere in its source (sorted).

    Import lines are found with a regular expression, not ``ast``: parsing and walking the package's
    trees cost 0.5-1 s a process, the expression 10 ms. An import line quoted at the start of a
    docstring line counts too, which can only add a module to a component, never drop one.
    """
    path = _module_file(module)
    if path is None:
        return ()
    pkg = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for m in _IMPORT.finditer(_read(path)):
        src, names, plain = m.groups()
        if plain is not None:
            cands = [part.split()[0] for part in plain.split(",") if part.split()]
        else:
            level = len(src) - len(src.lstrip("."))
            target = src.lstrip(".")
            if level:
                parts = pkg.split(".")
                parts = parts[: len(parts) - (level - 1)]
                target = ".".join(parts + ([target] if target else []))
            # `from a import b` imports module a.b when b is a module, else a name of a
            cands = [target] + [f"{target}.{part.split()[0]}" for part in names.strip("()").split(",")
                                if part.split() and part.split()[0].isidentifier()]
        found.update(c for c in cands if _module_file(c) is not None)
    return tuple(sorted(found))


@lru_cache(maxsize=None)
def closure(entries: tuple) -> tuple:
    """``entries`` and every ``study`` module they import, transitively (imports from outside an
    optional package into it are not followed); sorted module names."""
    seen: set = set()
    todo = list(entries)
    while todo:
        mod = todo.pop()
        if mod in seen or _module_file(mod) is None:
            continue
        seen.add(mod)
        own = _optional_root(mod)
        for dep in _imports(mod):
            opt = _optional_root(dep)
            if opt is None or opt == own:
                todo.append(dep)
    return tuple(sorted(seen))


# ------------------------------------------------------------------------------------------------- hashing
@lru_cache(maxsize=None)
def _read(path: Path) -> str:
    return path.read_bytes().decode("utf-8", errors="surrogateescape")


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:FILE_DIGITS]


@lru_cache(maxsize=None)
def file_bytes_hash(path: Path) -> str:
    """sha256 of a file's contents with CRLF and CR line endings made LF (first
    :data:`FILE_DIGITS` hex digits): how every file was hashed before :data:`SCHEME`, and how
    YAML still is."""
    return _digest(path.read_bytes().replace(b"\r\n", b"\n").replace(b"\r", b"\n"))


@lru_cache(maxsize=None)
def file_hash(path: Path) -> str:
    """sha256 of what a file contributes to a run: a Python module's :func:`executed_source`, any
    other file's contents (line endings made LF; first :data:`FILE_DIGITS` hex digits)."""
    if path.suffix != ".py":
        return file_bytes_hash(path)
    return _digest(executed_source(_read(path).replace("\r\n", "\n").replace("\r", "\n")).encode(
        "utf-8", errors="surrogateescape"))


def executed_source(text: str) -> str:
    """``text`` (a module's source) without what Python does not execute: comments, statements
    that are a bare string (docstrings), blank lines and trailing spaces. A source that does not
    parse is returned whole (hashed as it is). Indentation and line breaks are kept: they are
    syntax."""
    lines = text.split("\n")
    try:
        tree = ast.parse(text)
        tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    except (SyntaxError, tokenize.TokenError, ValueError):
        return text
    drop: dict = {}  # line index -> [(first column, last column + 1)] in characters

    def cut(r0: int, c0: int, r1: int, c1: int) -> None:
        for r in range(r0, r1 + 1):
            drop.setdefault(r - 1, []).append((c0 if r == r0 else 0, c1 if r == r1 else len(lines[r - 1])))

    def chars(row: int, byte_col: int) -> int:  # ast's columns count UTF-8 bytes, tokenize's characters
        return len(lines[row - 1].encode("utf-8", errors="surrogateescape")[:byte_col].decode("utf-8", "ignore"))

    for node in ast.walk(tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            cut(node.lineno, chars(node.lineno, node.col_offset), node.end_lineno,
                chars(node.end_lineno, node.end_col_offset))
    for tok in tokens:
        if tok.type == tokenize.COMMENT:
            cut(tok.start[0], tok.start[1], tok.end[0], tok.end[1])
    out = []
    for i, line in enumerate(lines):
        if i in drop:
            keep = [True] * len(line)
            for a, b in drop[i]:
                keep[a:b] = [False] * (b - a)
            line = "".join(ch for ch, k in zip(line, keep) if k)
        line = line.rstrip()
        if line.strip():
            out.append(line)
    return "\n".join(out)


def _key(path: Path) -> str:
    """A file's name in a fingerprint: its path relative to the repository (the same on every
    machine)."""
    return path.resolve().relative_to(REPO_ROOT.resolve()).as_posix()


def _combine(files: dict) -> str:
    text = "\n".join(f"{k} {files[k]}" for k in sorted(files))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:DIGITS]


# ------------------------------------------------------------------------------------------------ a run
def _names(value) -> list:
    """Manoeuvre or effect names from a config value: a name, a list of names or of dicts with a
    name."""
    if value is None:
        return []
    items = value if isinstance(value, (list, tuple)) else [value]
    out = []
    for it in items:
        name = it.get("name") if isinstance(it, dict) else it
        if isinstance(name, str):
            out.append(name)
    return out


def _data_file(group: str, name: str) -> Path | None:
    if not name or "/" in name or "\\" in name or name.startswith("."):
        return None
    p = REPO_ROOT / "conf" / group / f"{name}.yaml"
    return p if p.is_file() else None


def entries(config: dict) -> dict:
    """Per component, ``(entry modules, extra files as (name, path))`` of a run's configuration (see
    the module
    docstring).
    Keys a configuration lacks are simply not used (a hand-made configuration gets the generic
    modules)."""
    config = config if isinstance(config, dict) else {}
    vessel = config.get("vessel") if isinstance(config.get("vessel"), dict) else {}
    model = config.get("model") if isinstance(config.get("model"), dict) else {}
    est = config.get("estimator") if isinstance(config.get("estimator"), dict) else {}
    on_files = config.get("train") is not None
    doctor = config.get("study") == "doctor"

    sim = ["study.sim", "study.records.measure", "study.sim.maneuvers"]
    kind = vessel.get("kind")
    if isinstance(kind, str):
        # study.sim.KINDS maps a kind to its module; read statically so nothing is imported here
        sim.append(f"study.sim.{kind}")
    sim_files = []
    if not on_files:
        mans = config.get("maneuvers") if isinstance(config.get("maneuvers"), dict) else {}
        for name in _names(mans.get("train")) + _names(mans.get("validate")):
            if (p := _data_file("maneuver", name)) is not None:
                sim_files.append((_key(p), p))

    mod = ["study.identify.models", "study.identify.regression"]
    mod_files = []
    effects = _names(model.get("effects"))
    if effects:
        mod += ["study.identify.with_effects", "study.identify.effects"]
        eff_dir = REPO_ROOT / "study" / "identify" / "effects"
        mod += [f"study.identify.effects.{p.stem}" for p in sorted(eff_dir.glob("*.py")) if p.stem != "__init__"]
        mod_files += [(_key(p), p) for n in effects if (p := _data_file("effect", n)) is not None]

    est_mods, est_files = ["study.identify.estimators"], []
    target = est.get("_target_")
    if isinstance(target, str) and "." in target:
        module = target.rpartition(".")[0]
        if _module_file(module) is not None:
            est_mods.append(module)
        elif (p := _external_file(module)) is not None:
            est_files.append((f"module {module}", p))  # by name: its path differs between machines

    pipe = ["study.run.pipeline"]
    if on_files:
        pipe += list(_FILE_RUN_MODULES)
    if doctor:
        pipe += ["study.commands.diagnose", "study.doctor.run", "study.doctor.diagnose", "study.identify.with_effects",
                 "study.identify.effects"]
    return {"simulator": (tuple(sim), tuple(sim_files)), "model": (tuple(mod), tuple(mod_files)),
            "structure": (("study.identify.structures",), ()), "estimator": (tuple(est_mods), tuple(est_files)),
            "pipeline": (tuple(pipe), ())}


@lru_cache(maxsize=256)
def _fingerprint_of(spec: tuple, hasher=file_hash) -> tuple:
    files, comps = {}, {}
    for name, mods, extra in spec:
        own = {_key(p): hasher(p) for p in (_module_file(m) for m in closure(mods)) if p is not None}
        own.update({key: hasher(p) for key, p in extra})
        comps[name] = _combine(own)
        files.update(own)
    return _combine(comps), tuple(sorted(comps.items())), tuple(sorted(files.items()))


def code_fingerprint(config: dict) -> dict:
    """The fingerprint of the code a run of ``config`` uses, as stored in its record under ``code``.

    Returns
    -------
    dict
        ``fingerprint`` (hash of the components' hashes), ``components`` (``{component: hash}``, see
        the module docstring) and ``files`` (``{path relative to the repository: hash of its
        contents}``, the union over the components). Computed from the files on disk, once per
        process for each distinct set of modules.
    """
    spec = tuple((name, mods, extra) for name, (mods, extra) in entries(config).items())
    fp, comps, files = _fingerprint_of(spec)
    fp_bytes, comps_bytes, _ = _fingerprint_of(spec, file_bytes_hash)
    return {"scheme": SCHEME, "fingerprint": fp, "components": dict(comps), "files": dict(files),
            "bytes": {"fingerprint": fp_bytes, "components": dict(comps_bytes)}}


def same_code(stored_fingerprint, current: dict) -> bool:
    """Whether a table's ``code_fingerprint`` is the current code's, under either hashing (a run
    recorded before :data:`SCHEME` holds the bytes' fingerprint)."""
    return stored_fingerprint is not None and stored_fingerprint in (
        current["fingerprint"], (current.get("bytes") or {}).get("fingerprint"))


def changed_components(stored: dict | None, current: dict) -> list:
    """The components whose code differs between a record's ``code`` and the current one
    (``['unknown']`` for a record without a fingerprint, ``[]`` when unchanged)."""
    if not isinstance(stored, dict) or not isinstance(stored.get("components"), dict):
        return ["unknown"]
    if stored.get("scheme") != current.get("scheme") and isinstance(current.get("bytes"), dict):
        current = current["bytes"]  # recorded before the executed-source hashing: compared on the files' bytes
    if stored.get("fingerprint") == current["fingerprint"]:
        return []
    old, new = stored["components"], current["components"]
    return sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))


def clear_cache() -> None:
    """Forget every file read and hash (for a process that edits the source it fingerprints:
    tests)."""
    for f in (_module_file, _imports, closure, _read, file_hash, file_bytes_hash, _fingerprint_of):
        f.cache_clear()
