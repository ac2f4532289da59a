"""Measurement noise [A2]: the white-noise level of a channel by the difference method
(:func:`noise_std`) and the standard deviation the filter uses for each channel, given or
estimated (:func:`measurement_noise`)."""
from __future__ import annotations

import math

import numpy as np

from study.records.state_estimation.options import CHANNELS


def noise_std(a: np.ndarray, order: int = 4) -> float:
    """The white-noise standard deviation of a smooth signal plus noise (NaN ignored), from its
    ``order``-th differences (the difference method: von Neumann et al. 1941; Hall, Kay &
    Titterington 1990), robustly by their median absolute deviation (1.4826 MAD estimates a normal
    sd; Rousseeuw & Croux 1993). See [A2] in
    ``docs/concepts/state-estimation.md``."""
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    if len(a) <= order + 2:
        return 0.0
    d = np.diff(a, order)
    norm = math.sqrt(math.comb(2 * order, order))
    mad = float(np.median(np.abs(d - np.median(d))))
    est = 1.4826 * mad / norm
    if est == 0.0:  # quantised data: the plain spread
        est = float(np.std(d)) / norm
    return est


def measurement_noise(Z: np.ndarray, opts: dict, has: dict, h: float, U_typ: float,
                      r_typ: float) -> tuple[dict, dict, np.ndarray]:
    """The measurement noise of each channel [A2]: the option's number, or ``"auto"``:
    :func:`noise_std` of the channel (one number for ``x0`` and ``y0``: one GNSS), floored to keep
    the variance positive on noise-free data.

    Parameters
    ----------
    Z : ndarray (n, 6)
        The measurements of :data:`CHANNELS` (NaN: none).
    opts : dict
        The resolved options (:func:`~study.records.state_estimation.options.resolve_options`).
    has : dict
        {channel: whether the record measures it}.
    h, U_typ, r_typ : float
        The median step [s], the record's typical speed [m/s] and turn rate [rad/s] (the floors).

    Returns
    -------
    std_used : dict
        {channel: standard deviation} (NaN where ``auto`` and the record does not measure it).
    auto : dict
        {channel: whether it was estimated}.
    R : ndarray (6,)
        The variances the filter uses (1 for a channel not measured).
    """
    floors = {"x0": 1e-3 * max(U_typ, 1e-6) * h, "psi": 1e-3 * max(r_typ, 1e-6) * h + 1e-7,
              "u": 1e-4 * max(U_typ, 1e-6), "r": 1e-4 * max(r_typ, 1e-6) + 1e-8}
    floors.update(y0=floors["x0"], v=floors["u"])
    std_used, auto = {}, {}
    keys = {"x0": "position_std", "y0": "position_std", "psi": "heading_std", "u": "u_std", "v": "v_std",
            "r": "r_std"}
    for j, c in enumerate(CHANNELS):
        given = opts[keys[c]]
        if given == "auto":
            if c in ("x0", "y0"):
                est = max(noise_std(Z[:, 0]), noise_std(Z[:, 1]))  # one GNSS: one number for both
            else:
                est = noise_std(Z[:, j]) if has[c] else float("nan")
            std_used[c] = max(est, floors[c]) if has[c] else float("nan")
            auto[c] = True
        else:
            std_used[c] = float(given)
            auto[c] = False
    R = np.array([std_used[c] ** 2 if has[c] else 1.0 for c in CHANNELS])
    return std_used, auto, R
