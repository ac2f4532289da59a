"""The model doctor: compare a model with measurements, show where it fails, name the missing
physical effect, add it and watch the error fall (``python -m study diagnose``).

- :mod:`.run`: the doctor from a resolved configuration (records read, report folder held, runs
  logged);
- :mod:`.diagnose`: baseline, candidates ranked by out-of-sample improvement, the error ladder, the
  verdict;
- :mod:`.report`: the report written (figures, ``report.json``, ``report.html``) with its replays
  and provenance;
- :mod:`.report_schema`: the report's one schema (:class:`.report_schema.Report`), serialised and
  read back;
- :mod:`.plots`, :mod:`.html`: the figures and the self-contained report page, rendered from the
  Jinja2 templates of ``templates/`` with what :mod:`.html_view` prepares for each section;
- :mod:`.examples`, :mod:`.turn_prediction`: the worked examples and a turn predicted from zigzags.

What the doctor uses is not its own: identification with a set of effects and its replay through
records is ``study.identify.with_effects``, the catalogue of candidate effects
``study.identify.effects`` (``.effects`` here keeps the old name for effects written against it),
the record checks ``study.records.vessel_checks``, the manoeuvre metrics
``study.records.maneuver_metrics``.
"""
