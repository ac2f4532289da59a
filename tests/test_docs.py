"""What the README and the documentation site promise, checked: the README is a landing page of at most 250 lines
with the two quickstart commands CI runs; the configuration page's group table lists every option of every group
in conf/; the studies page's claims table is ``paper_figs/CLAIMS.md``'s; the site builds with ``mkdocs build
--strict``; every file under ``paper_figs/`` that the README or a documentation page links, shows or names exists
(also where mkdocs is not installed); and without the real data ``python -m study reality_check`` stops with one line saying where it looked
and how to point at the data (not a KeyError). The layer table (docs/concepts/architecture.md) is checked
against ``.importlinter`` by tests/test_architecture.py."""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIG_PAGE = ROOT / "docs" / "reference" / "config.md"
STUDIES_PAGE = ROOT / "docs" / "studies" / "index.md"

#: the quickstart commands, exactly: .ci/run runs the second
QUICKSTART = ("pip install -e '.[test]' && python -m study", "pip install -e '.[test]' && python -m pytest -n auto --dist loadfile")


def test_the_readme_is_a_landing_page():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines (at most 250)"
    for cmd in QUICKSTART:
        assert cmd in lines, f"README.md lacks the quickstart command line `{cmd}`"
    assert QUICKSTART[1] in (ROOT / ".ci" / "run").read_text().splitlines(), ".ci/run no longer runs the README's tests"
    for image in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        assert (ROOT / image).is_file(), f"README.md shows {image}, which does not exist"


def test_the_readme_links_resolve():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    links = [t for t in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text) if "://" not in t]
    assert links
    missing = [t for t in links if not (ROOT / t).exists()]
    assert not missing, f"README.md links to {missing}"


#: a Markdown link or image target, ``[text](target)`` or ``![alt](target "title")``, without its #anchor
LINK = re.compile(r"\]\(\s*<?([^)\s>#]+)(?:#[^)\s]*)?>?(?:\s+\"[^\"]*\")?\s*\)")
#: a file under paper_figs/ named in code (`paper_figs/CLAIMS.md`), not a pattern (`paper_figs/<study>/`)
NAMED = re.compile(r"`(?:\.\./)*(paper_figs/[^`\s<>*{}]+\.[A-Za-z0-9]+)`")


def _pages() -> list:
    return [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))


def paper_figs_targets(page: Path, text: str) -> list:
    """(target as written, the repository path it shows) of every link, image and named file under paper_figs/
    on a page. The README's links resolve from the repository root; a documentation page's from its place in the
    site, where docs/hooks.py puts paper_figs/ at the site's root (``../paper_figs/x.png`` from docs/studies/)."""
    import posixpath

    out = []
    for t in LINK.findall(text):
        if "://" in t or "paper_figs/" not in t:
            continue
        if page == ROOT / "README.md":
            out.append((t, posixpath.normpath(t)))
        else:
            here = page.parent.relative_to(ROOT / "docs").as_posix()
            out.append((t, posixpath.normpath(posixpath.join(here, t))))
    out += [(t, t) for t in NAMED.findall(text)]
    return out


def test_every_paper_figs_file_the_readme_and_docs_link_exists():
    """Every figure, table or file under paper_figs/ that README.md or a page of docs/ links, shows or names
    exists, and a documentation page's link reaches it from where the page stands in the site."""
    found, missing = 0, []
    for page in _pages():
        for written, rel in paper_figs_targets(page, page.read_text(encoding="utf-8")):
            found += 1
            if not rel.startswith("paper_figs/") or not (ROOT / rel).is_file():
                missing.append(f"{page.relative_to(ROOT)}: {written}")
    assert found >= 10, found  # the pages show paper_figs/ figures: a pattern that finds none is broken
    assert not missing, f"links to files that do not exist (rebuild with python -m study figures?): {missing}"


def test_the_paper_figs_link_check_can_fail():
    docs = ROOT / "docs" / "studies" / "index.md"
    text = ("![a](../paper_figs/grand/drift_vs_noise.png) [b](../../paper_figs/CLAIMS.md) "
            "`paper_figs/nowhere.md` [c](https://example.org/paper_figs/x.png) `paper_figs/<study>/`")
    got = paper_figs_targets(docs, text)
    assert got == [("../paper_figs/grand/drift_vs_noise.png", "paper_figs/grand/drift_vs_noise.png"),
                   ("../../paper_figs/CLAIMS.md", "../paper_figs/CLAIMS.md"),
                   ("paper_figs/nowhere.md", "paper_figs/nowhere.md")]
    assert not any(r.startswith("paper_figs/") and (ROOT / r).is_file() for _, r in got)
    readme = paper_figs_targets(ROOT / "README.md", "![x](paper_figs/seed000_svr_mmg/drift_heatmap_none.png)")
    assert readme == [("paper_figs/seed000_svr_mmg/drift_heatmap_none.png",
                       "paper_figs/seed000_svr_mmg/drift_heatmap_none.png")]


