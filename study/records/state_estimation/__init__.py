"""State estimation: u, v, r and their time derivatives from positions and heading, by an extended
Kalman filter (EKF) and a Rauch-Tung-Striebel (RTS) smoother on a kinematic model (no
hydrodynamics).

:func:`estimate_states` estimates ``u, v, r`` and ``u_dot, v_dot, r_dot`` from ``x0, y0, psi``
alone, or refines measured ``u, v, r``. Used by ``study.records.schema.read_record(...,
states="auto"|"ekf")`` and by the ``smoothed`` structure with ``smoothing.method: rts``. The model,
its sources, the assumptions [A1]-[A5] the code refers to, and why it is written by hand (numba)
rather than taken from a library are in
``docs/concepts/state-estimation.md``.

Modules: ``options`` (names, defaults, the options' check), ``kernels`` (the compiled filter and
smoother), ``noise`` (measurement noise [A2]), ``process`` (process noise by maximum likelihood
[A3]), ``estimate`` (the estimate of a record, [A4]).
"""
from __future__ import annotations

from study.records.state_estimation.estimate import RECORD_COLUMNS, StateEstimate, apply_to_frame, estimate_states
from study.records.state_estimation.noise import measurement_noise, noise_std
from study.records.state_estimation.options import (CHANNELS, DEFAULTS, GAP_FACTOR, GRID_PER_DECADE, MAX_TURN_STEP, STATES, resolve_options)
from study.records.state_estimation.process import process_noise

__all__ = ["CHANNELS", "DEFAULTS", "GAP_FACTOR", "GRID_PER_DECADE", "MAX_TURN_STEP", "RECORD_COLUMNS", "STATES",
           "StateEstimate", "apply_to_frame", "estimate_states", "measurement_noise", "noise_std",
           "process_noise", "resolve_options"]
