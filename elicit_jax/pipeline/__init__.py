"""Pipelines: a TOML definition expanded into a stage graph, run with up-to-date checks.

One engine for every study kind (:mod:`study_kinds`: filtering — with the models and quickstart
studies and the ``serve --demo`` inputs — and elicitation): :mod:`definition` (what every
definition shares) and :mod:`spec` (the filtering definition), :mod:`graph` (stages, DAG),
:mod:`plan` (the filtering study's graph and the stages every kind plans), :mod:`runner`
(execution, skip/resume), :mod:`stages` (the real stage functions), :mod:`run` (plan + run +
report, behind the CLI), :mod:`gather` and :mod:`tables` (a run's results),
:mod:`report_folder` and :mod:`report` (Markdown/HTML).
"""
