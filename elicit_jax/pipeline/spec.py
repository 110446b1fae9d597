"""Pipeline definitions: a TOML file read into frozen dataclasses, with profiles applied.

A definition names the grid (tasks × operators × seeds × models), the training sets to
compare (``methods``) and per-stage config overrides. Layout (see ``pipelines/*.toml``)::

    [pipeline]                      # name, description, profile, seeds, models, methods
    [[task]]                        # one table per task: operators and demo counts
    [collect] [train] [score] [thresholds] [filter] [evaluate]   # stage overrides
    [deminf] [demo_score] [cupid] [quality]   # settings of the curation baselines
    [sensitivity]                   # optional: outcome vs λ across the fitted margin
    [collections]                   # optional: seeds, methods: the study on more collections
    [scorer]                        # optional: profile and [train] keys of the scoring policy
    [task.sizes.paper]              # per task: other named sizes (base_episodes, new_episodes)
    [profiles.cpu.train]            # overrides applied only under that profile
    [profiles.cpu.pipeline]         # seeds, models, methods under that profile
    [profiles.cpu.collections]      # the collections table under that profile
    [profiles.cpu.scorer]           # the scorer's keys under that profile (over [scorer])
    [task.profiles.cpu]             # per-task overrides under that profile (after the above)

Section keys are passed to the stage's library config by field name; unknown fields are
reported when the stage graph is built.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.definition import (
    DEFAULT_KIND,
    HEAD_KEYS,
    PROFILES,
    Definition,
    Layout,
    check_keys,
    read_frame,
    read_toml,
    sub_table,
    task_table,
)
from elicit_jax.pipeline.sizes import DEFAULT_SIZES, choose_sizes
from elicit_jax.pipeline.spec_parts import (
    CollectionsSpec,
    ScorerSpec,
    SensitivitySpec,
    TaskSpec,
    check_rollout_methods,
    parse_collections,
    parse_scorer,
    parse_sensitivity,
    parse_task,
)

__all__ = [  # the parts re-exported: other parsers (elicitation studies) use them from here
    "PROFILES",
    "CollectionsSpec",
    "PipelineSpec",
    "ScorerSpec",
    "SensitivitySpec",
    "TaskSpec",
    "check_keys",
    "load_spec",
    "parse_spec",
    "sub_table",
    "task_table",
]
SECTIONS = (
    "collect",
    "train",
    "score",
    "thresholds",
    "filter",
    "evaluate",
    "report",
    "deminf",
    "demo_score",
    "cupid",
    "quality",
)
CURATION_METHODS = (
    "deminf",
    "deminf-matched",
    "demo-score",
    "demo-score-matched",
    "cupid",
    "cupid-matched",
    "quality",
    "quality-matched",
)
METHODS = (
    "base",
    "naive",
    "filtered",
    "filtered-episode",
    "random",
    "longest",
    "shortest",
    "likelihood",
    "novelty",
    "filtered-valley",
    *CURATION_METHODS,
)
LAYOUT = Layout(
    top=frozenset(
        {"pipeline", "task", "profiles", "sensitivity", "collections", "scorer", *SECTIONS}
    ),
    head=frozenset({*HEAD_KEYS, "methods", "sizes"}),
    sections=SECTIONS,
    profile=frozenset({*SECTIONS, "task", "pipeline", "collections", "scorer"}),
    profile_head=frozenset({"seeds", "models", "methods", "collect_seed", "sizes"}),
)
"""The tables and keys a filtering definition allows."""


@dataclasses.dataclass(frozen=True)
class PipelineSpec(Definition):
    """A parsed pipeline definition under one profile: what every definition has
    (:class:`~elicit_jax.pipeline.definition.Definition`; its tasks are :class:`TaskSpec`),
    and the training sets compared.

    Attributes:
      methods: training sets compared (``base``, ``naive``, ``filtered``, baselines).
      sensitivity: the λ-sensitivity study, if the definition asks for one.
      collections: the study over several collections, if the definition asks for it.
      kind: the study kind (:mod:`elicit_jax.pipeline.study_kinds`).
      sizes: the named sizes run side by side (:mod:`elicit_jax.pipeline.sizes`; ``default``:
        the tasks' own counts).
      scorer: the policy that scores the contrast sets and every D_new, if the definition
        gives one (``[scorer]``); None: the first training seed's base policy scores.
    """

    methods: tuple[str, ...]
    sensitivity: SensitivitySpec | None = None
    collections: CollectionsSpec | None = None
    kind: str = DEFAULT_KIND
    sizes: tuple[str, ...] = (DEFAULT_SIZES,)
    scorer: ScorerSpec | None = None

    @property
    def n_cells(self) -> int:
        """Grid cells: tasks × models (each trains one base policy, all seeds at once)."""
        return len(self.tasks) * len(self.models)


def builtin_dir() -> Path:
    """Directory of the pipeline definitions shipped inside the package."""
    return Path(str(resources.files("elicit_jax") / "pipelines"))


def builtin_names() -> list[str]:
    """Names of the shipped definitions (the TOML files in :func:`builtin_dir`)."""
    return sorted(p.stem for p in builtin_dir().glob("*.toml"))


def resolve_path(name_or_path: str | Path) -> Path:
    """A definition file: an existing path, or the name of a shipped definition (also written
    ``pipelines/<name>.toml``, as in a checkout, so the same command works after a pip
    install)."""
    path = Path(name_or_path)
    if path.exists():
        return path
    shipped = builtin_dir() / f"{Path(str(name_or_path)).stem}.toml"
    shipped_like = path.parent in (Path("."), Path("pipelines"))  # as the README writes it
    if path.suffix in ("", ".toml") and shipped_like and shipped.exists():
        return shipped
    names = ", ".join(builtin_names())
    raise ElicitError(f"no such pipeline file (shipped definitions: {names})", path)


def load_spec(
    name_or_path: str | Path,
    profile: str | None = None,
    tasks: tuple[str, ...] | None = None,
    parse: Callable[..., Any] | None = None,
    sizes: str | None = None,
) -> PipelineSpec:
    """Read and validate a pipeline definition.

    Args:
      name_or_path: a TOML file, or the name of a shipped definition.
      profile: ``paper`` or ``cpu``; default: the file's ``[pipeline] profile``.
      tasks: run only these of the definition's tasks (default: all).
      parse: ``(data, *, source, text, profile) -> spec`` (default :func:`parse_spec`; an
        elicitation study passes its own).
      sizes: the named sizes to run, comma-separated (default: the file's ``[pipeline]
        sizes``, else ``default``), checked as the file's are
        (:func:`~elicit_jax.pipeline.sizes.choose_sizes`) against the tasks run.

    Raises:
      ElicitError: one line naming the file and the offending key.
    """
    path = resolve_path(name_or_path)
    data, text = read_toml(path)
    spec = (parse or parse_spec)(data, source=str(path), text=text, profile=profile)
    if tasks:
        known = [t.name for t in spec.tasks]
        unknown = [t for t in tasks if t not in known]
        if unknown:
            raise ElicitError(
                f"no task {', '.join(unknown)} in this definition (it has {', '.join(known)})",
                path,
            )
        spec = dataclasses.replace(spec, tasks=tuple(t for t in spec.tasks if t.name in tasks))
    if sizes is not None:
        if not hasattr(spec, "sizes"):
            raise ElicitError("--sizes applies to filtering studies, not to this kind", path)
        spec = dataclasses.replace(spec, sizes=choose_sizes(sizes, spec.tasks, str(path)))
    return spec


def parse_spec(
    data: Mapping[str, Any], *, source: str = "<spec>", text: str = "", profile: str | None = None
) -> PipelineSpec:
    """Build a :class:`PipelineSpec` from parsed TOML ``data`` (see :func:`load_spec`)."""
    frame = read_frame(data, LAYOUT, source, profile)
    head, sections = frame.head, frame.sections
    tasks = frame.tasks(lambda raw: parse_task(raw, source), source)
    methods = _methods(head, source)
    sensitivity = parse_sensitivity(data, frame.seeds, methods, sections["evaluate"], source)
    if sensitivity is not None:
        unknown = sorted(set(sensitivity.tasks) - {t.name for t in tasks})
        if unknown:
            raise ElicitError(f"[sensitivity] tasks {', '.join(unknown)} are not [[task]]s", source)
    collections = None
    if "collections" in data or "collections" in frame.overrides:
        collections = parse_collections(frame.table(data, "collections", source), methods, source)
    scorer = None
    if "scorer" in data or "scorer" in frame.overrides:
        scorer = parse_scorer(frame.table(data, "scorer", source), frame.models, source)
        if set(methods) <= {"base", "naive"}:
            raise ElicitError(
                f"[scorer]: no method of this study scores demonstrations (methods: "
                f"{', '.join(methods)}); remove [scorer]",
                source,
            )
    return PipelineSpec(
        **frame.definition(source, text, tasks),
        methods=methods,
        sensitivity=sensitivity,
        collections=collections,
        sizes=choose_sizes(head.get("sizes"), tasks, source),
        scorer=scorer,
    )


def _methods(head: Mapping[str, Any], source: str) -> tuple[str, ...]:
    """The ``[pipeline] methods`` list, validated."""
    methods = tuple(head.get("methods", ("base", "naive", "filtered")))
    for m in methods:
        if m not in METHODS:
            raise ElicitError(f"unknown method '{m}' (choose from {', '.join(METHODS)})", source)
    if "base" not in methods:
        raise ElicitError("methods must include 'base' (every comparison is against it)", source)
    check_rollout_methods(methods, "", source)
    return methods
