"""The output-error problem: simulate a model through measured records and compare its outputs with
them.

Zheng & Xiao (2017, Sec. 3.2, eqs. 18-19) integrates the KT equations with the measured rudder and
compares the heading with the record ("integral" samples, as against finite differences); several
records (or phases of one) enter one objective at once, its "parallel processing" (Sec. 1.2). Here
any model that can be simulated does the same: each record segment (cut at dropouts) is replayed
open loop from its first measured state with its measured rudder angle and propeller speed
(``study.sim.replay``, the steering gear switched off so the measured angle acts as measured), every
candidate parameter set of a batch in one vectorised call of the compiled integrator.

Outputs and weights: the channels compared (``outputs``; default the model's own: u, v, r for force
models, r and psi for Nomoto models) are each divided by their spread over the records, so that
``cost = sum_c SSE_c / s_c^2 / N``, a mean normalised squared error (dimensionless, comparable
across channels). ``sse`` gives the raw per-channel sums for a likelihood with one noise scale per
channel.

Divergence is a result, not a crash: a candidate whose replay leaves the physical envelope
(:data:`ENVELOPE`: speed, yaw rate, sway) or overflows is stopped there -- none of its outputs count
-- and penalised (:data:`DIVERGED`); the problem counts such candidates (``n_diverged``, in the
run's metrics as ``oe_diverged_candidates``). Before, a replay at 8e189 was finite, escaped the
penalty, and made the Gauss-Newton polish fail ("array must not contain infs or NaNs"); the polish
is now skipped when its Jacobian cannot be formed (a perturbed candidate diverged), keeping the best
point it had (``oe_polish_skipped``).
"""
from __future__ import annotations

import math

import numpy as np

from ..sim import replay
from .structures import segments

#: the integrator's state (study.sim.replay's state0)
STATE = ("u", "v", "r", "x0", "y0", "psi")
#: cost of a simulation that diverged (NaN/inf): worse than any finite one, but finite for the optimisers
DIVERGED = 1e12
#: a replay is stopped as diverged when it leaves this envelope: speed over 5 times the service speed, yaw rate
#: over 20 U0/L (a full turn in a third of a ship length's travel; both as study.identify.with_effects's), sway
#: velocity over 2 U0 (a ship sliding sideways at twice its service speed). Assumption: no ship manoeuvres there,
#: so no record can ask for it.
ENVELOPE = {"speed_U0": 5.0, "r_U0_L": 20.0, "v_U0": 2.0}


def leaves_envelope(sim: np.ndarray, U0: float, L: float) -> np.ndarray:
    """(B,) True for each member of a replay ``sim`` (n, >= 6 columns u, v, r, x0, y0, psi, B)
    that overflows or leaves :data:`ENVELOPE` of a ship of service speed ``U0`` and length ``L``."""
    with np.errstate(over="ignore", invalid="ignore"):
        u, v, r = sim[:, 0, :], sim[:, 1, :], sim[:, 2, :]
        out = ~np.all(np.isfinite(sim[:, :6, :]), axis=(0, 1))
        out |= np.any(np.hypot(u, v) > ENVELOPE["speed_U0"] * U0, axis=0)
        out |= np.any(np.abs(r) > ENVELOPE["r_U0_L"] * U0 / L, axis=0)
        out |= np.any(np.abs(v) > ENVELOPE["v_U0"] * U0, axis=0)
    return out


#: a batch of at least twice this many members is simulated as two halves in two threads (a half of 8 or more
#: still fills the integrator's SIMD member loop: study.sim.core._SIMD_MIN_BATCH)
SPLIT_MIN = 8
_POOL = None


def _pool():
    """Two worker threads, made on first use (a batch is split in two whatever the number of
    cores)."""
    global _POOL
    if _POOL is None:
        from concurrent.futures import ThreadPoolExecutor

        _POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="output-error")
    return _POOL


