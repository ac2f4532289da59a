"""MkDocs hook: the figures the pages show are the ones in ``paper_figs/`` (rebuilt by ``python -m study figures``),
added to the site as they are instead of being copied into ``docs/``. Only the figures a page references."""
from __future__ import annotations

import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
FIGURE = re.compile(r"\((?:\.\./)*(paper_figs/[^)\s]+\.(?:png|svg))\)")


def on_files(files, config):
    wanted = set()
    for page in Path(config["docs_dir"]).rglob("*.md"):
        wanted.update(FIGURE.findall(page.read_text(encoding="utf-8")))
    for rel in sorted(wanted):
        if (ROOT / rel).is_file():  # a missing figure stays a broken link, which --strict reports
            files.append(File(rel, src_dir=str(ROOT), dest_dir=config["site_dir"],
                              use_directory_urls=config["use_directory_urls"]))
    return files
