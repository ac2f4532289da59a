"""Equivalence check of study runs with ``model.effects`` and of runs on records, across two versions of the code.

A sibling of ``scripts/engine_equivalence.py`` (which checks ``identify`` itself): here whole runs go through
``study.run.pipeline.run_study``, so the branch a run takes on ``model.effects`` (simulated and on records), the
rows it writes and its validation are compared. Per configuration the run's ``status``, ``error``, ``metrics``,
``params`` and the sha256 of every artefact are dumped (timings left out); ``compare`` reports the differences
exactly (floats bit for bit, NaN equal to NaN), metric by metric.

The records of the runs on files are simulated once into a folder (``--records``, default
``/tmp/effects_equivalence_records``) and reused by both sides, so the paths in the metrics agree::

    cd /tmp/base && PYTHONPATH=/tmp/base python /path/to/scripts/effects_equivalence.py dump /tmp/base_fx.pkl
    cd /work/wt && PYTHONPATH=/work/wt python scripts/effects_equivalence.py dump /tmp/new_fx.pkl
    python scripts/effects_equivalence.py compare /tmp/base_fx.pkl /tmp/new_fx.pkl
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from engine_equivalence import _order, _same  # noqa: E402

SIM = ["experiment=tiny", "noise=low_relative"]
#: simulated runs: {key: overrides}
SIMULATED = {
    "sim/known/current": ["model=known", "model.effects=[current]", "environment=current"],
    "sim/mmg_hull/current": ["model=mmg_hull", "model.effects=[current]", "environment=current"],
    "sim/mmg_hull/current/ridge": ["model=mmg_hull", "model.effects=[current]", "environment=current",
                                   "estimator=ridge"],
    "sim/known/rudder_dynamics": ["model=known", "model.effects=[rudder_dynamics]", "environment=rudder_lag"],
    "sim/known/yaw_bias,current": ["model=known", "model.effects=[yaw_bias,current]", "environment=current"],
    "sim/known/shallow_water": ["model=known", "model.effects=[shallow_water]", "depth=h_T_2p9"],
    "sim/nomoto1/current (skipped)": ["model=nomoto1", "+model.effects=[current]", "environment=current"],
    "sim/mmg_hull/current/output_error (skipped)": ["model=mmg_hull", "model.effects=[current]",
                                                    "structure=output_error", "estimator=de"],
    "sim/mmg_hull/none": ["model=mmg_hull"],
}
#: records written for the runs on files: {file stem: (manoeuvre, seed)}
TRAIN = {"train_zz10": ("zigzag_10_10", 0), "train_zz20": ("zigzag_20_20", 0), "train_rr": ("random_rudder", 0)}
VALIDATE = {"val_turn35": ("turning_35", 1), "val_zz35": ("zigzag_35_35", 1)}
#: runs on files: {key: overrides}
FILES = {
    "files/mmg_hull": ["model=mmg_hull"],
    "files/mmg_hull/current": ["model=mmg_hull", "model.effects=[current]"],
    "files/known/current": ["model=known", "model.effects=[current]"],
    "files/known/current/novalidate": ["model=known", "model.effects=[current]", "validate=null"],
    "files/known": ["model=known"],
    "files/nomoto1_nl": ["model=nomoto1_nl"],
}


def _compose(name: str, overrides: list) -> dict:
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from study.commands.app import CONF_DIR

    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    return OmegaConf.to_container(cfg, resolve=True)


def write_records(folder: Path) -> None:
    """The runs on files' records (KVLCC2, noise-free, 0.5 s), written once."""
    from study.records.schema import write_record
    from study.commands.simulate import make_record

    folder.mkdir(parents=True, exist_ok=True)
    for name, (man, seed) in {**TRAIN, **VALIDATE}.items():
        path = folder / f"{name}.csv"
        if not path.exists():
            conf = _compose("simulate", ["vessel=kvlcc2", f"maneuver={man}", "noise=none", "noise.sample_dt=0.5",
                                         f"seed={seed}", "out=unused"])
            write_record(make_record(conf), path)


