"""Pipeline definitions: a TOML file read into frozen dataclasses, with profiles applied.

A definition names the grid (tasks × operators × seeds × models), the training sets to
compare (``methods``) and per-stage config overrides. Layout (see ``pipelines/*.toml``)::

    [pipeline]                      # name, description, profile, seeds, models, methods
    [[task]]                        # one table per task: operators and demo counts
    [collect] [train] [score] [thresholds] [filter] [evaluate]   # stage overrides
    [deminf] [demo_score] [cupid] [quality]   # settings of the curation baselines
    [sensitivity]                   # optional: outcome vs λ across the fitted margin
    [profiles.cpu.train]            # overrides applied only under that profile
    [profiles.cpu.pipeline]         # seeds, models, methods under that profile
    [task.profiles.cpu]             # per-task overrides under that profile (after the above)

Section keys are passed to the stage's library config by field name; unknown fields are
reported when the stage graph is built.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Callable, Mapping
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.policy.config import PIPELINE_PROFILES as PROFILES

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
_PROFILE_PIPELINE_KEYS = {"seeds", "models", "methods", "collect_seed"}
_SENSITIVITY_KEYS = {"points", "seeds", "eval_seed", "operators", "tasks"}
_TOP_KEYS = {"pipeline", "task", "profiles", "sensitivity", *SECTIONS}
_PIPELINE_KEYS = {"name", "description", "profile", "seeds", "models", "methods", "collect_seed"}
_TASK_KEYS = {
    "name",
    "base_operator",
    "operators",
    "base_episodes",
    "new_episodes",
    "holdout_episodes",
    "incompatible_operator",
    "incompatible_episodes",
    "profiles",
}


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """One task of the grid and the demonstrations collected for it.

    Attributes:
      name: task name (``square-nut``, ``reach-pillar``, ...).
      base_operator: the proficient operator whose demos form D_base.
      operators: the new operators, each contributing one D_new.
      base_episodes: size of D_base.
      new_episodes: size of each D_new.
      holdout_episodes: held-out base demos (collected with another seed): the compatible
        contrast set used to fit the thresholds.
      incompatible_operator: operator known a priori to conflict with the base style.
      incompatible_episodes: its demos (another seed, disjoint from every D_new): the
        incompatible contrast set.
    """

    name: str
    base_operator: str
    operators: tuple[str, ...]
    base_episodes: int
    new_episodes: int
    holdout_episodes: int
    incompatible_operator: str
    incompatible_episodes: int


@dataclasses.dataclass(frozen=True)
class SensitivitySpec:
    """The λ-sensitivity study: the filtering outcome at several λ across the fitted margin,
    trained and evaluated on seeds the main study does not use.

    Attributes:
      points: λ values, evenly spaced over the λ range of the fit's margin (both ends
        included; the fitted λ lies inside).
      seeds: training seeds, disjoint from the study's.
      eval_seed: evaluation initial-state set, other than the study's.
      operators: the operators studied (default: every operator of the task).
      tasks: the tasks studied (default: every task of the definition).
    """

    points: int = 5
    seeds: tuple[int, ...] = (100, 101, 102)
    eval_seed: int = 1
    operators: tuple[str, ...] = ()
    tasks: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class PipelineSpec:
    """A parsed pipeline definition under one profile.

    Attributes:
      name: pipeline name.
      description: one paragraph shown in reports.
      profile: ``paper`` (the paper's sizes) or ``cpu`` (shrunk to fit a 2-core machine).
      seeds: training seeds; results are reported as mean (std) over them.
      models: policy kinds (``mlp``, ``mdn``, ``lstm``).
      methods: training sets compared (``base``, ``naive``, ``filtered``, baselines).
      collect_seed: base seed of demonstration collection.
      tasks: the tasks with their operators.
      sections: stage name -> config overrides (profile overrides already merged in).
      source: where the definition was read from.
      text: the definition's exact text, reproduced in reports.
      sensitivity: the λ-sensitivity study, if the definition asks for one.
    """

    name: str
    description: str
    profile: str
    seeds: tuple[int, ...]
    models: tuple[str, ...]
    methods: tuple[str, ...]
    collect_seed: int
    tasks: tuple[TaskSpec, ...]
    sections: Mapping[str, Mapping[str, Any]]
    source: str
    text: str
    sensitivity: SensitivitySpec | None = None

    def section(self, name: str) -> dict[str, Any]:
        """A copy of the overrides for stage ``name`` (empty if none)."""
        return dict(self.sections.get(name, {}))

    @property
    def n_cells(self) -> int:
        """Grid cells: tasks × models (each trains one base policy, all seeds at once)."""
        return len(self.tasks) * len(self.models)


def builtin_dir() -> Path:
    """Directory of the pipeline definitions shipped inside the package."""
    return Path(str(resources.files("elicit_jax") / "pipelines"))


def builtin_names() -> list[str]:
    """Names of the shipped definitions (quickstart, filtering, models, elicitation)."""
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
) -> PipelineSpec:
    """Read and validate a pipeline definition.

    Args:
      name_or_path: a TOML file, or the name of a shipped definition.
      profile: ``paper`` or ``cpu``; default: the file's ``[pipeline] profile``.
      tasks: run only these of the definition's tasks (default: all).
      parse: ``(data, *, source, text, profile) -> spec`` (default :func:`parse_spec`; an
        elicitation study passes its own).

    Raises:
      ElicitError: one line naming the file and the offending key.
    """
    path = resolve_path(name_or_path)
    text = path.read_text()
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ElicitError(f"malformed TOML ({e})", path) from e
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
    return spec


def parse_spec(
    data: Mapping[str, Any], *, source: str = "<spec>", text: str = "", profile: str | None = None
) -> PipelineSpec:
    """Build a :class:`PipelineSpec` from parsed TOML ``data`` (see :func:`load_spec`)."""
    check_keys(data, _TOP_KEYS, "top level", source)
    head = data.get("pipeline")
    if not isinstance(head, Mapping):
        raise ElicitError("missing [pipeline] table", source)
    check_keys(head, _PIPELINE_KEYS, "[pipeline]", source)
    profile = profile or head.get("profile", "paper")
    if profile not in PROFILES:
        raise ElicitError(
            f"unknown profile '{profile}' (choose from {', '.join(PROFILES)})", source
        )
    overrides = data.get("profiles", {}).get(profile, {})
    check_keys(overrides, {*SECTIONS, "task", "pipeline"}, f"[profiles.{profile}]", source)
    head_over = sub_table(overrides, "pipeline", source)
    check_keys(head_over, _PROFILE_PIPELINE_KEYS, f"[profiles.{profile}.pipeline]", source)
    head = {**head, **head_over}
    for prof in data.get("profiles", {}):
        if prof not in PROFILES:
            raise ElicitError(f"[profiles.{prof}]: unknown profile name", source)
    sections = {}
    for name in SECTIONS:
        merged = {**sub_table(data, name, source), **sub_table(overrides, name, source)}
        sections[name] = MappingProxyType(merged)
    tasks_raw = data.get("task", [])
    if not isinstance(tasks_raw, list) or not tasks_raw:
        raise ElicitError("needs at least one [[task]] table", source)
    task_over = sub_table(overrides, "task", source)
    tasks = tuple(_task(task_table(t, task_over, profile, source), source) for t in tasks_raw)
    if len({t.name for t in tasks}) != len(tasks):
        raise ElicitError("a task is listed twice", source)
    methods = tuple(head.get("methods", ("base", "naive", "filtered")))
    for m in methods:
        if m not in METHODS:
            raise ElicitError(f"unknown method '{m}' (choose from {', '.join(METHODS)})", source)
    if "base" not in methods:
        raise ElicitError("methods must include 'base' (every comparison is against it)", source)
    for rolled in ("demo-score", "cupid"):
        if any(m.startswith(rolled) for m in methods) and "naive" not in methods:
            raise ElicitError(
                f"{rolled} rolls out the policy trained on D_base ∪ D_new: add 'naive' to methods",
                source,
            )
    seeds = tuple(int(s) for s in head.get("seeds", (0,)))
    models = tuple(str(m) for m in head.get("models", ("mlp",)))
    if not seeds or not models:
        raise ElicitError("[pipeline] seeds and models must not be empty", source)
    if len(set(seeds)) != len(seeds):
        raise ElicitError("[pipeline] seeds are listed twice", source)
    sensitivity = _sensitivity(data, seeds, methods, sections["evaluate"], source)
    if sensitivity is not None:
        unknown = sorted(set(sensitivity.tasks) - {t.name for t in tasks})
        if unknown:
            raise ElicitError(f"[sensitivity] tasks {', '.join(unknown)} are not [[task]]s", source)
    return PipelineSpec(
        name=str(head.get("name", Path(source).stem)),
        description=str(head.get("description", "")).strip(),
        profile=profile,
        seeds=seeds,
        models=models,
        methods=methods,
        collect_seed=int(head.get("collect_seed", 0)),
        tasks=tasks,
        sections=MappingProxyType(sections),
        source=source,
        text=text,
        sensitivity=sensitivity,
    )


def _sensitivity(
    data: Mapping[str, Any],
    seeds: tuple[int, ...],
    methods: tuple[str, ...],
    evaluate: Mapping[str, Any],
    source: str,
) -> SensitivitySpec | None:
    """The [sensitivity] table, validated: held-out seeds and evaluation states."""
    if "sensitivity" not in data:
        return None
    raw = sub_table(data, "sensitivity", source)
    check_keys(raw, _SENSITIVITY_KEYS, "[sensitivity]", source)
    default = SensitivitySpec()
    spec = SensitivitySpec(
        points=int(raw.get("points", default.points)),
        seeds=tuple(int(s) for s in raw.get("seeds", default.seeds)),
        eval_seed=int(raw.get("eval_seed", default.eval_seed)),
        operators=tuple(str(o) for o in raw.get("operators", ())),
        tasks=tuple(str(t) for t in raw.get("tasks", ())),
    )
    if spec.points < 2:
        raise ElicitError(f"[sensitivity] points must be at least 2, got {spec.points}", source)
    if not spec.seeds or set(spec.seeds) & set(seeds):
        raise ElicitError(
            "[sensitivity] seeds must be given and disjoint from [pipeline] seeds (held out)",
            source,
        )
    if spec.eval_seed == int(evaluate.get("seed", 0)):
        raise ElicitError(
            "[sensitivity] eval_seed must differ from [evaluate] seed (held-out initial states)",
            source,
        )
    if "naive" not in methods or "filtered" not in methods:
        raise ElicitError(
            "[sensitivity] compares with the study: methods need naive and filtered", source
        )
    return spec


def check_keys(table: Any, allowed: set[str], where: str, source: str) -> None:
    """Check that ``table`` is a table whose keys are all in ``allowed``.

    Args:
      table: the parsed TOML value.
      allowed: the keys it may hold.
      where: how the error names the table (``"[pipeline]"``).
      source: the spec file, for the error.

    Raises:
      ElicitError: not a table, or an unknown key (the allowed ones are listed).
    """
    if not isinstance(table, Mapping):
        raise ElicitError(f"{where} must be a table", source)
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ElicitError(
            f"{where}: unknown key(s) {', '.join(unknown)} (allowed: {', '.join(sorted(allowed))})",
            source,
        )


def sub_table(data: Mapping[str, Any], name: str, source: str) -> dict[str, Any]:
    """The table ``data[name]`` as a dict (empty when absent).

    Raises:
      ElicitError: ``data[name]`` is not a table.
    """
    value = data.get(name, {})
    if not isinstance(value, Mapping):
        raise ElicitError(f"[{name}] must be a table", source)
    return dict(value)


def task_table(
    raw: Any, profile_over: Mapping[str, Any], profile: str, source: str
) -> dict[str, Any]:
    """A [[task]] table with the profile's overrides for every task, then its own.

    Args:
      raw: one parsed ``[[task]]`` entry.
      profile_over: the profile's ``[profiles.<name>.task]`` overrides for every task.
      profile: the chosen profile name.
      source: the spec file, for the error.

    Returns:
      The task's keys, later layers winning: own keys, profile overrides, own profile block.

    Raises:
      ElicitError: not a table, or an unknown profile name in the task's ``profiles``.
    """
    if not isinstance(raw, Mapping):
        raise ElicitError("each [[task]] must be a table", source)
    own = raw.get("profiles", {})
    if not isinstance(own, Mapping):
        raise ElicitError(f"[[task]] {raw.get('name')}: profiles must be a table", source)
    for prof in own:
        if prof not in PROFILES:
            raise ElicitError(f"[task.profiles.{prof}]: unknown profile name", source)
    base = {k: v for k, v in raw.items() if k != "profiles"}
    return {**base, **profile_over, **sub_table(own, profile, source)}


def _task(raw: Mapping[str, Any], source: str) -> TaskSpec:
    check_keys(raw, _TASK_KEYS, "[[task]]", source)
    for key in ("name", "operators", "incompatible_operator"):
        if key not in raw:
            raise ElicitError(f"[[task]] is missing '{key}'", source)
    operators = tuple(str(o) for o in raw["operators"])
    if not operators:
        raise ElicitError(f"[[task]] {raw['name']}: operators must not be empty", source)
    counts = {
        k: int(raw.get(k, d))
        for k, d in (
            ("base_episodes", 50),
            ("new_episodes", 50),
            ("holdout_episodes", 5),
            ("incompatible_episodes", 3),
        )
    }
    for k, v in counts.items():
        if v < 1:
            raise ElicitError(f"[[task]] {raw['name']}: {k} must be at least 1, got {v}", source)
    return TaskSpec(
        name=str(raw["name"]),
        base_operator=str(raw.get("base_operator", "base")),
        operators=operators,
        incompatible_operator=str(raw["incompatible_operator"]),
        **counts,
    )
