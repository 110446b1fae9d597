"""Pipelines: a TOML definition expanded into a stage graph, run with up-to-date checks.

Modules: :mod:`spec` (definitions), :mod:`graph` (stages, DAG), :mod:`plan` (the filtering
study's graph), :mod:`runner` (execution, skip/resume), :mod:`stages` (the real stage
functions), :mod:`run` (plan + run + report, behind the CLI), :mod:`gather` and :mod:`tables`
(a run's results), :mod:`report` (Markdown/HTML).
"""
