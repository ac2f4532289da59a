"""Identify a model with a set of effects, and replay it through records: the identification the
model doctor (``study.doctor``) ranks effects with and a study run with ``model.effects``
(``study.run.pipeline``, ``study.run.records_run``) uses.

The model is a vessel kind's force model: the vessel config holds the coefficients as the user knows
them (captive tests, CFD, a previous identification); the model config may free some of them
(``equations``, each coefficient under the equation its config declares) and drop some (``omit``);
effects (``study.identify.effects``, discovered from ``conf/effect``) add their physics through
their hooks. Identification is by equation error with variable projection (Golub & Pereyra 1973):
for given values of the effects' nonlinear parameters the rows are built and every linear unknown
(free coefficients, the effects' linear parameters) follows by one weighted least-squares problem
over the three equations together (a parameter such as a_H acts in sway and yaw at once); the
nonlinear parameters minimise the training error inside their bounds (a grid, then a bounded
Nelder-Mead search); an effect's discrete variants (shallow water's formulas) are each fitted and
the best kept. The identified model is then replayed open loop through each record with its measured
rudder and propeller (``study.sim.replay``), at each record's own water depth, and the error per
channel measured.

The modules: ``problem`` (the records, the model, the rows, the linear solve and the replay),
``search`` (the nonlinear parameters' search and the :class:`Fit` it returns), ``uncertainty`` (the
anchor's prior, the posterior, identifiability), ``replay_errors`` (how far a replay is from a
record), ``inverse_dynamics`` (the residual forces) and ``estimator`` (:class:`VariableProjection`,
the estimator of a study run with ``model.effects``: ``study.identify.fit.fit_effects``).
"""
from .estimator import ModelWithEffects, VariableProjection, identify_effects
from .inverse_dynamics import residuals
from .problem import ENVELOPE, EQUATIONS, EffectsProblem, as_frame, record_h_T
from .replay_errors import (CHANNELS, NRMSE_CAP, UNITS, diverged_records, record_error, record_errors,
                            scored_channels, states_estimated, validation_error)
from .search import Fit

__all__ = ["CHANNELS", "ENVELOPE", "EQUATIONS", "NRMSE_CAP", "UNITS", "EffectsProblem", "Fit", "ModelWithEffects",
           "VariableProjection", "as_frame", "diverged_records", "identify_effects", "record_error", "record_errors",
           "record_h_T", "residuals", "scored_channels", "states_estimated", "validation_error"]
