"""The compiled code a run needs is loaded from numba's on-disk cache in a new process, never compiled again
(without it every fresh worker spent 2-5 s compiling the accelerations kernel and self-propulsion's accel).

The test makes its own cache (a fresh NUMBA_CACHE_DIR): a first process compiles and writes it, a second must
load every function from it (numba's per-dispatcher ``stats.cache_hits``) and compile nothing."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import json, sys
import numpy as np
from study.sim import _accel_kernel, _wind_kernel, accelerations, integrator, load_vessel, simulate, wind_forces
from study.sim import mmg
v = load_vessel("kt1_mariner")
simulate(v, "zigzag_10_10", duration=20.0)
accelerations(v, v.params[:, None], [1.0], [0.0], [0.01], [0.1], [1.0])
wind_forces(v, [5.0], [0.0], [0.0], 10.0, 1.0)
mmg.straight_surge_force(load_vessel("kvlcc2").params[:len(mmg.PARAM_NAMES)], 7.0, 1.5)
fns = {"integrate": integrator("nomoto"),
       "accel_kernel": _accel_kernel("nomoto"), "wind_kernel": _wind_kernel(), "mmg_accel": mmg._accel_kernel()}
print(json.dumps({k: {"hits": sum(f.stats.cache_hits.values()), "misses": sum(f.stats.cache_misses.values())}
                  for k, f in fns.items()}))
"""


def _child(cache_dir):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, cwd=ROOT,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_second_process_loads_every_kernel_from_the_cache(tmp_path):
    first = _child(tmp_path)
    assert all(s["misses"] >= 1 for s in first.values()), first  # a new cache: everything compiled once
    second = _child(tmp_path)
    assert all(s["misses"] == 0 and s["hits"] >= 1 for s in second.values()), second