def configurations(records: Path) -> dict:
    out = {k: ("sim", SIM + v) for k, v in SIMULATED.items()}
    for k, v in FILES.items():
        val = [] if "validate=null" in v else [f"validate={records}/val_*.csv"]
        out[k] = ("files", ["vessel=kvlcc2", f"train={records}/train_*.csv", *val, *v])
    return out


def run_one(overrides: list) -> dict:
    from study.run.pipeline import run_study, study_config

    conf = _compose("config", overrides)
    conf["progress"] = False
    _, data = study_config(conf)
    try:
        res = run_study(conf, data)
    except Exception as e:  # a failure is a result too: it must be the same one
        return {"status": "failed", "error": f"{type(e).__name__}: {e}"}
    return {"status": res.get("status", "ok"), "error": res.get("error"), "metrics": res.get("metrics", {}),
            "params": res.get("params", []),
            "artefacts": {k: hashlib.sha256(v).hexdigest() for k, v in (res.get("artefacts") or {}).items()}}


def dump(path: str, only: str | None, records: Path) -> None:
    import study

    print(f"study imported from {study.__file__}", flush=True)
    write_records(records)
    out = {}
    for key, (_, ov) in configurations(records).items():
        if only and only not in key:
            continue
        t0 = time.perf_counter()
        out[key] = run_one(ov)
        print(f"{key:50s} {out[key]['status']:8s} {time.perf_counter() - t0:6.1f} s", flush=True)
    with open(path, "wb") as f:
        pickle.dump({"study": study.__file__, "runs": out}, f)


def compare(pa: str, pb: str) -> int:
    A, B = (pickle.load(open(p, "rb")) for p in (pa, pb))
    print(f"a: {A['study']}\nb: {B['study']}")
    ra, rb = A["runs"], B["runs"]
    if set(ra) != set(rb):
        print("configurations differ:", sorted(set(ra) ^ set(rb)))
    keys = sorted(set(ra) & set(rb))
    ndiff = 0
    for k in keys:
        a, b = ra[k], rb[k]
        if _same(a, b):
            extra = "  (dict key order differs)" if _order(a) != _order(b) else ""
            print(f"  same    {k} [{a['status']}]{extra}")
            continue
        ndiff += 1
        print(f"  DIFFERS {k} [{a['status']} / {b['status']}]")
        for part in ("status", "error", "artefacts"):
            if not _same(a.get(part), b.get(part)):
                print(f"      {part}: {a.get(part)!r} -> {b.get(part)!r}")
        ma, mb = a.get("metrics") or {}, b.get("metrics") or {}
        for m in sorted(set(ma) | set(mb)):
            if m not in ma or m not in mb or not _same(ma[m], mb[m]):
                print(f"      metric {m}: {ma.get(m, '<absent>')!r} -> {mb.get(m, '<absent>')!r}")
        pa_, pb_ = a.get("params") or [], b.get("params") or []
        if len(pa_) != len(pb_):
            print(f"      params: {len(pa_)} rows -> {len(pb_)} rows")
        for x, y in zip(pa_, pb_):
            if not _same(x, y):
                keys_ = sorted(set(x) | set(y))
                d = {c: (x.get(c, "<absent>"), y.get(c, "<absent>")) for c in keys_
                     if c not in x or c not in y or not _same(x[c], y[c])}
                print(f"      param {x.get('name')}: {d}")
    print(f"{len(keys)} configurations compared; {ndiff} differ")
    return 1 if ndiff or set(ra) != set(rb) else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out")
    d.add_argument("--only")
    d.add_argument("--records", default="/tmp/effects_equivalence_records")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args(argv)
    if args.cmd == "dump":
        dump(args.out, args.only, Path(args.records))
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
