"""Identification: sample structures, regressors, estimators.

A *model* config (``conf/model``) names the vessel-kind coefficients to identify per equation; a *structure*
(``conf/structure``) turns a record into (state, acceleration) samples; an *estimator* (``conf/estimator``)
fits y = Phi theta with a scikit-learn-style contract. ``study.identify.regression.build`` puts them together.
"""
