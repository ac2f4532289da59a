"""Equivalence check of the identification engine (``study.identify.fit.identify``) across two versions of the code.

Runs ``identify`` on small simulated records for a fixed set of configurations (every estimator config on the
regression structures it allows and on output error where it simulates; the prior-taking estimators with and
without a prior; emcee with each regression likelihood and ``correct_rows`` true and false) and dumps, per
configuration, the ``estimates``, ``params`` and ``metrics`` of the :class:`Identification` (timings left out),
with the sha256 of every artefact and the posterior draws, to a pickle. A second call compares two such dumps
exactly: floats bit for bit, NaN equal to NaN; dict key order is reported apart (it reaches no table).

Which ``study`` is imported is the caller's choice (``PYTHONPATH`` and the working directory); the script writes
nothing but its output file. Typical use, from the worktree under test and a checkout of the reference commit::

    cd /tmp/base && PYTHONPATH=/tmp/base python /path/to/scripts/engine_equivalence.py dump /tmp/base.pkl
    cd /work/wt && PYTHONPATH=/work/wt python scripts/engine_equivalence.py dump /tmp/new.pkl
    python scripts/engine_equivalence.py compare /tmp/base.pkl /tmp/new.pkl

``dump`` takes ``--only SUBSTRING`` to run the configurations whose key contains it. The sampling and evolutionary
estimators run with short settings (:data:`FAST`), the same on both sides. BLAS runs on one thread, so that a
dump repeats exactly.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import math  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

#: short settings of the slow estimators, as hydra overrides (the same on both sides of a comparison)
FAST = {"emcee": ["estimator.params.target_ess=100", "estimator.params.min_tau_multiple=10",
                  "estimator.params.max_steps=1500", "estimator.params.init=local", "estimator.params.n_probes=2"],
        "de": ["estimator.params.maxiter=30", "estimator.params.popsize=8"],
        "de_staged": ["estimator.params.maxiter=30", "estimator.params.popsize=8",
                      "estimator.params.stages=[{records:[0,1,2]}]"]}
#: (model, vessel) pairs: a Nomoto model (physical parameters K, T, ...) and a force model
MODELS = [("nomoto1_nl", "kt1_mariner"), ("mmg_hull", "kvlcc2")]
#: the models output error is checked on (a force model's simulated fit takes minutes even with short settings)
OUTPUT_ERROR = ("nomoto1_nl",)
REGRESSION = ["euler", "central", "integral", "diff_center", "smoothed"]
EMCEE_VARIANTS = {"reg": [], "reg_nocorr": ["estimator.params.correct_rows=false"],
                  "iid": ["estimator.params.likelihood=regression_iid"],
                  "prior": ["estimator.params.prior={source:offset,sd:0.3,offset:0.2}"]}
MAP_VARIANTS = {"prior": [], "flat": ["estimator.params.prior=null"]}


def configurations() -> dict:
    """{key: hydra overrides} of every configuration checked."""
    from study.identify.estimators import list_estimators, make_estimator

    out = {}
    for model, vessel in MODELS:
        base = [f"model={model}", f"vessel={vessel}"]
        for e in list_estimators():
            types = make_estimator(e).problem_types
            variants = {"emcee": EMCEE_VARIANTS, "map": MAP_VARIANTS}.get(e, {"": []})
            structures = (REGRESSION if "regression" in types else []) + \
                (["output_error"] if "output_error" in types and model in OUTPUT_ERROR else [])
            for s in structures:
                for v, extra in variants.items():
                    if s == "output_error" and v not in ("", "reg"):
                        continue
                    out[f"{model}/{s}/{e}{'/' + v if v else ''}"] = [*base, f"structure={s}", f"estimator={e}",
                                                                      *FAST.get(e, []), *extra]
    return out


def _conf(overrides: list) -> dict:
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from study.commands.app import CONF_DIR

    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=tiny", "noise=low_relative", *overrides])
    conf = OmegaConf.to_container(cfg, resolve=True)
    conf["progress"] = False
    return conf


def run_one(overrides: list) -> dict:
    """The identification of one configuration, as plain data (or the reason it was skipped or failed)."""
    from study.identify.fit import identify
    from study.run.pipeline import SimulatedJob

    job = SimulatedJob(_conf(overrides))
    skipped = job.prepare()
    if skipped is not None:
        return {"skipped": skipped["error"]}
    records, _ = job.dataset(job.seed)
    try:
        ident = identify(job.model, job.structure, job.est_cfg, records, seed=job.seed)
    except Exception as e:  # a refusal is a result too: it must be the same one
        return {"error": f"{type(e).__name__}: {e}"}
    return {"estimates": ident.estimates, "params": ident.params, "metrics": ident.metrics,
            "artefacts": {k: hashlib.sha256(v).hexdigest() for k, v in ident.artefacts.items()},
            "draws": {k: np.asarray(v).tobytes().hex() for k, v in ident.draws.items()}}


def dump(path: str, only: str | None) -> None:
    import study

    print(f"study imported from {study.__file__}", flush=True)
    out = {}
    for key, ov in configurations().items():
        if only and only not in key:
            continue
        t0 = time.perf_counter()
        out[key] = run_one(ov)
        what = next(iter(out[key])) if set(out[key]) & {"skipped", "error"} else "ok"
        print(f"{key:55s} {what:8s} {time.perf_counter() - t0:6.1f} s", flush=True)
    with open(path, "wb") as f:
        pickle.dump({"study": study.__file__, "runs": out}, f)


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or (a == b and math.copysign(1, a) == math.copysign(1, b))
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return set(a) == set(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def _order(a, path="") -> list:
    """Paths of the dicts whose key order, not content, is in question: their key lists."""
    if isinstance(a, dict):
        return [(path, list(a))] + [x for k, v in a.items() for x in _order(v, f"{path}/{k}")]
    if isinstance(a, list):
        return [x for i, v in enumerate(a) for x in _order(v, f"{path}[{i}]")]
    return []


def compare(pa: str, pb: str) -> int:
    A, B = (pickle.load(open(p, "rb")) for p in (pa, pb))
    print(f"a: {A['study']}\nb: {B['study']}")
    ra, rb = A["runs"], B["runs"]
    if set(ra) != set(rb):
        print("configurations differ:", sorted(set(ra) ^ set(rb)))
    keys = sorted(set(ra) & set(rb))
    diff = [k for k in keys if not _same(ra[k], rb[k])]
    order = [k for k in keys if k not in diff and _order(ra[k]) != _order(rb[k])]
    status = {}
    for k in keys:
        s = "skipped" if "skipped" in ra[k] else "error" if "error" in ra[k] else "ok"
        status[s] = status.get(s, 0) + 1
    print(f"{len(keys)} configurations compared ({status}); {len(diff)} differ; {len(order)} differ in dict key "
          "order only")
    for k in diff:
        for part in ("estimates", "params", "metrics", "artefacts", "draws", "skipped", "error"):
            if not _same(ra[k].get(part), rb[k].get(part)):
                print(f"  {k}: {part} differs")
    for k in order:
        print(f"  {k}: key order differs")
    return 1 if diff or set(ra) != set(rb) else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out")
    d.add_argument("--only")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args(argv)
    if args.cmd == "dump":
        dump(args.out, args.only)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
