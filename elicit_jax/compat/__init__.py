"""Compatibility of demonstrations with a base policy (Gandhi et al., CoRL 2022).

Modules: :mod:`measures` (ℓ, ν, M of one pair; :class:`~.measures.ScoreConfig`), :mod:`score`
(chunked, vmapped scoring of whole datasets), :mod:`score_file` (streaming Parquet in and out,
per-episode summaries), :mod:`thresholds` (the :class:`~.thresholds.Thresholds` value and its
JSON), :mod:`threshold_source` (which thresholds a command applies), :mod:`threshold_fit` /
:mod:`fit` / :mod:`selection` (fitting λ and η on contrast sets), :mod:`filtering` (M-filter
and baselines), :mod:`maps` (2-D maps), :mod:`feedback` (worst windows, nearest base
demonstration).
"""
