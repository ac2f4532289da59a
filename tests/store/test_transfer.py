"""Finished runs moved between results folders: export, import, resume from what arrived; archives that
are not runs refused before anything is written."""
import io
import json
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from study.store import ResultStore, run_id
from study.store.transfer import ArchiveError, export_runs, import_runs

REPO = Path(__file__).resolve().parents[2]


def _record(seed, study="demo", status="ok", value=1.0):
    conf = {"seed": seed, "study": study, "vessel": {"name": "kvlcc2"}, "estimator": {"name": "ls"}}
    return {"run_id": run_id(conf), "status": status, "config": conf, "seed": seed,
            "error": None if status == "ok" else "it broke", "started": "2024-01-01T00:00:00+00:00",
            "finished": "2024-01-01T00:00:01+00:00", "metrics": {"drift_median": 0.01},
            "params": [{"equation": "N", "name": "Nr", "estimate": value, "truth": 1.0}], "timings": {"fit": 0.1}}


def _store(tmp_path, name="a"):
    s = ResultStore(tmp_path / name)
    s.write(_record(0), artefacts={"validation/zz.csv": b"t,psi\n0,0\n"})
    s.write(_record(1))
    s.write(_record(2, study="other"))
    s.write(_record(3, status="failed"))
    return s


def test_export_then_import_carries_finished_runs_and_their_artefacts(tmp_path):
    src = _store(tmp_path)
    assert export_runs(src, tmp_path / "all.tar.xz") == 3  # the failed run stays behind
    assert export_runs(src, tmp_path / "demo.tar.gz", study="demo") == 2
    dst = ResultStore(tmp_path / "b")
    rep = import_runs(dst, tmp_path / "demo.tar.gz")
    assert len(rep.added) == 2 and not rep.kept and rep.artefact_files == 1
    r0 = _record(0)["run_id"]
    assert dst.read(r0) == src.read(r0)  # the same record, provenance and all
    assert (dst.artefact_dir(r0) / "validation" / "zz.csv").read_bytes() == b"t,psi\n0,0\n"
    assert not dst.finished(_record(2, study="other")["run_id"])  # another study's run did not travel
    # importing again adds nothing and keeps what is there
    again = import_runs(dst, tmp_path / "all.tar.xz")
    assert sorted(again.kept) == sorted(rep.added) and again.added == [_record(2, study="other")["run_id"]]


def test_artefacts_stream_in_any_member_order_and_never_as_bytes(tmp_path, monkeypatch):
    """An archive whose members come in another order (artefacts before their record, runs interleaved) imports the
    same; each artefact reaches the store as a file, not as bytes held in memory."""
    src = ResultStore(tmp_path / "a")
    for seed in range(3):
        src.write(_record(seed), artefacts={"validation/zz.csv": f"t,psi\n{seed},0\n".encode(),
                                            "fit/rows.csv": f"x\n{seed}\n".encode()})
    export_runs(src, tmp_path / "x.tar")
    with tarfile.open(tmp_path / "x.tar") as tar:
        members = [(m, tar.extractfile(m).read() if m.isfile() else None) for m in tar.getmembers()]
    with tarfile.open(tmp_path / "shuffled.tar.gz", "w:gz") as tar:
        for m, data in reversed(members):
            tar.addfile(m, io.BytesIO(data) if data is not None else None)
    written = []
    original = ResultStore.write

    def spy(self, record, overwrite=False, artefacts=None):
        written.append({k: type(v) for k, v in (artefacts or {}).items()})
        return original(self, record, overwrite=overwrite, artefacts=artefacts)

    monkeypatch.setattr(ResultStore, "write", spy)
    dst = ResultStore(tmp_path / "b")
    rep = import_runs(dst, tmp_path / "shuffled.tar.gz")
    assert len(rep.added) == 3 and rep.artefact_files == 6
    assert all(t is not bytes for w in written for t in w.values()) and len(written) == 3
    for seed in range(3):
        rid = _record(seed)["run_id"]
        assert dst.read(rid) == src.read(rid)
        assert (dst.artefact_dir(rid) / "validation" / "zz.csv").read_text() == f"t,psi\n{seed},0\n"
        assert (dst.artefact_dir(rid) / "fit" / "rows.csv").read_text() == f"x\n{seed}\n"


