"""Synthetic, manoeuvre-like regressor matrices with a known truth: the shared test data of the
estimator tests (tests/identify/test_estimators.py) and benchmark
(benchmarks/bench_estimators_synthetic.py)."""
from __future__ import annotations

import numpy as np


def manoeuvre_regressors(n=2000, k=5, seed=0, duration=1680.0, extra=0):
    """(X, theta): k manoeuvre-like columns scaled over 1e-3..1e2 (columns 0, 1 correlated 0.99),
    plus ``extra`` irrelevant smooth columns (true coefficient 0, appended last)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, duration, n, endpoint=False)

    def smooth(nf=4):
        f = rng.uniform(2, 12, nf) / duration * 10
        a, ph = rng.uniform(0.3, 1.0, nf), rng.uniform(0, 2 * np.pi, nf)
        s = (a[:, None] * np.sin(2 * np.pi * f[:, None] * t[None, :] + ph[:, None])).sum(0)
        return s / s.std()

    v, r, d = smooth(), smooth(), smooth()
    cands = [v, r, v * np.abs(v), r * np.abs(r), v * v * r, v * r * r, r ** 3, d, v ** 3, d * np.abs(d), v * np.abs(r),
             d ** 3, r * np.abs(v), v * r, d * r * r, d * v * v, np.sin(d)]
    cols = [c / np.sqrt(np.mean(c * c)) for c in cands[:k]]
    e = cols[1] - (cols[1] @ cols[0]) / (cols[0] @ cols[0]) * cols[0]
    e /= np.sqrt(np.mean(e * e))
    cols[1] = 0.99 * cols[0] + np.sqrt(1 - 0.99 ** 2) * e
    scales = np.logspace(-3, 2, k)
    rng.shuffle(scales)
    X = np.column_stack(cols) * scales
    theta = rng.choice([-1, 1], k) * rng.uniform(0.3, 1.0, k) / scales
    if extra:
        X = np.column_stack([X] + [smooth() * 10.0 ** rng.uniform(-2, 1) for _ in range(extra)])
        theta = np.concatenate([theta, np.zeros(extra)])
    return X, theta
