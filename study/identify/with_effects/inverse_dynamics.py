"""The residual forces of a fitted model on its training records (inverse dynamics): what the
doctor plots against the states and the rudder, and what the rudder-residual probe bins."""
from __future__ import annotations

import numpy as np

from .problem import EQUATIONS, EffectsProblem
from .search import Fit


def residuals(problem: EffectsProblem, fit: Fit, names: list) -> list:
    """Inverse dynamics of the fitted model on the training records: per segment the times, the
    residual forces [N, N, N m] (measured inertial forces minus the model's) and the states and
    inputs at the rows."""
    out, seen = [], set()
    for seg in problem.segments:
        y, Phi, cols = problem.rows(fit.effects, fit.values, segs=[seg])
        ops = problem.structure.ops(seg, 1)
        nodes = problem.structure.nodes(seg)
        r = {"record": seg.record, "name": names[seg.record] if seg.record < len(names) else str(seg.record),
             "time": ops.times, "first": seg.record not in seen}
        seen.add(seg.record)
        c = np.array([fit.coefs.get(n, 0.0) for n in cols])
        res = y - (np.einsum("mek,k->me", Phi, c) if len(cols) else 0.0)
        for k, eq in enumerate(EQUATIONS):
            r[eq] = res[:, k] * problem.scale[k]
        for s in ("u", "v", "r", "delta", "psi", "n", "wind_angle_rel"):
            if s in nodes:
                r[s] = ops.value(nodes[s])
        out.append(r)
    return out
