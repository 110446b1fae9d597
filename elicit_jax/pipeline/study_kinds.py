"""The kinds of study a pipeline definition can hold, declared as data (:data:`STUDY_KINDS`),
and the one registry of stage kinds they extend (:data:`STAGE_KINDS`).

A kind is what ``[pipeline] kind`` names (default ``filtering``: the filtering, models and
quickstart studies and the ``serve --demo`` inputs; ``elicitation``: the elicitation study
with simulated people). Each entry gives the kind's definition parser, its stage-graph
builder, its report stage's kind, and how its report is gathered from a run directory, read
back from a report folder and written. The stage kinds (:class:`StageKind`: config, plan,
function, gathering) are the filtering study's, extended by the elicitation study's own and by
one report stage kind per study kind, all of whose report stages run :func:`report_stage`.
Planning a run (:func:`elicit_jax.pipeline.run.plan_run`), running its stages, writing and
rebuilding reports and printing a run's results look the kinds up here; nothing else compares
kind names.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.definition import DEFAULT_KIND, read_kind
from elicit_jax.pipeline.elicitation import evidence as study_evidence
from elicit_jax.pipeline.elicitation import gather as study_gather
from elicit_jax.pipeline.elicitation import plan as study_plan
from elicit_jax.pipeline.elicitation import report as study_report
from elicit_jax.pipeline.elicitation import spec as study_spec
from elicit_jax.pipeline.elicitation.stages import ELICITATION_GATHER, ELICITATION_KINDS
from elicit_jax.pipeline.evidence import DATA_KIND, report_data_of, round_trip
from elicit_jax.pipeline.gather import REPORT_STAGE, gather, read_manifest
from elicit_jax.pipeline.graph import Graph
from elicit_jax.pipeline.plan import build_graph
from elicit_jax.pipeline.plan_cell import ConfigResolver
from elicit_jax.pipeline.report import LAYOUT as REPORT_LAYOUT
from elicit_jax.pipeline.report import summary_tables
from elicit_jax.pipeline.report_folder import ReportLayout, write_report
from elicit_jax.pipeline.runner import StageContext, StageFn
from elicit_jax.pipeline.spec import load_spec, parse_spec, resolve_path
from elicit_jax.pipeline.stage_kind import StageKind, StageKinds
from elicit_jax.pipeline.stages import FILTERING_KINDS


@dataclasses.dataclass(frozen=True)
class StudyKind:
    """One kind of study: everything the engine needs to plan, run and report it.

    Attributes:
      name: what ``[pipeline] kind`` says (and the run manifest records).
      parse: ``(data, *, source, text, profile) -> spec``: the definition parser.
      build_graph: ``(spec, resolve) -> Graph``: the stage graph of a parsed definition
        (``resolve``: :meth:`StageKinds.resolve` of :data:`STAGE_KINDS`).
      report_stage: the kind of its one report stage (registered by :data:`STAGE_KINDS`
        with :func:`report_stage` as its function).
      gather: ``(run_dir, stage kinds) -> data``: what the report shows, read from a run
        directory by the stage kinds' gatherers.
      round_trip: ``data -> data`` as a rebuild reads it back (first report = its rebuilds).
      from_raw: ``(report-data.json header, rollout table, folder) -> data``: a report's data
        from its folder's raw results.
      layout: its report's tables, figures and intro (:class:`ReportLayout`), written by the
        one report path of every kind (:meth:`write_report`).
      summary: ``data -> [(title, table)]``: the tables a finished run prints.
      data_kind: the artifact kind of its reports' ``report-data.json``.
    """

    name: str
    parse: Callable[..., Any]
    build_graph: Callable[[Any, ConfigResolver], Graph]
    report_stage: str
    gather: Callable[[Path, StageKinds], Any]
    round_trip: Callable[[Any], Any]
    from_raw: Callable[[Mapping[str, Any], Any, Path], Any]
    layout: ReportLayout
    summary: Callable[[Any], list[tuple[str, Any]]]
    data_kind: str

    def report_data(self, run_dir: str | Path) -> Any:
        """What the report of a run directory of this kind shows (gathered by
        :data:`STAGE_KINDS`)."""
        return self.gather(Path(run_dir), STAGE_KINDS)

    def write_report(
        self, data: Any, folder: str | Path, rebuilt_from: Path | None = None
    ) -> tuple[Path, Path]:
        """Write the report folder of ``data`` (:func:`report_folder.write_report` with this
        kind's layout); returns the Markdown and HTML paths."""
        return write_report(self.layout, data, folder, rebuilt_from)


# fmt: off
STUDY_KINDS = {
    DEFAULT_KIND: StudyKind(
        name=DEFAULT_KIND, parse=parse_spec, build_graph=build_graph, report_stage=REPORT_STAGE,
        gather=gather, round_trip=round_trip, from_raw=report_data_of,
        layout=REPORT_LAYOUT, summary=summary_tables, data_kind=DATA_KIND,
    ),
    study_spec.KIND: StudyKind(
        name=study_spec.KIND, parse=study_spec.parse_study,
        build_graph=study_plan.build_study_graph,
        report_stage=study_gather.STUDY_REPORT_STAGE,
        gather=study_gather.gather_study, round_trip=study_evidence.round_trip_study,
        from_raw=study_evidence.study_from_json, layout=study_report.LAYOUT,
        summary=study_report.summary_tables, data_kind=study_evidence.STUDY_DATA_KIND,
    ),
}
# fmt: on
"""Study kind name -> its entry."""


def report_stage(ctx: StageContext) -> None:
    """Every study kind's report stage: gather the run's artifacts as its study kind does and
    write its Markdown + HTML report."""
    kind = kind_of_run(ctx.run_dir)
    kind.write_report(kind.round_trip(kind.report_data(ctx.run_dir)), Path(ctx.output))


STAGE_KINDS = StageKinds(FILTERING_KINDS).extend(
    *ELICITATION_KINDS,
    *(
        StageKind(k.report_stage, report_stage, inputs=("*",), outputs="report")
        for k in STUDY_KINDS.values()
    ),
    gather=ELICITATION_GATHER,
)
"""The one registry of stage kinds: the filtering study's, the elicitation study's, and each
study kind's report stage."""


def stage_functions() -> dict[str, StageFn]:
    """Stage kind -> function of every registered kind, as the runners take them."""
    return STAGE_KINDS.functions()


def kind_of_run(run_dir: str | Path) -> StudyKind:
    """The study kind of a run directory (recorded in its manifest)."""
    return study_kind(read_manifest(run_dir)["config"].get("kind", DEFAULT_KIND), run_dir)


def study_kind(name: str, where: Any = None) -> StudyKind:
    """The entry of kind ``name``.

    Raises:
      ElicitError: no such kind (naming ``where``: the definition or run directory).
    """
    if name not in STUDY_KINDS:
        known = ", ".join(STUDY_KINDS)
        raise ElicitError(f"unknown study kind '{name}' (choose from {known})", where)
    return STUDY_KINDS[name]


def data_kinds() -> tuple[str, ...]:
    """The artifact kinds of every study kind's ``report-data.json``."""
    return tuple(k.data_kind for k in STUDY_KINDS.values())


def kind_of_data(data_kind: str) -> StudyKind:
    """The study kind whose reports keep a ``report-data.json`` of artifact kind ``data_kind``
    (one of :func:`data_kinds`)."""
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
    return spec, _graph(kind, spec, path), lambda: stage_functions()


def plan_data(
    data: Mapping[str, Any], source: str
) -> tuple[Any, Graph, Callable[[], Mapping[str, StageFn]]]:
    """:func:`plan_definition` of a definition given as parsed tables (``serve --demo``'s)."""
    head = data.get("pipeline", {})
    name = head.get("kind", DEFAULT_KIND) if isinstance(head, Mapping) else DEFAULT_KIND
    kind = study_kind(str(name), source)
    spec = kind.parse(data, source=source)
    return spec, _graph(kind, spec, source), lambda: stage_functions()


def _graph(kind: StudyKind, spec: Any, where: Any) -> Graph:
    """The stage graph of ``spec``, its configs resolved and its stages checked against their
    kinds (:meth:`StageKinds.check`)."""
    graph = kind.build_graph(spec, STAGE_KINDS.resolve)
    STAGE_KINDS.check(graph, where)
    return graph
