"""Identification: sample structures, regressors, estimators.

A *model* config (``conf/model``) names the vessel-kind coefficients to identify per equation; a
*structure* (``conf/structure``) turns a record into (state, acceleration) samples; an *estimator*
(``conf/estimator``) fits y = Phi theta with a scikit-learn-style contract. ``study.identify.fit``
puts them together (``identify``; ``build`` for the bare regression rows). ``with_effects``
identifies a force model together with candidate physical effects (``effects/``, discovered from
``conf/effect``): the model doctor and a run with ``model.effects`` use it.
"""
