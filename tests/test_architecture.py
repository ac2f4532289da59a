"""The architecture, checked: the layers of ``.importlinter`` hold (import-linter, every import including those
inside functions), no contract lists an exception, no module of the package is in an import cycle, and the
layer table of the documentation (docs/concepts/architecture.md) is the contract's.

The import graph is built from the source on disk every time (no cache): a test must not depend on a cache's
state.
"""
from __future__ import annotations

import re
from pathlib import Path

import grimp  # import-linter's import graph (import-linter is in the test extras)
from importlinter import api as importlinter_api

import study

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / ".importlinter"


def _contracts() -> list[dict]:
    return importlinter_api.read_configuration(str(CONFIG))["contracts_options"]


def test_the_package_checked_is_this_checkout():
    """grimp reads the ``study`` found on sys.path: it must be the one these tests import, from this repository."""
    assert Path(study.__file__).resolve().parent == REPO / "study"


def test_every_contract_is_kept(capsys):
    from importlinter.application.use_cases import lint_imports

    ok = lint_imports(config_filename=str(CONFIG), cache_dir=None, no_logo=True)
    report = capsys.readouterr().out
    assert ok, f"broken import contracts (.importlinter):\n{report}"
    assert "0 broken" in report


def test_no_contract_lists_an_exception():
    """No ``ignore_imports`` (nor exhaustiveness exceptions): the layers hold for every import, as they are."""
    contracts = _contracts()
    assert contracts
    for c in contracts:
        assert not c.get("ignore_imports"), f"contract '{c['name']}' lists exceptions: {c['ignore_imports']}"
        assert not c.get("exhaustive_ignores"), f"contract '{c['name']}' leaves modules out: {c['exhaustive_ignores']}"
        assert not c.get("allow_indirect_imports") or c["allow_indirect_imports"] in ("False", "false")


def test_the_package_layers_cover_every_module():
    """The top-level contract is exhaustive over ``study``: a new module must be given its layer."""
    top = [c for c in _contracts() if c.get("containers") in ("study", ["study"])]
    assert len(top) == 1 and top[0]["type"] == "layers"
    assert str(top[0].get("exhaustive")).lower() == "true"


def _cycle_through(graph, importer: str, imported: str):
    back = graph.find_shortest_chain(importer=imported, imported=importer)
    return (importer,) + back if back else None


def test_no_module_is_in_an_import_cycle():
    """Module by module (a package's ``__init__`` and its own submodules too, which import-linter's sibling check
    does not compare), over the package and its Hydra plugins: for every import a -> b, no chain leads from b
    back to a."""
    graph = grimp.build_graph("study", "hydra_plugins", cache_dir=None)
    cycles = set()
    # the project's own modules (hydra_plugins is a namespace shared with the installed Hydra plugins)
    own = [m for m in sorted(graph.modules) if m.split(".")[0] == "study" or m.startswith("hydra_plugins.study_")]
    for importer in own:
        for imported in sorted(graph.find_modules_directly_imported_by(importer)):
            cyc = _cycle_through(graph, importer, imported)
            if cyc:
                cycles.add(" -> ".join(cyc))
    assert not cycles, "import cycles:\n" + "\n".join(sorted(cycles))


def test_the_cycle_check_finds_a_cycle():
    """The check above can fail: the same function finds a cycle added to the real graph."""
    graph = grimp.build_graph("study", cache_dir=None)
    assert _cycle_through(graph, "study.sim.core", "study.sim.maneuvers") is None
    graph.add_import(importer="study.sim.maneuvers", imported="study.sim")  # a cycle the layers forbid
    cyc = _cycle_through(graph, "study.sim.maneuvers", "study.sim")
    assert cyc is not None and cyc[0] == cyc[-1] == "study.sim.maneuvers"


#: the page that describes the layers
LAYERS_PAGE = REPO / "docs" / "concepts" / "architecture.md"


def _docs_layers() -> list[str]:
    """The module cells of the documentation's layer table (``## Layers`` of docs/concepts/architecture.md), top to
    bottom."""
    text = LAYERS_PAGE.read_text(encoding="utf-8")
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ") and "layer" not in line.lower()[:12]]
    out = []
    for line in rows:
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) >= 2 and re.fullmatch(r"\d+", cells[0]):
            out.append(" | ".join(re.findall(r"`([\w.]+)`", cells[1])))
    return out


def test_the_docs_describe_the_layers_as_they_are():
    top = [c for c in _contracts() if c.get("containers") in ("study", ["study"])][0]
    layers = top["layers"] if isinstance(top["layers"], list) else top["layers"].split("\n")
    want = [" | ".join(m.strip() for m in re.split(r"[|:]", layer) if m.strip()) for layer in layers if layer.strip()]
    assert _docs_layers() == want
