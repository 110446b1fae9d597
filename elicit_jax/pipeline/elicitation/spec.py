"""Elicitation study definitions: a TOML file with ``[pipeline] kind = "elicitation"``.

Layout (see ``pipelines/elicitation.toml``)::

    [pipeline]      # kind = "elicitation", name, description, profile, seeds, collect_seed,
                    # conditions (naive, filtered, rejection, informed), ablation
                    # (prompt, indicator, feedback), dagger_conditions (naive, informed)
    [people]        # size, seed, styles, [people.ranges] trait = [low, high]
    [session]       # session settings (SessionConfig fields: demos, practice, prompt, ...)
    [[task]]        # name, base_operator, base_episodes, holdout_episodes,
                    # incompatible_operator, incompatible_episodes, styles, dagger,
                    # [task.people_ranges] trait = [low, high] (this task's trait ranges)
    [collect] [train] [score] [thresholds] [filter] [evaluate]   # library config overrides
    [profiles.cpu.*]  [task.profiles.cpu]                         # profile overrides

A task's ``incompatible_operator`` may not be a person's starting style (the thresholds would
be fitted on that person's own way of doing the task). Each task's population is drawn by
:func:`~elicit_jax.elicit.people.traits.make_population` from ``[people]`` (the task's
``styles`` replace ``[people] styles``): person ``i`` starts from the ``i``-th style
(cycling), with traits drawn from the ranges (a task's ``people_ranges`` replace
``[people.ranges]`` for the traits it names), all seeded.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.spec import PROFILES, check_keys, load_spec, sub_table, task_table

KIND = "elicitation"
CONDITIONS = ("naive", "filtered", "rejection", "informed")
"""The paper's Table 2 columns (besides the base policy), plus ``rejection``: informed
rejection without adaptation (the rule filters; the person is shown nothing but what naive
mode shows, so it cannot learn from the interface) — teaching and filtering apart."""
ABLATION = ("prompt", "indicator", "feedback")
"""Informed sessions that show one part of the interface only (all three = ``informed``)."""
DAGGER = ("naive", "informed")
SECTIONS = ("collect", "train", "score", "thresholds", "filter", "evaluate", "session", "report")
_TOP = {"pipeline", "task", "profiles", "people", *SECTIONS}
_HEAD = {
    "kind",
    "name",
    "description",
    "profile",
    "seeds",
    "models",
    "collect_seed",
    "conditions",
    "ablation",
    "dagger_conditions",
}
_PEOPLE = {"size", "seed", "styles", "ranges"}
_TASK = {
    "name",
    "base_operator",
    "base_episodes",
    "holdout_episodes",
    "incompatible_operator",
    "incompatible_episodes",
    "styles",
    "dagger",
    "profiles",
    "people_ranges",
}
_SESSION_FIXED = {"task", "policy", "base_demos", "lambda", "lambda_", "eta", "operator", "mode"}
_SESSION_FIXED |= {"show", "dagger", "thresholds_file", "policy_seed", "seed"}


@dataclasses.dataclass(frozen=True)
class StudyTask:
    """One task of the study.

    Attributes:
      name: task name.
      base_operator: the proficient operator whose demos form D_base.
      base_episodes: size of D_base.
      holdout_episodes: held-out base demos (compatible contrast set for the thresholds).
      incompatible_operator: operator known a priori to conflict (incompatible contrast set).
      incompatible_episodes: its demos.
      people: the population's operator specs (``person:STYLE,...``), in order.
      dagger: also run the HG-DAgger sessions on this task.
    """

    name: str
    base_operator: str
    base_episodes: int
    holdout_episodes: int
    incompatible_operator: str
    incompatible_episodes: int
    people: tuple[str, ...]
    dagger: bool = False


@dataclasses.dataclass(frozen=True)
class StudySpec:
    """A parsed elicitation study under one profile (fields as :class:`PipelineSpec`'s, plus
    the conditions, the ablation arms and the DAgger conditions)."""

    name: str
    description: str
    profile: str
    seeds: tuple[int, ...]
    models: tuple[str, ...]
    collect_seed: int
    conditions: tuple[str, ...]
    ablation: tuple[str, ...]
    dagger_conditions: tuple[str, ...]
    tasks: tuple[StudyTask, ...]
    sections: Mapping[str, Mapping[str, Any]]
    source: str
    text: str
    kind: str = KIND

    def section(self, name: str) -> dict[str, Any]:
        """A copy of the overrides for stage ``name`` (empty if none)."""
        return dict(self.sections.get(name, {}))


def read_kind(path: Path) -> str:
    """``elicitation`` or ``filtering``: what kind of definition the TOML file holds."""
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError):
        return "filtering"  # the filtering loader reports the error
    head = data.get("pipeline", {})
    return str(head.get("kind", "filtering")) if isinstance(head, Mapping) else "filtering"


def load_study(
    name_or_path: str | Path, profile: str | None = None, tasks: tuple[str, ...] | None = None
) -> StudySpec:
    """Read and validate an elicitation study definition (see the module docstring).

    Raises:
      ElicitError: one line naming the file and the offending key.
    """
    return load_spec(name_or_path, profile, tasks, parse=parse_study)  # type: ignore[return-value]


def _names(head: Mapping[str, Any], key: str, allowed: tuple[str, ...], source: str) -> tuple:
    values = tuple(str(v) for v in head.get(key, allowed))
    bad = [v for v in values if v not in allowed]
    if bad or len(set(values)) != len(values):
        raise ElicitError(
            f"[pipeline] {key}: distinct values among {', '.join(allowed)}, got {list(values)}",
            source,
        )
    return values


def parse_study(
    data: Mapping[str, Any], *, source: str = "<spec>", text: str = "", profile: str | None = None
) -> StudySpec:
    """Build a :class:`StudySpec` from parsed TOML ``data`` (see :func:`load_study`)."""
    check_keys(data, _TOP, "top level", source)
    head = data.get("pipeline")
    if not isinstance(head, Mapping) or head.get("kind") != KIND:
        raise ElicitError(f'an elicitation study needs [pipeline] kind = "{KIND}"', source)
    check_keys(head, _HEAD, "[pipeline]", source)
    profile = profile or head.get("profile", "paper")
    if profile not in PROFILES:
        raise ElicitError(
            f"unknown profile '{profile}' (choose from {', '.join(PROFILES)})", source
        )
    for prof in data.get("profiles", {}):
        if prof not in PROFILES:
            raise ElicitError(f"[profiles.{prof}]: unknown profile name", source)
    overrides = data.get("profiles", {}).get(profile, {})
    check_keys(overrides, {*SECTIONS, "task", "people"}, f"[profiles.{profile}]", source)
    sections = {
        name: MappingProxyType(
            {**sub_table(data, name, source), **sub_table(overrides, name, source)}
        )
        for name in SECTIONS
    }
    bad = sorted(set(sections["session"]) & _SESSION_FIXED)
    if bad:
        raise ElicitError(
            f"[session] {', '.join(bad)} are set by the study, not the definition", source
        )
    people = {**sub_table(data, "people", source), **sub_table(overrides, "people", source)}
    check_keys(people, _PEOPLE, "[people]", source)
    raw_tasks = data.get("task", [])
    if not isinstance(raw_tasks, list) or not raw_tasks:
        raise ElicitError("needs at least one [[task]] table", source)
    task_over = sub_table(overrides, "task", source)
    tasks = tuple(
        _task(task_table(t, task_over, profile, source), people, source) for t in raw_tasks
    )
    if len({t.name for t in tasks}) != len(tasks):
        raise ElicitError("a task is listed twice", source)
    seeds = tuple(int(s) for s in head.get("seeds", (0,)))
    models = tuple(str(m) for m in head.get("models", ("mlp",)))
    if not seeds or not models:
        raise ElicitError("[pipeline] seeds and models must not be empty", source)
    return StudySpec(
        name=str(head.get("name", Path(source).stem)),
        description=str(head.get("description", "")).strip(),
        profile=profile,
        seeds=seeds,
        models=models,
        collect_seed=int(head.get("collect_seed", 0)),
        conditions=_names(head, "conditions", CONDITIONS, source),
        ablation=_names(head, "ablation", ABLATION, source),
        dagger_conditions=_names(head, "dagger_conditions", DAGGER, source),
        tasks=tasks,
        sections=MappingProxyType(sections),
        source=source,
        text=text,
    )


def _task(raw: Mapping[str, Any], people: Mapping[str, Any], source: str) -> StudyTask:
    from elicit_jax.elicit.people.traits import make_population
    from elicit_jax.sim.operators import style_names

    check_keys(raw, _TASK, "[[task]]", source)
    for key in ("name", "incompatible_operator"):
        if key not in raw:
            raise ElicitError(f"[[task]] is missing '{key}'", source)
    name = str(raw["name"])
    counts = {
        k: int(raw.get(k, d))
        for k, d in (("base_episodes", 50), ("holdout_episodes", 5), ("incompatible_episodes", 3))
    }
    for k, v in counts.items():
        if v < 1:
            raise ElicitError(f"[[task]] {name}: {k} must be at least 1, got {v}", source)
    styles = [str(s) for s in raw.get("styles", people.get("styles", ()))]
    if not styles:
        raise ElicitError(f"[[task]] {name}: no starting styles ([people] styles)", source)
    try:
        known = style_names(name)
    except ElicitError as e:
        raise ElicitError(f"[[task]] {name}: {e}", source) from None
    base_operator = str(raw.get("base_operator", "base"))
    for style in [*styles, base_operator, str(raw["incompatible_operator"])]:
        if style not in known:
            raise ElicitError(
                f"[[task]] {name}: no operator '{style}' (known: {', '.join(known)})", source
            )
    if base_operator in styles:
        raise ElicitError(
            f"[[task]] {name}: a person cannot start from the base operator's style", source
        )
    if str(raw["incompatible_operator"]) in styles:
        raise ElicitError(
            f"[[task]] {name}: incompatible_operator '{raw['incompatible_operator']}' is also a "
            "person's starting style (the thresholds would be fitted on that person's own way)",
            source,
        )
    size = int(people.get("size", 6))
    ranges = {**dict(people.get("ranges", {})), **dict(raw.get("people_ranges", {}))}
    try:
        population = make_population(styles, size, int(people.get("seed", 0)), ranges)
    except ElicitError as e:
        raise ElicitError(f"[[task]] {name}: {e}", source) from None
    return StudyTask(
        name=name,
        base_operator=base_operator,
        incompatible_operator=str(raw["incompatible_operator"]),
        people=tuple(p.spec() for p in population),
        dagger=bool(raw.get("dagger", False)),
        **counts,
    )