def _group_rows() -> dict:
    text = CONFIG_PAGE.read_text(encoding="utf-8")
    table = text.split("## Config groups", 1)[1]
    table = table[table.index("| group |"):].split("\n\n", 1)[0]
    rows = {}
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) >= 3 and cells[0].startswith("`"):
            rows[cells[0].strip("`")] = set(re.findall(r"`([^`=]+)`", cells[1]))
    return rows


GROUPS = sorted(p.name for p in (ROOT / "conf").iterdir() if p.is_dir() and p.name != "hydra") + ["hydra/launcher"]


@pytest.mark.parametrize("group", GROUPS)
def test_config_group_table_lists_every_option(group):
    rows = _group_rows()
    assert group in rows, f"{CONFIG_PAGE.relative_to(ROOT)}'s config-group table has no row for `{group}`"
    options = {p.stem for p in (ROOT / "conf" / group).glob("*.yaml")}
    missing = sorted(options - rows[group])
    assert not missing, f"{CONFIG_PAGE.relative_to(ROOT)}'s config-group table misses {missing} of `{group}`"


def _claim_rows(text: str, verdict_col: int) -> list:
    out = []
    for ln in text.splitlines():
        if ln.startswith("| ") and not re.match(r"\| (seed|paper) \|", ln) and "`" not in ln.split("|")[1]:
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", ln)[1:-1]]
            if len(cells) > verdict_col and cells[verdict_col].startswith("**"):
                out.append((cells[0], cells[1], cells[verdict_col]))
    return out


def _paper(cell: str) -> str:
    """CLAIMS.md names a paper by its number in the project and its authors, ``000 (Song et al. 2025)``; the
    documentation by its authors alone."""
    m = re.fullmatch(r"\d{3} \((.+)\)", cell)
    return m.group(1) if m else cell


def test_the_studies_page_does_not_copy_the_verdicts():
    """The verdicts are written in one place, paper_figs/CLAIMS.md (rebuilt with the figures); the studies page
    points to it instead of a copy that would go stale."""
    page = STUDIES_PAGE.read_text(encoding="utf-8")
    sec = page[page.index("## The papers' claims, tested"):]
    sec = sec[:sec.index("\n## ", 1)]
    assert "paper_figs/CLAIMS.md" in sec and not _claim_rows(sec, 2)


def test_the_claims_check_can_fail():
    row = "| 000 (Song et al. 2025) | a claim | `seed000_svr_mmg` | **holds** | n |"
    assert [(_paper(a), b, c) for a, b, c in _claim_rows(row, 3)] == [("Song et al. 2025", "a claim", "**holds**")]
    assert _claim_rows("| Song et al. 2025 | a claim | **does not hold** |", 2) != [("Song et al. 2025", "a claim",
                                                                                      "**holds**")]


@pytest.mark.slow
def test_the_site_builds_strict(tmp_path):
    """``mkdocs build --strict`` from the checkout: every page, link, anchor, figure and the API reference."""
    if shutil.which("mkdocs") is None and not _importable("mkdocs"):
        pytest.skip("mkdocs is not installed (pip install -e '.[docs]', or the test extra)")
    for mod in ("material", "mkdocstrings_handlers.python"):
        if not _importable(mod):
            pytest.skip(f"{mod} is not installed (pip install -e '.[docs]')")
    site = tmp_path / "site"
    p = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)], cwd=ROOT,
                       capture_output=True, text=True, timeout=600, env={**_env(), "NO_MKDOCS_2_WARNING": "1"})
    assert p.returncode == 0, p.stdout + p.stderr
    assert (site / "index.html").is_file() and (site / "reference" / "api" / "index.html").is_file()
    api = (site / "reference" / "api" / "index.html").read_text(encoding="utf-8")
    import study

    for verb in study.__all__:
        assert verb in api, f"the API page does not document {verb}"
    assert (site / "paper_figs" / "seed000_svr_mmg" / "drift_heatmap_none.png").is_file()


def _importable(mod: str) -> bool:
    import importlib.util

    try:
        return importlib.util.find_spec(mod) is not None
    except ModuleNotFoundError:
        return False


def _env() -> dict:
    import os

    return {k: v for k, v in os.environ.items()}


def test_reality_check_without_data_says_where_in_one_line(tmp_path):
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT), "STUDY_REAL_DATA": str(tmp_path / "nowhere"),
           "OPENBLAS_NUM_THREADS": "1"}
    p = subprocess.run([sys.executable, "-m", "study", "reality_check", "--out", str(tmp_path / "out")], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    assert "kvlcc2_hsva/raw_data/*.dat" in lines[0] and str(tmp_path / "nowhere") in lines[0]
    assert "STUDY_REAL_DATA" in lines[0] and "KeyError" not in p.stderr
    assert not (tmp_path / "out").exists()
