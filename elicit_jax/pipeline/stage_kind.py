"""A stage kind as one object (:class:`StageKind`), and the one registry of them
(:class:`StageKinds`) that the study kinds extend.

A stage kind bundles everything the engine knows about one kind of stage: how its raw config
becomes the library's full config (``resolve``), how it is planned (the inputs its function
reads, the folder its outputs go under, whether the study's report reads it), the function
that runs it, and how its finished outputs are gathered into a report (``gather``: per report
field, what one finished stage adds to it). The registry answers every question the planner,
the runners and the gatherers ask about a kind; an unregistered kind is a one-line error.
"""

from __future__ import annotations

import dataclasses
import fnmatch
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.runner import StageFn

Gatherer = Callable[[Mapping[str, Any], Path], "list[Any] | None"]
"""``(stage record of run.json, its output path) -> items``: what one finished stage adds to
one field of a report (None: the output is not complete yet, the stage counts as unfinished)."""


KEPT_KEYS: Mapping[str, Callable[[Any], Any]] = MappingProxyType({"collection": int, "sizes": str})
"""The keys a stage's config keeps beside its kind's resolved config (the planner adds them,
the library's configs have no such field): key -> how its value is recorded."""


@dataclasses.dataclass(frozen=True)
class StageKind:
    """One kind of stage: its config, its plan, its function and its gathering.

    Attributes:
      name: the kind (``Stage.kind``; what ``run.json`` records).
      run: the stage function (``StageContext -> None``; module-level, so Ray can ship it).
      resolve: ``raw config -> full config`` (validating field names against the library's
        config); None keeps the raw config.
      inputs: the input names its function reads (a stage may leave optional ones out);
        shell patterns (``scores:*``) name families of inputs.
      outputs: the folder of the run directory its outputs go under (``data/``) or the one
        output it writes (``report``).
      reported: the study's report stage reads it (an input of the report stage).
      side_by_side: its outputs are files side by side in ``outputs`` (reports keep them
        under their file names), so a later collection's have ``c<n>-`` before their name
        rather than a ``c<n>/`` folder.
      gather: report field -> :data:`Gatherer`: what a finished stage adds to that field of a
        report; a study's report takes the fields it has.
    """

    name: str
    run: StageFn
    resolve: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    inputs: tuple[str, ...] = ()
    outputs: str = ""
    reported: bool = False
    side_by_side: bool = False
    gather: Mapping[str, Gatherer] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "gather", MappingProxyType(dict(self.gather)))

    def config(self, raw: dict[str, Any]) -> dict[str, Any]:
        """The full, validated config of a stage of this kind; a ``collection`` key (a stage
        of a later collection) and a ``sizes`` key (a stage of named sizes other than the
        default: :mod:`elicit_jax.pipeline.sizes`) are kept beside it (:data:`KEPT_KEYS`)."""
        if self.resolve is None:
            return raw
        kept = {key: cast(raw[key]) for key, cast in KEPT_KEYS.items() if key in raw}
        if not kept:
            return self.resolve(raw)
        return {**self.resolve({k: v for k, v in raw.items() if k not in kept}), **kept}

    def check(self, stage: Stage) -> None:
        """Refuse a planned stage whose inputs or output this kind does not declare.

        Raises:
          ElicitError: naming the stage and the input or output.
        """
        for name in stage.inputs:
            if not any(fnmatch.fnmatchcase(name, p) for p in self.inputs):
                raise ElicitError(
                    f"stage '{stage.id}' reads input '{name}', which a '{self.name}' stage "
                    f"does not take (it takes: {', '.join(self.inputs) or 'none'})"
                )
        if not stage.output.startswith(self.outputs):
            raise ElicitError(
                f"stage '{stage.id}' writes '{stage.output}', outside the "
                f"'{self.outputs}' of its kind '{self.name}'"
            )


def reported_kinds(kinds: Iterable[StageKind]) -> tuple[str, ...]:
    """The names of those of ``kinds`` that a study's report stage reads."""
    return tuple(kind.name for kind in kinds if kind.reported)


class StageKinds:
    """The registry: stage kind name -> :class:`StageKind` (immutable; :meth:`extend` gives a
    new registry with more kinds, or more report fields for a kind already there)."""

    def __init__(self, kinds: Iterable[StageKind] = ()) -> None:
        by_name: dict[str, StageKind] = {}
        for kind in kinds:
            if kind.name in by_name:
                raise ElicitError(f"stage kind '{kind.name}' is registered twice")
            by_name[kind.name] = kind
        self._kinds = MappingProxyType(by_name)

    def __contains__(self, name: object) -> bool:
        return name in self._kinds

    def __iter__(self) -> Iterator[str]:
        return iter(self._kinds)

    def __len__(self) -> int:
        return len(self._kinds)

    def __getitem__(self, name: str) -> StageKind:
        return self.kind(name)

    def kind(self, name: str, where: Any = None) -> StageKind:
        """The entry of stage kind ``name``.

        Raises:
          ElicitError: no such kind (one line, naming the registered ones and ``where``).
        """
        if name not in self._kinds:
            known = ", ".join(sorted(self._kinds))
            raise ElicitError(f"unknown stage kind '{name}' (registered: {known})", where)
        return self._kinds[name]

    def extend(
        self, *kinds: StageKind, gather: Mapping[str, Mapping[str, Gatherer]] | None = None
    ) -> StageKinds:
        """A registry with ``kinds`` added (a name already registered is an error) and, per
        kind already registered, the report fields of ``gather`` added to its own."""
        extended = []
        for name, kind in self._kinds.items():
            more = (gather or {}).get(name, {})
            clash = set(more) & set(kind.gather)
            if clash:
                raise ElicitError(f"stage kind '{name}' already gathers {', '.join(clash)}")
            extended.append(dataclasses.replace(kind, gather={**kind.gather, **more}))
        unknown = set(gather or {}) - set(self._kinds)
        if unknown:
            raise ElicitError(f"cannot extend unregistered stage kind(s) {', '.join(unknown)}")
        return StageKinds([*extended, *kinds])

    def resolve(self, kind: str, raw: dict[str, Any]) -> dict[str, Any]:
        """The planner's config resolver: ``(kind, raw config) -> full config``."""
        return self.kind(kind).config(raw)

    def functions(self) -> dict[str, StageFn]:
        """Stage kind -> function, as the runners take them."""
        return {name: kind.run for name, kind in self._kinds.items()}

    def reported(self) -> tuple[str, ...]:
        """The kinds a study's report stage reads."""
        return reported_kinds(self._kinds.values())

    def check(self, graph: Graph, where: Any = None) -> None:
        """Refuse a graph with a stage of an unregistered kind, or one whose inputs or output
        its kind does not declare (:meth:`StageKind.check`)."""
        for stage in graph:
            self.kind(stage.kind, where).check(stage)
