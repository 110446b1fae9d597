"""The kinds of study a pipeline definition can hold, declared as data (:data:`STUDY_KINDS`).

A kind is what ``[pipeline] kind`` names (default ``filtering``: the filtering, models and
quickstart studies and the ``serve --demo`` inputs; ``elicitation``: the elicitation study
with simulated people). Each entry gives the kind's definition parser, its stage-graph
builder and config resolver, its stage registry, and how its report is gathered from a run
directory, read back from a report folder and written. Planning a run
(:func:`elicit_jax.pipeline.run.plan_run`), writing and rebuilding reports and printing a
run's results look the kind up here; nothing else compares kind names.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline import stages as filtering_stages
from elicit_jax.pipeline.definition import DEFAULT_KIND, read_kind
from elicit_jax.pipeline.elicitation import evidence as study_evidence
from elicit_jax.pipeline.elicitation import gather as study_gather
from elicit_jax.pipeline.elicitation import plan as study_plan
from elicit_jax.pipeline.elicitation import report as study_report
from elicit_jax.pipeline.elicitation import spec as study_spec
from elicit_jax.pipeline.elicitation import stages as study_stages
from elicit_jax.pipeline.evidence import DATA_KIND, STUDY_DATA_KIND, report_data_of, round_trip
from elicit_jax.pipeline.gather import gather
from elicit_jax.pipeline.graph import Graph
from elicit_jax.pipeline.plan import build_graph
from elicit_jax.pipeline.plan_cell import ConfigResolver
from elicit_jax.pipeline.report import summary_tables, write_report
from elicit_jax.pipeline.runner import StageFn
from elicit_jax.pipeline.spec import load_spec, parse_spec, resolve_path
from elicit_jax.pipeline.stages import resolve_config


@dataclasses.dataclass(frozen=True)
class StudyKind:
    """One kind of study: everything the engine needs to plan, run and report it.

    Attributes:
      name: what ``[pipeline] kind`` says (and the run manifest records).
      parse: ``(data, *, source, text, profile) -> spec``: the definition parser.
      build_graph: ``(spec, resolve) -> Graph``: the stage graph of a parsed definition.
      resolve: ``(stage kind, raw config) -> config``: each stage's full, validated config.
      registry: ``() -> {stage kind: function}``: the stage functions (looked up in their
        module when called, so a test that replaces the module's registry is obeyed).
      gather: ``run_dir -> data``: what the report shows, read from a run directory.
      round_trip: ``data -> data`` as a rebuild reads it back (first report = its rebuilds).
      from_raw: ``(report-data.json header, rollout table, folder) -> data``: a report's data
        from its folder's raw results.
      write_report: ``(data, folder, rebuilt_from=None) -> (md, html)``: writes a report folder.
      summary: ``data -> [(title, table)]``: the tables a finished run prints.
      data_kind: the artifact kind of its reports' ``report-data.json``.
    """

    name: str
    parse: Callable[..., Any]
    build_graph: Callable[[Any, ConfigResolver], Graph]
    resolve: ConfigResolver
    registry: Callable[[], Mapping[str, StageFn]]
    gather: Callable[[Path], Any]
    round_trip: Callable[[Any], Any]
    from_raw: Callable[[Mapping[str, Any], Any, Path], Any]
    write_report: Callable[..., tuple[Path, Path]]
    summary: Callable[[Any], list[tuple[str, Any]]]
    data_kind: str


# fmt: off
STUDY_KINDS = {
    DEFAULT_KIND: StudyKind(
        name=DEFAULT_KIND, parse=parse_spec, build_graph=build_graph, resolve=resolve_config,
        registry=lambda: filtering_stages.real_registry(), gather=gather,
        round_trip=round_trip, from_raw=report_data_of,
        write_report=write_report, summary=summary_tables, data_kind=DATA_KIND,
    ),
    study_spec.KIND: StudyKind(
        name=study_spec.KIND, parse=study_spec.parse_study,
        build_graph=study_plan.build_study_graph, resolve=study_stages.resolve_study_config,
        registry=lambda: study_stages.study_registry(), gather=study_gather.gather_study,
        round_trip=study_evidence.round_trip_study, from_raw=study_evidence.study_from_json,
        write_report=study_report.write_study_report, summary=study_report.summary_tables,
        data_kind=STUDY_DATA_KIND,
    ),
}
# fmt: on
"""Study kind name -> its entry."""


def study_kind(name: str, where: Any = None) -> StudyKind:
    """The entry of kind ``name``.

    Raises:
      ElicitError: no such kind (naming ``where``: the definition or run directory).
    """
    if name not in STUDY_KINDS:
        known = ", ".join(STUDY_KINDS)
        raise ElicitError(f"unknown study kind '{name}' (choose from {known})", where)
    return STUDY_KINDS[name]


def kind_of_data(data_kind: str) -> StudyKind:
    """The study kind whose reports keep a ``report-data.json`` of artifact kind ``data_kind``."""
    return next(k for k in STUDY_KINDS.values() if k.data_kind == data_kind)


def plan_definition(
    name_or_path: str | Path,
    profile: str | None = None,
    tasks: tuple[str, ...] | None = None,
    sizes: str | None = None,
) -> tuple[Any, Graph, Callable[[], Mapping[str, StageFn]]]:
    """A definition file's parsed spec, its stage graph and its stage registry, whatever its
    kind (see :func:`elicit_jax.pipeline.spec.load_spec` for the arguments)."""
    path = resolve_path(name_or_path)
    kind = study_kind(read_kind(path), path)
    spec = load_spec(path, profile, tasks, parse=kind.parse, sizes=sizes)
    return spec, kind.build_graph(spec, kind.resolve), kind.registry


def plan_data(
    data: Mapping[str, Any], source: str
) -> tuple[Any, Graph, Callable[[], Mapping[str, StageFn]]]:
    """:func:`plan_definition` of a definition given as parsed tables (``serve --demo``'s)."""
    head = data.get("pipeline", {})
    name = head.get("kind", DEFAULT_KIND) if isinstance(head, Mapping) else DEFAULT_KIND
    kind = study_kind(str(name), source)
    spec = kind.parse(data, source=source)
    return spec, kind.build_graph(spec, kind.resolve), kind.registry
