"""The parts of a pipeline definition below ``[pipeline]``: its tasks, the λ-sensitivity study
and the collections table, each a frozen dataclass with its parser, and the TOML table helpers
every definition parser shares (:func:`check_keys`, :func:`sub_table`, :func:`task_table`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.policy.config import PIPELINE_PROFILES as PROFILES

SENSITIVITY_KEYS = {"points", "seeds", "eval_seed", "operators", "tasks"}
COLLECTIONS_KEYS = {"seeds", "methods"}
TASK_KEYS = {
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


def parse_sensitivity(
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
    check_keys(raw, SENSITIVITY_KEYS, "[sensitivity]", source)
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


def parse_task(raw: Mapping[str, Any], source: str) -> TaskSpec:
    """One ``[[task]]`` table (profile overrides merged, :func:`task_table`), validated."""
    check_keys(raw, TASK_KEYS, "[[task]]", source)
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


@dataclasses.dataclass(frozen=True)
class CollectionsSpec:
    """The study run again on other collections of the same demonstration sets.

    Attributes:
      seeds: collection seeds. Collection ``c`` collects every D_base, D_new and contrast set
        of a task anew, with collection seed ``collect_seed + COLLECTION_STRIDE·c`` plus the
        role's own offset (as a single collection does), so no two collections share a demo
        or an initial state. Collection 0 is the definition's own: same seeds, stage ids and
        paths as without this table.
      methods: the cells run on every collection (a subset of ``[pipeline] methods``, with
        ``base``); the full ``methods`` list runs on the first collection only.
    """

    seeds: tuple[int, ...]
    methods: tuple[str, ...]


def parse_collections(
    raw: Mapping[str, Any], methods: tuple[str, ...], source: str
) -> CollectionsSpec:
    """The ``[collections]`` table (profile overrides already merged), validated.

    Raises:
      ElicitError: an unknown key, no or repeated seeds, a negative seed, or a method that
        ``[pipeline] methods`` does not run.
    """
    check_keys(raw, COLLECTIONS_KEYS, "[collections]", source)
    seeds_raw = raw.get("seeds", ())
    if not isinstance(seeds_raw, list | tuple) or not seeds_raw:
        raise ElicitError("[collections] seeds must be a non-empty list of seeds", source)
    if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds_raw):
        raise ElicitError(
            f"[collections] seeds must be non-negative integers, got {list(seeds_raw)}", source
        )
    seeds = tuple(int(s) for s in seeds_raw)
    if len(set(seeds)) != len(seeds):
        raise ElicitError(f"[collections] seeds are listed twice: {list(seeds)}", source)
    chosen = tuple(str(m) for m in raw.get("methods", methods))
    if not chosen:
        raise ElicitError("[collections] methods must not be empty", source)
    missing = [m for m in chosen if m not in methods]
    if missing:
        raise ElicitError(
            f"[collections] methods {', '.join(missing)} are not in [pipeline] methods "
            f"({', '.join(methods)})",
            source,
        )
    if "base" not in chosen:
        raise ElicitError("[collections] methods must include 'base'", source)
    check_rollout_methods(chosen, "[collections] ", source)
    return CollectionsSpec(seeds=seeds, methods=chosen)


def check_rollout_methods(methods: tuple[str, ...], where: str, source: str) -> None:
    """Demo-SCORE and CUPID roll out the naive policy: a method list with either needs 'naive'.

    Args:
      methods: the method names.
      where: the table named in the error (``""`` for ``[pipeline]``).
      source: the definition file, for the error.
    """
    for rolled in ("demo-score", "cupid"):
        if any(m.startswith(rolled) for m in methods) and "naive" not in methods:
            raise ElicitError(
                f"{where}{rolled} rolls out the policy trained on D_base ∪ D_new: add 'naive' "
                f"to {where}methods",
                source,
            )
