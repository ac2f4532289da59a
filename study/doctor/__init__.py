"""The model doctor: compare a model with measurements, show where it fails, name the missing physical effect,
add it and watch the error fall (``python -m study.diagnose``).

- :mod:`.effects`: the catalogue of candidate effects, how each enters the identification and the simulation;
- :mod:`.fit`: identification of a model with a set of effects (variable projection), and its replay through
  records;
- :mod:`.diagnose`: baseline, candidates ranked by out-of-sample improvement, the error ladder, the verdict;
- :mod:`.plots`, :mod:`.html`: the figures and the self-contained report.
"""
