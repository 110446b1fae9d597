"""The frame every kind of pipeline definition shares (a filtering study, an elicitation study,
the ``serve --demo`` inputs): the TOML table helpers, the profile chosen and its overrides
merged into the stage sections, the ``[[task]]`` tables, the seeds and the models
(:func:`read_frame`); and the demonstration sets every task collects (:class:`ContrastTask`,
:func:`contrast_fields`). What a kind adds on top is its own (:mod:`~elicit_jax.pipeline.spec`,
:mod:`~elicit_jax.pipeline.elicitation.spec`).
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Callable, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.policy.config import PIPELINE_PROFILES as PROFILES

DEFAULT_KIND = "filtering"
"""The kind of a definition without ``[pipeline] kind``."""
HEAD_KEYS = frozenset({"name", "description", "profile", "seeds", "models", "collect_seed"})
"""The ``[pipeline]`` keys of every kind (:meth:`Frame.definition`)."""


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


def read_toml(path: Path) -> tuple[dict[str, Any], str]:
    """A definition file's parsed tables and its exact text.

    Raises:
      ElicitError: malformed TOML, naming the file.
    """
    text = path.read_text()
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as e:
        raise ElicitError(f"malformed TOML ({e})", path) from e


def read_kind(path: Path) -> str:
    """The kind of definition a TOML file holds (``[pipeline] kind``, default
    :data:`DEFAULT_KIND`); an unreadable file is left to the parser to report."""
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError):
        return DEFAULT_KIND
    head = data.get("pipeline", {})
    return str(head.get("kind", DEFAULT_KIND)) if isinstance(head, Mapping) else DEFAULT_KIND


@dataclasses.dataclass(frozen=True)
class Layout:
    """The keys one kind of definition allows.

    Attributes:
      top: the top-level tables.
      head: the keys of ``[pipeline]``.
      sections: the stage sections (``[train]``, ...), merged with the profile's.
      profile: the keys of ``[profiles.<name>]``.
      profile_head: the keys of ``[profiles.<name>.pipeline]`` (when ``profile`` has
        ``pipeline``).
    """

    top: frozenset[str]
    head: frozenset[str]
    sections: tuple[str, ...]
    profile: frozenset[str]
    profile_head: frozenset[str] = frozenset()


@dataclasses.dataclass(frozen=True)
class Frame:
    """What every definition has, under the profile chosen.

    Attributes:
      head: ``[pipeline]``, the profile's ``[profiles.<name>.pipeline]`` merged in.
      profile: the profile's name.
      overrides: the ``[profiles.<name>]`` table.
      sections: stage section -> its keys, the profile's merged in.
      task_tables: each ``[[task]]`` with its profile overrides (:func:`task_table`).
      seeds: training seeds (distinct, at least one).
      models: policy kinds (at least one).
    """

    head: Mapping[str, Any]
    profile: str
    overrides: Mapping[str, Any]
    sections: Mapping[str, Mapping[str, Any]]
    task_tables: tuple[dict[str, Any], ...]
    seeds: tuple[int, ...]
    models: tuple[str, ...]

    def tasks(self, parse: Callable[[dict[str, Any]], Any], source: str) -> tuple[Any, ...]:
        """Each task table parsed by ``parse``; a task listed twice is an error."""
        tasks = tuple(parse(t) for t in self.task_tables)
        if len({t.name for t in tasks}) != len(tasks):
            raise ElicitError("a task is listed twice", source)
        return tasks

    def definition(self, source: str, text: str, tasks: tuple[Any, ...]) -> dict[str, Any]:
        """The :class:`Definition` fields of a definition read from ``source`` (its ``text``)
        with its parsed ``tasks``: the name (default: the file's stem), description and
        collection seed of ``[pipeline]``, the profile, seeds, models and sections."""
        return {
            "name": str(self.head.get("name", Path(source).stem)),
            "description": str(self.head.get("description", "")).strip(),
            "profile": self.profile,
            "seeds": self.seeds,
            "models": self.models,
            "collect_seed": int(self.head.get("collect_seed", 0)),
            "tasks": tasks,
            "sections": self.sections,
            "source": source,
            "text": text,
        }

    def table(self, data: Mapping[str, Any], name: str, source: str) -> dict[str, Any]:
        """A top-level table with the profile's table of the same name merged in."""
        return {**sub_table(data, name, source), **sub_table(self.overrides, name, source)}


def read_frame(data: Mapping[str, Any], layout: Layout, source: str, profile: str | None) -> Frame:
    """The :class:`Frame` of parsed TOML ``data`` under ``profile`` (default: the file's
    ``[pipeline] profile``, else ``paper``).

    Raises:
      ElicitError: one line naming ``source`` and the offending key.
    """
    check_keys(data, set(layout.top), "top level", source)
    head = data.get("pipeline")
    if not isinstance(head, Mapping):
        raise ElicitError("missing [pipeline] table", source)
    check_keys(head, set(layout.head), "[pipeline]", source)
    profile = profile or head.get("profile", "paper")
    if profile not in PROFILES:
        raise ElicitError(
            f"unknown profile '{profile}' (choose from {', '.join(PROFILES)})", source
        )
    for prof in data.get("profiles", {}):
        if prof not in PROFILES:
            raise ElicitError(f"[profiles.{prof}]: unknown profile name", source)
    overrides = data.get("profiles", {}).get(profile, {})
    check_keys(overrides, set(layout.profile), f"[profiles.{profile}]", source)
    if "pipeline" in layout.profile:
        head_over = sub_table(overrides, "pipeline", source)
        where = f"[profiles.{profile}.pipeline]"
        check_keys(head_over, set(layout.profile_head), where, source)
        head = {**head, **head_over}
    sections = {
        name: MappingProxyType(
            {**sub_table(data, name, source), **sub_table(overrides, name, source)}
        )
        for name in layout.sections
    }
    raw_tasks = data.get("task", [])
    if not isinstance(raw_tasks, list) or not raw_tasks:
        raise ElicitError("needs at least one [[task]] table", source)
    task_over = sub_table(overrides, "task", source)
    seeds = tuple(int(s) for s in head.get("seeds", (0,)))
    models = tuple(str(m) for m in head.get("models", ("mlp",)))
    if not seeds or not models:
        raise ElicitError("[pipeline] seeds and models must not be empty", source)
    if len(set(seeds)) != len(seeds):
        raise ElicitError("[pipeline] seeds are listed twice", source)
    return Frame(
        head=dict(head),
        profile=profile,
        overrides=overrides,
        sections=MappingProxyType(sections),
        task_tables=tuple(task_table(t, task_over, profile, source) for t in raw_tasks),
        seeds=seeds,
        models=models,
    )


@dataclasses.dataclass(frozen=True)
class Definition:
    """What every parsed definition has, under one profile (a kind's spec adds its own).

    Attributes:
      name: the study's name.
      description: one paragraph shown in reports.
      profile: ``paper`` (the paper's sizes) or ``cpu`` (shrunk to fit a 2-core machine).
      seeds: training seeds; results are reported as mean (std) over them.
      models: policy kinds (``mlp``, ``mdn``, ``lstm``).
      collect_seed: base seed of demonstration collection.
      tasks: the tasks (each a :class:`ContrastTask` and what the kind adds).
      sections: stage name -> config overrides (profile overrides already merged in).
      source: where the definition was read from.
      text: the definition's exact text, reproduced in reports.
    """

    name: str
    description: str
    profile: str
    seeds: tuple[int, ...]
    models: tuple[str, ...]
    collect_seed: int
    tasks: tuple[Any, ...]
    sections: Mapping[str, Mapping[str, Any]]
    source: str
    text: str

    def section(self, name: str) -> dict[str, Any]:
        """A copy of the overrides for stage ``name`` (empty if none)."""
        return dict(self.sections.get(name, {}))


@dataclasses.dataclass(frozen=True)
class ContrastTask:
    """A task and the demonstration sets every study collects for it.

    Attributes:
      name: task name (``square-nut``, ``reach-pillar``, ...).
      base_operator: the proficient operator whose demos form D_base.
      incompatible_operator: operator known a priori to conflict with the base style.
      base_episodes: size of D_base.
      holdout_episodes: held-out base demos (collected with another seed): the compatible
        contrast set the thresholds are fitted on.
      incompatible_episodes: the incompatible operator's demos (another seed, disjoint from
        every other set): the incompatible contrast set.
    """

    name: str
    base_operator: str
    incompatible_operator: str
    base_episodes: int
    holdout_episodes: int
    incompatible_episodes: int


def contrast_fields(
    raw: Mapping[str, Any],
    source: str,
    required: tuple[str, ...] = (),
    counts: tuple[tuple[str, int], ...] = (),
) -> dict[str, Any]:
    """The :class:`ContrastTask` fields of one ``[[task]]`` table, validated, with the
    episode ``counts`` a kind adds (key, default).

    Raises:
      ElicitError: a missing key (``name``, ``required``, ``incompatible_operator``) or a
        count below 1.
    """
    for key in ("name", *required, "incompatible_operator"):
        if key not in raw:
            raise ElicitError(f"[[task]] is missing '{key}'", source)
    name = str(raw["name"])
    defaults = (("base_episodes", 50), *counts, ("holdout_episodes", 5))
    numbers = {k: int(raw.get(k, d)) for k, d in (*defaults, ("incompatible_episodes", 3))}
    for k, v in numbers.items():
        if v < 1:
            raise ElicitError(f"[[task]] {name}: {k} must be at least 1, got {v}", source)
    return {
        "name": name,
        "base_operator": str(raw.get("base_operator", "base")),
        "incompatible_operator": str(raw["incompatible_operator"]),
        **numbers,
    }


def section_fields(
    cls: type, overrides: Mapping[str, Any], section: str, also: tuple[str, ...] = ()
) -> dict[str, Any]:
    """A section's keys as fields of the library config ``cls`` they set.

    Args:
      cls: the library config.
      overrides: the section's keys (those it takes besides ``cls``'s fields removed).
      section: how the error names the section (``train`` -> ``[train]``).
      also: the keys the section takes besides ``cls``'s fields, listed as allowed.

    Raises:
      ElicitError: a key that is no field of ``cls`` (the allowed keys are listed).
    """
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ElicitError(
            f"[{section}] unknown option(s) {', '.join(unknown)} "
            f"(allowed: {', '.join(sorted(names | set(also)))})"
        )
    return dict(overrides)