def test_records_only_keep_their_artefact_list(tmp_path):
    src = _store(tmp_path)
    export_runs(src, tmp_path / "r.tar", artefacts=False)
    dst = ResultStore(tmp_path / "b")
    import_runs(dst, tmp_path / "r.tar")
    r0 = _record(0)["run_id"]
    assert dst.read(r0)["artefacts"] == ["validation/zz.csv"]
    assert not dst.artefact_dir(r0).exists()


def test_a_finished_run_is_kept_and_a_failed_one_replaced(tmp_path):
    src = _store(tmp_path)
    dst = ResultStore(tmp_path / "b")
    dst.write(_record(0, value=2.0))          # finished here with another value: kept
    dst.write(_record(1, status="failed"))    # failed here: the archive's finished run replaces it
    export_runs(src, tmp_path / "x.tar.xz")
    rep = import_runs(dst, tmp_path / "x.tar.xz")
    assert rep.kept == [_record(0)["run_id"]]
    assert dst.read(_record(0)["run_id"])["params"][0]["estimate"] == 2.0
    assert dst.read(_record(1)["run_id"])["status"] == "ok"
    assert len(list(dst.failed_dir.glob("*.json"))) == 1  # the failed attempt is kept, as for any retried run


def _tar(members: dict) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return buf.getvalue()


@pytest.mark.parametrize("members, says", [
    ({"records/x.json": b"{"}, "not valid JSON"),
    ({"notes.txt": b"hi"}, "expected records/<run_id>.json"),
    ({"records/0123456789abcdef.json": json.dumps(_record(0)).encode()}, "is not its file name"),
    ({f"records/{_record(3)['run_id']}.json": json.dumps(_record(3, status='failed')).encode()},
     "expected a finished run"),
    ({f"records/{_record(0)['run_id']}.json": json.dumps(_record(0)).encode(),
      "artefacts/0123456789abcdef/a.csv": b"1"}, "has no record in the archive"),
    ({"../records/evil.json": b"{}"}, "no links, absolute paths or '..'"),
])
def test_an_archive_that_is_not_runs_is_refused_before_any_write(tmp_path, members, says):
    good = {f"records/{_record(1)['run_id']}.json": json.dumps(_record(1)).encode()}
    (tmp_path / "bad.tar").write_bytes(_tar({**good, **members}))
    dst = ResultStore(tmp_path / "b")
    with pytest.raises(ArchiveError) as e:
        import_runs(dst, tmp_path / "bad.tar")
    assert says in str(e.value) and "bad.tar" in str(e.value)
    assert not dst.root.exists()  # not even the folder: the good member was not written either


def test_export_refuses_an_unknown_ending_and_an_empty_selection(tmp_path):
    src = _store(tmp_path)
    with pytest.raises(ArchiveError, match=r"x\.zip: expected a name ending in one of"):
        export_runs(src, tmp_path / "x.zip")
    with pytest.raises(ArchiveError, match="no finished run of study 'nope'"):
        export_runs(src, tmp_path / "x.tar", study="nope")
    assert not list(tmp_path.glob("x.*")) and not list(tmp_path.glob(".x.*"))


@pytest.mark.slow
def test_the_command_line_exports_imports_and_refuses_with_one_line(tmp_path):
    _store(tmp_path)
    cli = [sys.executable, "-m", "study", "results"]
    out = subprocess.run([*cli, "export", "--root", str(tmp_path / "a"), "--study", "demo", "--no-artefacts",
                          str(tmp_path / "d.tar.xz")], capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0 and "2 finished run(s) of demo" in out.stdout, out.stderr
    out = subprocess.run([*cli, "import", "--root", str(tmp_path / "b"), str(tmp_path / "d.tar.xz")],
                         capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0 and "2 run(s) added" in out.stdout, out.stderr
    assert (tmp_path / "b" / "runs.parquet").exists()
    (tmp_path / "junk.tar").write_text("not a tar")
    out = subprocess.run([*cli, "import", "--root", str(tmp_path / "c"), str(tmp_path / "junk.tar")],
                         capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 2 and not (tmp_path / "c").exists()
    assert out.stderr.strip().count("\n") == 0 and "junk.tar: not a readable tar archive" in out.stderr
