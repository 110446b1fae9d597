"""The parts of a pipeline definition below ``[pipeline]``: its tasks, the λ-sensitivity study,
the collections table and the scoring policy, each a frozen dataclass with its parser. The
TOML table helpers every definition parser shares are :mod:`elicit_jax.pipeline.definition`'s.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.definition import ContrastTask, check_keys, contrast_fields, sub_table
from elicit_jax.pipeline.sizes import task_sizes

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
    "sizes",
}


@dataclasses.dataclass(frozen=True)
class TaskSpec(ContrastTask):
    """One task of the grid and the demonstrations collected for it: D_base and the contrast
    sets (:class:`~elicit_jax.pipeline.definition.ContrastTask`), and one D_new per operator.

    Attributes:
      operators: the new operators, each contributing one D_new.
      new_episodes: size of each D_new.
      sizes: the task's other named sizes, ``(name, base_episodes, new_episodes)``
        (``[task.sizes.<name>]``; :mod:`elicit_jax.pipeline.sizes`).
    """

    operators: tuple[str, ...]
    new_episodes: int
    sizes: tuple[tuple[str, int, int], ...] = ()


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


def parse_task(raw: Mapping[str, Any], source: str) -> TaskSpec:
    """One ``[[task]]`` table (profile overrides merged), validated."""
    check_keys(raw, TASK_KEYS, "[[task]]", source)
    fields = contrast_fields(raw, source, ("operators",), (("new_episodes", 50),))
    operators = tuple(str(o) for o in raw["operators"])
    if not operators:
        raise ElicitError(f"[[task]] {fields['name']}: operators must not be empty", source)
    sizes = task_sizes(raw.get("sizes"), fields["name"], source)
    return TaskSpec(operators=operators, sizes=sizes, **fields)


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


SCORER_DEFAULT_PROFILE = "paper"
"""The training profile of a ``[scorer]`` table without ``profile``: the paper's sizes (a
scorer exists to be bigger than the compared policies)."""


@dataclasses.dataclass(frozen=True)
class ScorerSpec:
    """The policy that scores the contrast sets and every D_new, when it is not the base
    policy: trained on D_base of the same collection, one seed (the first training seed), with
    training settings of its own.

    Attributes:
      profile: the policy library's training profile its settings start from
        (:data:`elicit_jax.policy.config.PROFILES`; default :data:`SCORER_DEFAULT_PROFILE`).
      settings: training options over that profile (the keys of ``[train]``); ``[train]``
        and ``[profiles.<name>.train]`` do not apply to it.
    """

    profile: str
    settings: Mapping[str, Any]

    def __post_init__(self) -> None:
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))


def parse_scorer(raw: Mapping[str, Any], models: tuple[str, ...], source: str) -> ScorerSpec:
    """The ``[scorer]`` table (``[profiles.<name>.scorer]`` already merged), validated as the
    train stages validate ``[train]`` (:func:`~elicit_jax.pipeline.stage_config.resolve_train`,
    for every model of the definition), plus ``profile``.

    Raises:
      ElicitError: one line naming ``source``: an unknown key or profile, ``seeds`` (the scorer
        trains the first training seed: the seed every score stage reads), or an invalid
        training option.
    """
    from elicit_jax.pipeline.stage_config import resolve_train

    settings = {k: v for k, v in raw.items() if k != "profile"}
    profile = raw.get("profile", SCORER_DEFAULT_PROFILE)
    if "seeds" in settings:
        raise ElicitError(
            "[scorer] seeds: the scorer trains one seed, the first of [pipeline] seeds (the "
            "seed every score stage reads); remove it",
            source,
        )
    if not isinstance(profile, str):
        raise ElicitError(f"[scorer] profile must be a profile name, got {profile!r}", source)
    for model in models:
        try:
            resolve_train({**settings, "model": model, "profile": profile}, "scorer", ("profile",))
        except ElicitError as e:
            text = str(e)
            text = text if text.startswith("[scorer]") else f"[scorer] {text}"
            raise ElicitError(text, source) from None
    return ScorerSpec(profile=profile, settings=settings)
