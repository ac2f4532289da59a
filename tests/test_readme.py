"""What the README promises about configuration and data: its config-group table lists every option of every group
in conf/, and without the real data `python -m study.reality_check` stops with one line saying where it looked and
how to point at the data (not a KeyError)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _group_rows() -> dict:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    table = text.split("## Config groups", 1)[1].lstrip("\n").split("\n\n", 1)[0]
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
    assert group in rows, f"README's config-group table has no row for `{group}`"
    options = {p.stem for p in (ROOT / "conf" / group).glob("*.yaml")}
    missing = sorted(options - rows[group])
    assert not missing, f"README's config-group table misses {missing} of `{group}`"


def test_reality_check_without_data_says_where_in_one_line(tmp_path):
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT), "STUDY_REAL_DATA": str(tmp_path / "nowhere"),
           "OPENBLAS_NUM_THREADS": "1"}
    p = subprocess.run([sys.executable, "-m", "study.reality_check", "--out", str(tmp_path / "out")], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    assert "kvlcc2_hsva/raw_data/*.dat" in lines[0] and str(tmp_path / "nowhere") in lines[0]
    assert "STUDY_REAL_DATA" in lines[0] and "KeyError" not in p.stderr
    assert not (tmp_path / "out").exists()
