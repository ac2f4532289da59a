"""One run of a study: the simulated run (:mod:`~study.run.pipeline`), the run on a user's
records (:mod:`~study.run.records_run`) and what they share (:mod:`~study.run.common`), a run's
configuration checked before any work (:mod:`~study.run.settings`), the executor that claims,
resumes and records replicated runs (:mod:`~study.run.executor`), and emcee's coverage experiment
(:mod:`~study.run.calibration`)."""
