"""The errors of regression rows that are no white noise of the target, estimated from the run's own
records and corrected in emcee's regression likelihood (``likelihood: regression``, ``correct_rows:
true``): the structure's truncation and the noise of the regressors (errors in variables).

Why: the row-noise model (``study.identify.row_noise``) takes the regressors as exact and the
structure's stencil as the derivative. Neither holds, and both bias the estimate by a posterior sd
or more (measured on the KT Mariner with ``study.run.calibration``): euler's O(h) truncation 1.55 sd
at 0.1 s (its 90 % intervals covered the truth 56 % of the time); at 1 s central's truncation 0.5 sd
plus the regressors' noise 0.7 sd on the same side (70-78 %). A bias estimated from the records is
the structure's, not sampling noise, so it is removed, not
widened.

**Truncation** (``study.identify.truncation``: the stencil's Taylor moments times Savitzky-Golay
derivatives of the measured signals; within 0.04 posterior sd of the actual bias on the KT at 0.1
s): the rows' truncation errors ``(t_y, T_X)`` are subtracted from the rows, ``y - t_y = (X - T_X)
theta + e``, before the noise model is fitted (at 1 s the truncation was otherwise taken for noise:
intervals too wide).

**Errors in variables** (corrected least squares: Fuller 1987, *Measurement Error Models*, Sec. 2.2;
the corrected score of Nakamura 1990, Biometrika 77, 127-137): with the measured rows ``X_o = X +
N``, ``y_o = y + eps`` and the whitening ``W``, generalised least squares solves ``X_o' W X_o theta
= X_o' W y_o``, whose expectation is off by ``E[N' W N] theta - E[N' W eps]``. The corrected normal
equations

    (X_o' W X_o - M) theta = X_o' W y_o - g,   M = E[N' W N],  g = E[N' W eps]

are unbiased to first order. ``M`` and ``g`` are not derived per structure: they are averaged over
``n_probes`` **probes**, each the run's own records with fresh white noise added at the level
estimated from each channel (``state_estimation.noise_std``: fourth differences, median absolute
deviation), passed through the structure (``study.identify.rows.regression_rows``) and the training
rows' map (differencing, cleaning, split): so every structure, its post-processing and nonlinear
regressors (r^3) are covered alike. The probes' own Monte Carlo error of ``g - M theta`` is added to
the covariance (measured per run from the probes' spread).

Assumptions (labelled): the measurement noise white per channel, its level the difference method's;
the rows linear in the noise near the record (a probe's noise is added to the already noisy record;
second order in the noise for r^3-like regressors); the probed channels are the schema's measured
ones (``PROBED_CHANNELS``; a command such as ``delta_cmd`` is no measurement).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np

#: the smallest reliability of the whitened regressors (the smallest eigenvalue of H^-1/2 (H - M) H^-1/2: 1 - the
#: largest share of their spread that is noise) at which the first-order correction is made. Below it the noise is
#: no small perturbation: measured on diff_center's split rows at 0.1 s (reliability 0.1-0.2), the correction took
#: the KT's intervals from 44 % coverage to 0 %; there the run is left uncorrected and says it cannot be trusted
RELIABILITY_MIN = 0.5
#: the schema's measured channels (study.records.schema): white noise is added to these in a probe
PROBED_CHANNELS = ("u", "v", "r", "psi", "x0", "y0", "delta", "n")
#: probes per run: their Monte Carlo error is measured from their spread and added to the covariance; it is
#: small wherever the regressors are reliable (their noise a small part of their spread), 16 are enough there
N_PROBES = 16


@dataclass
class RowErrors:
    """What the likelihood needs to correct one equation's training rows (module docstring).

    ``trunc_y`` (n,), ``trunc_X`` (n, k): the rows' truncation errors, through the row map (None:
    no stencil); ``probes``: a callable yielding ``(N, eps)`` per probe, the change of the
    training rows (n, k) and target (n,) that one draw of the measurement noise makes (None: no
    correction of the regressors' noise); ``channel_sd``: per record, the noise level of each
    probed channel the probes used."""

    trunc_y: np.ndarray | None = None
    trunc_X: np.ndarray | None = None
    probes: Callable[[], Iterator[tuple[np.ndarray, np.ndarray]]] | None = None
    channel_sd: list = field(default_factory=list)

    def corrected(self, X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(X - T_X, y - t_y)``: the rows with their truncation removed."""
        if self.trunc_y is None:
            return X, y
        return X - self.trunc_X, y - self.trunc_y


def channel_noise(df) -> dict:
    """{channel: white-noise sd} of one record's probed channels
    (``state_estimation.noise_std``)."""
    from study.records.state_estimation import noise_std

    return {c: float(noise_std(df[c].to_numpy())) for c in PROBED_CHANNELS if c in df.columns}


def noisy_copies(records: list, n_probes: int, seed: int) -> tuple[list, Iterator[list]]:
    """(per record its channel noise levels, a generator of ``n_probes`` copies of ``records``,
    each with fresh white noise at those levels added to the probed channels). Deterministic in
    ``seed``."""
    frames = [rec.data if hasattr(rec, "data") else rec for rec in records]
    sds = [channel_noise(df) for df in frames]

    def gen():
        rng = np.random.default_rng([int(seed), 0x0E1F])
        for _ in range(n_probes):
            yield [df.assign(**{c: df[c].to_numpy() + s * rng.standard_normal(len(df)) for c, s in sd.items() if s > 0})
                   for df, sd in zip(frames, sds)]

    return sds, gen()


@dataclass
class Correction:
    """The errors-in-variables terms of the whitened rows: ``M`` (k x k) and ``g`` (k), means
    over the probes, and the per-probe values to measure their Monte Carlo error."""

    M: np.ndarray
    g: np.ndarray
    M_b: np.ndarray  # (B, k, k)
    g_b: np.ndarray  # (B, k)

    def mc_covariance(self, theta: np.ndarray) -> np.ndarray:
        """Covariance of the probes' mean of ``g_b - M_b theta`` (their Monte Carlo error)."""
        c = self.g_b - self.M_b @ theta
        B = len(c)
        return np.cov(c, rowvar=False).reshape(len(theta), len(theta)) / B if B > 1 else np.zeros((len(theta),) * 2)


def eiv_terms(errors: RowErrors, whiten: Callable[[np.ndarray], np.ndarray],
              exact: np.ndarray | None = None) -> Correction | None:
    """``M = E[N_w' N_w]``, ``g = E[N_w' eps_w]`` over the probes, ``N_w`` the whitened change of
    the rows. ``exact``: whitened columns without noise fitted beside the regressors
    (diff_center's intercept): the noise along them is absorbed by them in the fit, so it is
    projected out of ``N_w`` and ``eps_w`` first (corrected least squares on the partialled rows,
    Frisch-Waugh); ``M`` and ``g`` get zero rows for them. Why: whitening differenced rows
    integrates their noise, whose largest part is then a trend the intercept takes up; left in,
    it over-corrected diff_center by tens of posterior sd."""
    if errors is None or errors.probes is None:
        return None
    k_extra = 0 if exact is None else exact.shape[1]
    basis = np.linalg.qr(exact)[0] if k_extra else None
    Ms, gs = [], []
    for N, eps in errors.probes():
        W = whiten(np.column_stack([N, eps]))
        if basis is not None:
            W = W - basis @ (basis.T @ W)
        Nw, ew = W[:, :-1], W[:, -1]
        if k_extra:
            Nw = np.column_stack([Nw, np.zeros((len(Nw), k_extra))])
        Ms.append(Nw.T @ Nw)
        gs.append(Nw.T @ ew)
    if not Ms:
        return None
    M_b, g_b = np.array(Ms), np.array(gs)
    return Correction(M_b.mean(axis=0), g_b.mean(axis=0), M_b, g_b)
