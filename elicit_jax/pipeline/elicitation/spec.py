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

A task's ``incompatible_operator`` may not be a person's starting style, by name nor by
what it does: no person may start within the region of θ its choices pin down
(:func:`starts_from`; the thresholds would be fitted on that person's own way of doing the
task). Each task's population is drawn by
:func:`~elicit_jax.elicit.people.traits.make_population` from ``[people]`` (the task's
``styles`` replace ``[people] styles``): person ``i`` starts from the ``i``-th style
(cycling), with traits drawn from the ranges (a task's ``people_ranges`` replace
``[people.ranges]`` for the traits it names), all seeded.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from elicit_jax.compat.thresholds import SESSION_KEYS
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.definition import (
    HEAD_KEYS,
    ContrastTask,
    Definition,
    Layout,
    check_keys,
    contrast_fields,
    read_frame,
    read_kind,
)
from elicit_jax.pipeline.spec import load_spec

__all__ = ["read_kind"]  # re-exported: which kind a definition file holds

KIND = "elicitation"
CONDITIONS = ("naive", "filtered", "rejection", "informed")
"""The paper's Table 2 columns (besides the base policy), plus ``rejection``: informed
rejection without adaptation (the rule filters; the person is shown nothing but what naive
mode shows, so it cannot learn from the interface) — teaching and filtering apart."""
ABLATION = ("prompt", "indicator", "feedback")
"""Informed sessions that show one part of the interface only (all three = ``informed``)."""
DAGGER = ("naive", "informed")
SECTIONS = ("collect", "train", "score", "thresholds", "filter", "evaluate", "session", "report")
LAYOUT = Layout(
    top=frozenset({"pipeline", "task", "profiles", "people", *SECTIONS}),
    head=frozenset({*HEAD_KEYS, "kind", "conditions", "ablation", "dagger_conditions"}),
    sections=SECTIONS,
    profile=frozenset({*SECTIONS, "task", "people"}),
)
"""The tables and keys an elicitation study allows."""
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
_SESSION_FIXED = {"task", "policy", "base_demos", *SESSION_KEYS, "lambda_", "operator", "mode"}
_SESSION_FIXED |= {"show", "dagger", "policy_seed", "seed"}


@dataclasses.dataclass(frozen=True)
class StudyTask(ContrastTask):
    """One task of the study: D_base and the contrast sets
    (:class:`~elicit_jax.pipeline.definition.ContrastTask`), and its people.

    Attributes:
      people: the population's operator specs (``person:STYLE,...``), in order.
      dagger: also run the HG-DAgger sessions on this task.
    """

    people: tuple[str, ...]
    dagger: bool = False


@dataclasses.dataclass(frozen=True)
class StudySpec(Definition):
    """A parsed elicitation study under one profile: what every definition has
    (:class:`~elicit_jax.pipeline.definition.Definition`; its tasks are :class:`StudyTask`),
    and the conditions, the ablation arms and the DAgger conditions."""

    conditions: tuple[str, ...]
    ablation: tuple[str, ...]
    dagger_conditions: tuple[str, ...]
    kind: str = KIND


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
    head = data.get("pipeline")
    if not isinstance(head, Mapping) or head.get("kind") != KIND:
        raise ElicitError(f'an elicitation study needs [pipeline] kind = "{KIND}"', source)
    _refuse_scorer(data, source)
    frame = read_frame(data, LAYOUT, source, profile)
    bad = sorted(set(frame.sections["session"]) & _SESSION_FIXED)
    if bad:
        raise ElicitError(
            f"[session] {', '.join(bad)} are set by the study, not the definition", source
        )
    people = frame.table(data, "people", source)
    check_keys(people, _PEOPLE, "[people]", source)
    tasks = frame.tasks(lambda raw: _task(raw, people, source), source)
    return StudySpec(
        **frame.definition(source, text, tasks),
        conditions=_names(frame.head, "conditions", CONDITIONS, source),
        ablation=_names(frame.head, "ablation", ABLATION, source),
        dagger_conditions=_names(frame.head, "dagger_conditions", DAGGER, source),
    )