class OutputErrorProblem:
    """Replay ``model`` through record segments; ``names``/``bounds``/``x0`` describe the
    parameters.

    Parameters
    ----------
    model : study.identify.models.Model
    records : list of DataFrames or Records
    outputs : sequence of str or None (the model's ``channels`` without psi for force models)
    x0 : dict or None
        An initial estimate (physical names), e.g. equation-error least squares.
    bounds : (k, 2) array or None
        The search box (DE's bounds; emcee's uniform prior).
    substeps : int
        Integration steps per record sample (accuracy of the replay).
    start_window : int
        Samples of the quadratic fit that gives each segment's initial state (see
        :func:`initial_value`).
    """

    def __init__(self, model, records, outputs=None, x0=None, bounds=None, substeps: int = 1,
                 min_samples: int = 10, start_window: int = 31, initial_state: str = "estimate"):
        self.model = model
        self.model_names = list(model.oe_names)
        if initial_state not in ("estimate", "measured"):
            raise ValueError(f"output_error: initial_state must be 'estimate' or 'measured', got {initial_state!r}")
        self.initial_state = initial_state
        if outputs is None:
            outputs = [c for c in model.channels if c != "psi"] if model.type != "nomoto" else list(model.channels)
        self.outputs = list(outputs)
        bad = [c for c in self.outputs if c not in ("u", "v", "r", "psi", "x0", "y0")]
        if bad:
            raise ValueError(f"output_error: unknown output channel(s) {bad}; use u, v, r, psi, x0, y0")
        self._col = [("u", "v", "r", "x0", "y0", "psi").index(c) for c in self.outputs]
        self.vessel = model.oe_vessel()
        self.substeps = int(substeps)
        self.segments = []
        for i, rec in enumerate(records):
            df = rec.data if hasattr(rec, "data") else rec
            for seg in segments(df, i, min_len=min_samples):
                t = seg.t
                h = float(np.median(np.diff(t)))
                tu = t[0] + h * np.arange(int(round((t[-1] - t[0]) / h)) + 1)
                if not np.allclose(tu[[0, -1]], t[[0, -1]], atol=0.5 * h) or len(tu) != len(t) or \
                        np.max(np.abs(tu - t)) > 1e-6 * max(1.0, h):
                    data = {c: np.interp(tu, t, a) for c, a in seg.data.items()}  # jittered: onto a uniform grid
                else:
                    data = seg.data
                Y = np.column_stack([data[c] for c in self.outputs])
                state0 = np.array([initial_value(tu, data[c], start_window) for c in ("u", "v", "r", "x0", "y0",
                                                                                       "psi")])
                self.segments.append({"t": tu, "delta": data["delta"], "n": data["n"], "state0": state0, "Y": Y,
                                      "record": i, "raw": {c: data[c] for c in STATE}})
        if not self.segments:
            raise ValueError(f"output_error: no record segment has {min_samples} samples")
        Yall = np.concatenate([s["Y"] for s in self.segments])
        self.scale = Yall.std(axis=0)
        self.scale[self.scale == 0] = 1.0
        self.n_obs = np.array([len(Yall)] * len(self.outputs))
        self.n_total = int(len(Yall))
        # initial states as nuisance parameters: the states the outputs depend on, per segment
        self.init_params = []  # (segment, row of the integrator state, name)
        if initial_state == "estimate":
            states = ["r"] if model.type == "nomoto" else ["u", "v", "r"]
            if "psi" in self.outputs:
                states.append("psi")
            for i, seg in enumerate(self.segments):
                for st in states:
                    self.init_params.append((i, STATE.index(st), f"{st}0[{i}]"))
        self.names = self.model_names + [n for _, _, n in self.init_params]
        init_x0, init_b = [], []
        for i, row, _ in self.init_params:
            seg = self.segments[i]
            c = seg["raw"][STATE[row]]
            w = max(6.0 * noise_sd(c), 1e-9 * (abs(seg["state0"][row]) + np.std(c) + 1e-12))
            init_x0.append(seg["state0"][row])
            init_b.append([seg["state0"][row] - w, seg["state0"][row] + w])
        self.x0 = None if x0 is None else np.array([float(x0[n]) for n in self.model_names] + init_x0)
        self.bounds = None if bounds is None else np.vstack([np.asarray(bounds, float).reshape(-1, 2),
                                                             np.asarray(init_b).reshape(-1, 2)])
        self.n_sim = 0  # simulations run (each batch member counts once)
        self.n_diverged = 0  # of which left the envelope (see ENVELOPE)
        self.polish_skipped = 0  # local fits stopped because a replay of their Jacobian diverged
        self.last_diverged = np.zeros(0, bool)  # the members of the last batch that diverged
        self.threads = True  # split large batches over two threads (see simulate)

    @property
    def k(self) -> int:
        return len(self.names)

    @property
    def k_model(self) -> int:
        return len(self.model_names)

    def simulate(self, theta) -> list:
        """Predicted outputs per segment, each (n_i, n_outputs, B), for parameter sets ``theta`` (k,
        B): the model's parameters, then the estimated initial states.

        A batch of at least ``2 * SPLIT_MIN`` members is simulated as two halves in two threads
        (the compiled integrator releases the GIL), so both cores work; the split depends on the
        batch size only, never on the number of cores, so results are the same on any machine
        (each half runs the vectorised member loop; ``tests/test_speed_paths.py`` checks a split
        batch against one call)."""
        theta = np.asarray(theta, float)
        if theta.ndim == 1:
            theta = theta[:, None]
        B = theta.shape[1]
        if B >= 2 * SPLIT_MIN and self.threads:
            h = B // 2
            (oa, ga), (ob, gb) = _pool().map(self._simulate, (theta[:, :h], theta[:, h:]))
            out, gone = [np.concatenate([a, b], axis=2) for a, b in zip(oa, ob)], np.concatenate([ga, gb])
        else:
            out, gone = self._simulate(theta)
        if gone.any():  # a diverged candidate is stopped: none of its outputs count
            for o in out:
                o[:, :, gone] = np.nan
        # the counters are kept here, in the calling thread, not in the halves' threads
        self.last_diverged = gone
        self.n_sim += B
        self.n_diverged += int(gone.sum())
        return out

    def _simulate(self, theta) -> tuple[list, np.ndarray]:
        """(outputs per segment, (B,) members that left the envelope) of one batch, without side
        effects."""
        B = theta.shape[1]
        P = self.model.oe_pack(theta[:self.k_model])
        out = []
        gone = np.zeros(B, bool)
        for i, s in enumerate(self.segments):
            y0 = np.repeat(s["state0"][:, None], B, axis=1)
            for j, (seg, row, _) in enumerate(self.init_params):
                if seg == i:
                    y0[row] = theta[self.k_model + j]
            sim = replay(self.vessel, s["t"], s["delta"], s["n"], y0, P=P, substeps=self.substeps)
            gone |= leaves_envelope(sim, self.vessel.U0, self.vessel.L)
            out.append(sim[:, self._col, :])
        return out, gone

    def sse(self, theta) -> np.ndarray:
        """Sum of squared output errors per channel, (n_outputs, B), in the channels' own units."""
        preds = self.simulate(theta)
        tot = 0.0
        with np.errstate(over="ignore", invalid="ignore"):  # a diverged member: inf, handled below
            for s, p in zip(self.segments, preds):
                e = p - s["Y"][:, :, None]
                tot = tot + np.sum(e * e, axis=0)
        tot = np.where(np.isfinite(tot), tot, np.inf)
        return tot

    def cost(self, theta) -> np.ndarray:
        """Mean normalised squared output error (B,) -- or a float for a single 1-D ``theta``."""
        single = np.ndim(theta) == 1
        S = self.sse(np.asarray(theta, float).reshape(self.k, -1))
        c = np.sum(S / self.scale[:, None] ** 2, axis=0) / self.n_total
        c = np.where(np.isfinite(c), c, DIVERGED)
        return float(c[0]) if single else c

    def residuals(self, theta, scale=None) -> np.ndarray:
        """Normalised residuals stacked over segments and channels, (N_total * n_outputs, B);
        each channel divided by its spread, or by ``scale`` (n_outputs,) when given."""
        preds = self.simulate(theta)
        sc = self.scale if scale is None else np.asarray(scale, float)
        with np.errstate(over="ignore", invalid="ignore"):
            parts = [((p - s["Y"][:, :, None]) / sc[None, :, None]).reshape(-1, p.shape[2])
                     for s, p in zip(self.segments, preds)]
        r = np.concatenate(parts, axis=0)
        r[:, self.last_diverged] = math.sqrt(DIVERGED)  # one penalty for the whole diverged candidate
        return np.where(np.isfinite(r), r, math.sqrt(DIVERGED))

    def summary(self, theta) -> dict:
        """RMSE per output channel and the normalised cost at ``theta`` (for the results table;
        inf when its replay diverges, with ``diverged`` 1), and how many candidates simulated so
        far diverged."""
        counts = {"simulations": self.n_sim, "diverged_candidates": self.n_diverged,
                  "polish_skipped": self.polish_skipped}
        S = self.sse(np.asarray(theta, float).reshape(self.k, 1))[:, 0]
        out = {f"rmse_{c}": float(math.sqrt(S[i] / self.n_obs[i])) for i, c in enumerate(self.outputs)}
        out["cost"] = float(np.sum(S / self.scale ** 2) / self.n_total)
        out["segments"] = len(self.segments)
        out["samples"] = self.n_total
        out["diverged"] = float(self.last_diverged[0])
        out.update(counts)
        return out


