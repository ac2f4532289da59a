"""Records, measured or simulated: their schema and checks (:mod:`~study.records.schema`,
:mod:`~study.records.plausibility`, :mod:`~study.records.vessel_checks`), the real data's loaders
(:mod:`~study.records.loaders`), where a record was measured (:mod:`~study.records.facility`),
the measurement model (:mod:`~study.records.measure`), state estimation
(:mod:`~study.records.state_estimation`) and the manoeuvre metrics a record is scored by
(:mod:`~study.records.metrics`, :mod:`~study.records.maneuver_metrics`)."""
