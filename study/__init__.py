"""study: a reference harness for identifying ship manoeuvring models.

The user's verbs, importable from the package (each imports what it needs when called, so ``import
study`` is fast; ``study.api`` holds them):

- :func:`load_vessel`, :func:`load_records`, :func:`real_data_dir`: vessels and records;
- :func:`simulate_maneuver`, :func:`measure_record`: a simulated record and its measurement;
- :func:`identify_model`, :func:`predict`, :func:`replay_record`: identification and what the model
  predicts;
- :func:`diagnose_records`: the model doctor;
- :func:`read_results`: the results table; :func:`read_posterior`: an emcee run's posterior (ArviZ).
"""

__version__ = "0.1.0"

#: the public verbs, defined in ``study.api`` and imported from it on first use
__all__ = ["Identified", "load_vessel", "load_records", "real_data_dir", "simulate_maneuver", "measure_record",
           "identify_model", "predict", "replay_record", "diagnose_records", "read_results", "read_posterior"]


def __getattr__(name):
    if name in __all__:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'study' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