def _refuse_scorer(data: Mapping[str, Any], source: str) -> None:
    """A filtering study's ``[scorer]`` has no place here: the sessions score live with the
    base policy, so the thresholds they are judged under must be fitted on its scores."""
    profiles = data.get("profiles")
    in_profile = isinstance(profiles, Mapping) and any(
        isinstance(p, Mapping) and "scorer" in p for p in profiles.values()
    )
    if "scorer" in data or in_profile:
        raise ElicitError(
            "[scorer] applies to filtering studies only: an elicitation study's sessions score "
            "with the base policy, so its thresholds are fitted on that policy's scores",
            source,
        )


CONTRAST_TOL = 0.05
"""How near (a fraction of the largest difference) a person's starting value may come to a
value the contrast set's style sets before the person counts as starting from that style."""


def starts_from(task: str, style: str, theta: Any) -> bool:
    """A person starting at ``theta`` starts from ``style``'s own way: on every coordinate
    the style's choices pin down, θ lies on the style's side of a threshold or within
    :data:`CONTRAST_TOL` of its value."""
    from elicit_jax.elicit.people.space import space_of
    from elicit_jax.sim.operators import style_of

    space = space_of(task)
    return space.within(theta, space.regions(style_of(task, style).choices), CONTRAST_TOL)


def _check_contrast_is_no_start(task: str, incompatible: str, population: Any, source: str) -> None:
    """No person starts from the contrast set's style (by its choices, not only its name)."""
    from elicit_jax.elicit.people.person import start_theta
    from elicit_jax.elicit.people.space import SPACES

    if task not in SPACES:
        return
    for i, person in enumerate(population):
        if starts_from(task, incompatible, start_theta(task, person)):
            raise ElicitError(
                f"[[task]] {task}: person p{i} ({person.style}) starts from the way of "
                f"incompatible_operator '{incompatible}' (the thresholds would be fitted on "
                "that person's own way)",
                source,
            )


def _task(raw: Mapping[str, Any], people: Mapping[str, Any], source: str) -> StudyTask:
    from elicit_jax.elicit.people.traits import make_population
    from elicit_jax.sim.operators import style_names

    check_keys(raw, _TASK, "[[task]]", source)
    fields = contrast_fields(raw, source)
    name = fields["name"]
    styles = [str(s) for s in raw.get("styles", people.get("styles", ()))]
    if not styles:
        raise ElicitError(f"[[task]] {name}: no starting styles ([people] styles)", source)
    try:
        known = style_names(name)
    except ElicitError as e:
        raise ElicitError(f"[[task]] {name}: {e}", source) from None
    base_operator, incompatible = fields["base_operator"], fields["incompatible_operator"]
    for style in [*styles, base_operator, incompatible]:
        if style not in known:
            raise ElicitError(
                f"[[task]] {name}: no operator '{style}' (known: {', '.join(known)})", source
            )
    if base_operator in styles:
        raise ElicitError(
            f"[[task]] {name}: a person cannot start from the base operator's style", source
        )
    if incompatible in styles:
        raise ElicitError(
            f"[[task]] {name}: incompatible_operator '{incompatible}' is also a "
            "person's starting style (the thresholds would be fitted on that person's own way)",
            source,
        )
    size = int(people.get("size", 6))
    ranges = {**dict(people.get("ranges", {})), **dict(raw.get("people_ranges", {}))}
    try:
        population = make_population(styles, size, int(people.get("seed", 0)), ranges)
    except ElicitError as e:
        raise ElicitError(f"[[task]] {name}: {e}", source) from None
    _check_contrast_is_no_start(name, incompatible, population, source)
    return StudyTask(
        people=tuple(p.spec() for p in population),
        dagger=bool(raw.get("dagger", False)),
        **fields,
    )
