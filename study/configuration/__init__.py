"""The bottom layer every command stands on: composing the configuration from ``conf/``
(:mod:`~study.configuration.compose`), one-line refusals and exit statuses
(:mod:`~study.configuration.cli`), and how a sweep ends
(:mod:`~study.configuration.sweep_summary`)."""
