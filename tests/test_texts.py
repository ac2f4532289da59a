"""The texts a user reads name the papers by authors and year and say nothing of the project's own history or of
one machine: no "issue N", no "seed 00N" (a study's file name such as ``seed000_svr_mmg`` is fine), no revision id
(a 40- or 7-12-hex commit id), no "this machine" or "2-core", in the README, the documentation site's pages, the
notebooks' text, the docstrings of the package and the commands' help.

Each check is also run on a sentence that breaks it, so it can fail.
"""
from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from study.commands import names as command_names

REPO = Path(__file__).resolve().parents[1]

#: what must not appear, with why
FORBIDDEN = {
    "an issue number": re.compile(r"\bissues?\s*#?\d+", re.I),
    "a source paper by its seed number (name it by authors and year)": re.compile(r"\bseeds?\s+00\d\b", re.I),
    "a revision id": re.compile(r"(?<![0-9A-Za-z_./-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)(?:[0-9a-f]{40}|[0-9a-f]{7,12})"
                                r"(?![0-9A-Za-z_])"),
    "a note about one machine": re.compile(r"\bthis (?:2-core )?(?:machine|box)\b|\b2-core\b", re.I),
}



def problems(text: str) -> list[str]:
    out = []
    for why, rx in FORBIDDEN.items():
        for m in rx.finditer(text):
            line = text[:m.start()].count("\n") + 1
            out.append(f"line {line}: {m.group(0)!r} ({why})")
    return out


@pytest.mark.parametrize("bad", ["see issue 13", "Issues 10-13", "seed 000 eq. 2", "as seed 004 did",
                                 "revision 62b33f6", "commit 0123456789abcdef0123456789abcdef01234567",
                                 "on this machine", "this 2-core box", "a 2-core CI runner"])
def test_the_checks_find_what_they_forbid(bad):
    assert problems(bad), bad


@pytest.mark.parametrize("good", ["experiment=seed000_svr_mmg", "paper_figs/seed004_kt_de/", "seeds 1-60",
                                  "seed 0 only", "Song et al. (2025) eq. 13", "1e-6", "run id 3f2a9c1d00b4e5f6",
                                  "deadline", "1234567 rows", "ffffff colour", "two cores"])
def test_the_checks_leave_ordinary_text_alone(good):
    assert not problems(good), problems(good)


def _pages() -> list[Path]:
    return [REPO / "README.md", REPO / "results" / "README.md"] + sorted((REPO / "docs").rglob("*.md")) + [REPO / "mkdocs.yml"]


@pytest.mark.parametrize("path", _pages(), ids=lambda p: str(p.relative_to(REPO)))
def test_readme_and_docs(path):
    found = problems(path.read_text(encoding="utf-8"))
    assert not found, f"{path.relative_to(REPO)}:\n" + "\n".join(found)


def _notebooks() -> list[Path]:
    return sorted((REPO / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", _notebooks(), ids=lambda p: p.name)
def test_notebooks(path):
    nb = json.loads(path.read_text(encoding="utf-8"))
    text = "\n".join("".join(c["source"]) for c in nb["cells"])
    found = problems(text)
    assert not found, f"{path.name}:\n" + "\n".join(found)


def _docstrings(path: Path) -> list[tuple[str, int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = []
    for node in [tree] + [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                                      ast.ClassDef))]:
        doc = ast.get_docstring(node, clean=False)
        if doc:
            out.append((getattr(node, "name", "<module>"), getattr(node, "lineno", 1), doc))
    return out


def test_docstrings_of_the_package():
    modules = sorted((REPO / "study").rglob("*.py")) + sorted((REPO / "hydra_plugins").rglob("*.py"))
    assert len(modules) > 50
    found = []
    for path in modules:
        rel = str(path.relative_to(REPO))
        for name, line, doc in _docstrings(path):
            found += [f"{rel}:{line} {name}: {p}" for p in problems(doc)]
    assert not found, "\n".join(found)


#: every command (the app and each discovered command), with how it shows its help
COMMANDS = [["study", "--help"]] + [["study", name, "--help"] for name in command_names()]


def test_the_commands_help():
    env = {**os.environ, "PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1"}
    procs = [(c, subprocess.Popen([sys.executable, "-m", *c], cwd=REPO, env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)) for c in COMMANDS]
    found = []
    for c, p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, f"python -m {' '.join(c)}: exit {p.returncode}\n{err}"
        assert len(out.strip().splitlines()) >= 3, f"python -m {' '.join(c)}: no help\n{out}"
        found += [f"python -m {' '.join(c)}: {x}" for x in problems(out)]
        if c == ["study", "--help"]:  # the app's help names every command (its list is written by hand)
            missing = [n for n in command_names() if n not in out]
            assert not missing, f"python -m study --help does not name the commands {missing}"
        if c[1:2] in (["--help"], ["simulate"], ["diagnose"]):  # Hydra's help template, conf/hydra/help/
            assert "Example" in out and "Usage: python -m" in out, f"python -m {' '.join(c)}: no usage or example"
    assert not found, "\n".join(found)


def _reports() -> list[Path]:
    figs = REPO / "paper_figs"
    return (sorted(figs.rglob("*.md")) + sorted(figs.glob("*/index.json"))
            + sorted(figs.glob("doctor/*/report.json")))


@pytest.mark.parametrize("path", _reports(), ids=lambda p: str(p.relative_to(REPO)))
def test_reports(path):
    """The committed reports and figure indexes (captions, claims, the doctor's reports): a report's provenance
    (its git revision, on purpose; in a study's index and CLAIMS.md the revisions that computed its runs) is left
    out of the check."""
    text = path.read_text(encoding="utf-8")
    if path.name == "report.json":
        rep = json.loads(text)
        rep.pop("provenance", None)
        text = json.dumps(rep)
    elif path.name == "index.json":  # a study's provenance: the revisions that computed its runs
        idx = json.loads(text)
        idx.pop("code", None)
        text = json.dumps(idx)
    elif path.name == "CLAIMS.md":  # its provenance section names those revisions, on purpose
        text = text.split("\n## The runs behind each study", 1)[0]
    found = problems(text)
    assert not found, f"{path.relative_to(REPO)}:\n" + "\n".join(found[:10])