def noise_sd(x: np.ndarray) -> float:
    """White-noise standard deviation of a smooth signal from its second differences (variance 6
    sigma^2 for white noise), made robust by the median absolute deviation (1.4826 MAD estimates
    a normal sigma)."""
    d2 = np.diff(np.asarray(x, float), 2)
    if len(d2) < 5:
        return 0.0
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def initial_value(t: np.ndarray, x: np.ndarray, window: int = 31) -> float:
    """A segment's initial value from a least-squares quadratic through its first samples, not
    its first (noisy) sample: a replay starts from this state, and an error in it -- a heading
    offset above all -- would bias every later output (measured: 2 % on K, T of a KT model at 2 %
    noise). At most a tenth of the segment is used, and the first sample alone when that is fewer
    than 5 samples."""
    w = min(int(window), len(t) // 10)
    if w < 5:
        return float(x[0])
    c = np.polyfit(t[:w] - t[0], x[:w], 2)
    return float(c[-1])


def default_bounds(model, x0: dict | None, cfg: dict) -> np.ndarray:
    """The search box of the output-error parameters.

    Nomoto models: a box in non-dimensional terms (K' = K L/U0, T' = T U0/L, alpha' = alpha
    (U0/L)^2; model config ``oe_bounds``, defaults wide enough for any merchant ship: K' in [0.01,
    20], T' in [0.01, 50], T3' in [0, 50], alpha' in [-1e4, 1e4]: the Mariner's is 103) --
    independent of any initial estimate, as Zheng & Xiao's (2017) DE is. Force models: around the
    equation-error estimate x0, +- ``relative`` x |x0| but at least ``floor`` x the largest |x0| of
    the same equation (structure config ``output_error.bounds``; defaults 1.0 and 0.05).
    """
    names = model.oe_names
    if model.type == "nomoto":
        L, U = model.vessel.L, model.vessel.U0
        nd = {"K": L / U, "T": U / L, "T1": U / L, "T2": U / L, "T3": U / L, "alpha": (U / L) ** 2}
        box = {"K": (0.01, 20.0), "T": (0.01, 50.0), "T1": (0.01, 50.0), "T2": (0.01, 50.0), "T3": (0.0, 50.0),
               "alpha": (-1.0e4, 1.0e4)}
        box.update({k: tuple(v) for k, v in (model.cfg.get("oe_bounds") or {}).items()})
        # dimensional = non-dimensional / factor (K = K' U/L, T = T' L/U, alpha = alpha' (L/U)^2)
        return np.array([[box[n][0] / nd[n], box[n][1] / nd[n]] for n in names])
    if x0 is None:
        raise ValueError(f"output_error: model '{model.name}' needs an initial estimate to centre its bounds")
    b = cfg.get("bounds") or {}
    rel, floor = float(b.get("relative", 1.0)), float(b.get("floor", 0.05))
    eq_of = {n: eq for eq, ns in model.physical_names.items() for n in ns}
    big = {eq: max(abs(x0[n]) for n in ns) for eq, ns in model.physical_names.items()}
    out = []
    for n in names:
        w = max(rel * abs(x0[n]), floor * big[eq_of[n]], 1e-12)
        out.append([x0[n] - w, x0[n] + w])
    return np.array(out)


def local_fit(problem: OutputErrorProblem, x0, max_nfev: int = 200, scale=None):
    """Bounded Gauss-Newton (scipy's trust-region-reflective ``least_squares``) on the normalised
    residuals, the Jacobian by forward differences of all k parameters in ONE batch simulation.
    ``scale``: the channels' divisors of the residuals (default their spreads; emcee's Laplace
    approximation passes the noise scales).

    Returns ``scipy.optimize.OptimizeResult`` with ``x``, ``fun`` (the cost), ``success``, ``nfev``
    and ``cov`` (Gauss-Newton covariance of x for unit residual variance; None if singular), ``jac``
    (the Jacobian of the normalised residuals at x, rows as in :meth:`OutputErrorProblem.residuals`;
    None when the fit was skipped) and ``skipped``: when a replay the Jacobian needs diverges (or
    the start itself does), the fit stops and returns the best point it evaluated (``success``
    False, ``skipped`` True, the reason in ``message``) instead of failing the run.
    """
    from scipy.optimize import OptimizeResult, least_squares

    lo, hi = problem.bounds[:, 0], problem.bounds[:, 1]
    x0 = np.asarray(x0, float)
    x0 = np.where(np.isfinite(x0), x0, 0.5 * (lo + hi))
    span = hi - lo
    x0 = np.clip(x0, lo + 1e-6 * span, hi - 1e-6 * span)
    steps = 1e-6 * np.maximum(np.abs(x0), 1e-3 * span)

    best = {"x": x0, "cost": problem.cost(x0), "nfev": 1}

    def fun(x):
        r = problem.residuals(x[:, None], scale)[:, 0]
        best["nfev"] += 1
        if not problem.last_diverged[0]:
            c = float(np.sum(r * r)) / problem.n_total
            if c < best["cost"]:
                best.update(x=x.copy(), cost=c)
        return r

    def jac(x, f0=None):
        X = np.repeat(x[:, None], problem.k + 1, axis=1)
        h = np.where(x + steps <= hi, steps, -steps)  # stay inside the box
        X[np.arange(problem.k), np.arange(1, problem.k + 1)] += h
        R = problem.residuals(X, scale)
        J = (R[:, 1:] - R[:, :1]) / h
        if problem.last_diverged.any() or not np.all(np.isfinite(J)):
            raise _NoJacobian("a replay of the Jacobian diverged")
        return J

    try:
        if best["cost"] >= DIVERGED:
            raise _NoJacobian("the start diverges")
        res = least_squares(fun, x0, jac=jac, bounds=(lo, hi), x_scale="jac", max_nfev=max_nfev, method="trf")
    except _NoJacobian as e:  # divergence is a result: keep the best point, report the skip
        problem.polish_skipped += 1
        x = np.asarray(best["x"], float)
        return OptimizeResult(x=x, fun=float(problem.cost(x)), success=False, nfev=best["nfev"], cov=None, jac=None,
                              message=f"Gauss-Newton polish skipped: {e}", skipped=True)
    cov = None
    try:
        JTJ = res.jac.T @ res.jac
        cov = np.linalg.inv(JTJ)
    except np.linalg.LinAlgError:
        pass
    return OptimizeResult(x=res.x, fun=float(problem.cost(res.x)), success=bool(res.success), nfev=res.nfev,
                          message=res.message, cov=cov, jac=res.jac, skipped=False)


class _NoJacobian(Exception):
    """The Gauss-Newton step cannot be formed (a replay diverged): the local fit stops."""
