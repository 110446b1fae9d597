"""The stage graph: stages, their artifacts, and the order they run in.

A :class:`Stage` names one unit of work (collect, train, score, ...): the registered
function that does it (``kind``), the artifact it writes (``output``, relative to the run
directory), its config and the stages whose artifacts it reads. A :class:`Graph` holds the
stages of a run and answers the questions the runner asks: in what order, and what depends
on what.
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

from elicit_jax.artifact import dumps
from elicit_jax.errors import ElicitError

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def freeze_config(config: Mapping[str, Any]) -> Mapping[str, Any]:
    """A read-only, JSON-normalised copy of ``config`` (tuples become lists, keys strings)."""
    return MappingProxyType(json.loads(dumps(dict(config))))


@dataclasses.dataclass(frozen=True)
class Stage:
    """One unit of work in a pipeline run.

    Attributes:
      id: unique id, path-like (``train/square-nut/mlp/seed0/naive/op1``).
      kind: name of the registered stage function that does the work.
      output: path of the artifact it writes, relative to the run directory.
      config: the JSON-serialisable config; a change re-runs this stage and its dependents.
      inputs: input name -> id of the stage whose output it reads.
      seed: the PRNG seed, if any.
      label: short human-readable description for progress displays.
    """

    id: str
    kind: str
    output: str
    config: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    inputs: Mapping[str, str] = dataclasses.field(default_factory=dict)
    seed: int | None = None
    label: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "config", freeze_config(self.config))
        object.__setattr__(self, "inputs", MappingProxyType(dict(self.inputs)))
        if not self.label:
            object.__setattr__(self, "label", self.id)

    def moved(self, segment: str, side_by_side: bool, label: str) -> Stage:
        """This stage moved under ``segment`` (a collection's ``c1``, a sizes'
        ``sizes-paper``): the segment after the first part of its id, output and input ids;
        a kind whose outputs sit side by side (``side_by_side``, a map) joins it to the file
        name instead (``maps/c1-<file>``), as reports keep maps under their file names."""

        def move(path: str, sep: str = "/") -> str:
            head, _, rest = path.partition("/")
            return f"{head}/{segment}{sep}{rest}"

        return dataclasses.replace(
            self,
            id=move(self.id),
            output=move(self.output, "-" if side_by_side else "/"),
            inputs={k: move(v) for k, v in self.inputs.items()},
            label=f"{label}: {self.label}",
        )

    @property
    def record_name(self) -> str:
        """File name of this stage's completion record (the id made filesystem-safe)."""
        return _SAFE.sub("_", self.id.replace("/", "__")) + ".json"


class Graph:
    """An immutable DAG of stages in a deterministic topological order.

    Args:
      stages: the stages; ids and outputs must be unique and every input must name a stage.

    Raises:
      ElicitError: on a duplicate id or output, an unknown input, or a cycle.
    """

    def __init__(self, stages: Iterable[Stage]) -> None:
        stages = list(stages)
        by_id: dict[str, Stage] = {}
        outputs: dict[str, str] = {}
        for s in stages:
            if s.id in by_id:
                raise ElicitError(f"duplicate stage id '{s.id}' in the pipeline graph")
            if s.output in outputs:
                raise ElicitError(
                    f"stages '{outputs[s.output]}' and '{s.id}' both write '{s.output}'"
                )
            by_id[s.id] = s
            outputs[s.output] = s.id
        for s in stages:
            for name, dep in s.inputs.items():
                if dep not in by_id:
                    raise ElicitError(f"stage '{s.id}' input '{name}' names unknown stage '{dep}'")
        self._by_id = by_id
        self._order = _toposort(stages)

    def __len__(self) -> int:
        return len(self._order)

    def __iter__(self):
        return iter(self._order)

    def __getitem__(self, stage_id: str) -> Stage:
        try:
            return self._by_id[stage_id]
        except KeyError as e:
            raise ElicitError(f"no stage '{stage_id}' in the pipeline graph") from e

    @property
    def order(self) -> tuple[Stage, ...]:
        """All stages, each after every stage it reads from (ties in insertion order)."""
        return self._order

    def dependents(self, stage_id: str) -> set[str]:
        """Ids of every stage that reads, directly or transitively, from ``stage_id``."""
        out: set[str] = set()
        frontier = {stage_id}
        while frontier:
            frontier = {
                s.id for s in self._order if s.id not in out and frontier & set(s.inputs.values())
            }
            out |= frontier
        return out

    def kinds(self) -> list[str]:
        """Distinct stage kinds, in first-run order."""
        return list(dict.fromkeys(s.kind for s in self._order))


def _toposort(stages: list[Stage]) -> tuple[Stage, ...]:
    """Kahn's algorithm, always taking the earliest-inserted ready stage (deterministic)."""
    remaining = {s.id: set(s.inputs.values()) for s in stages}
    done: set[str] = set()
    order: list[Stage] = []
    while remaining:
        ready = [s for s in stages if s.id in remaining and remaining[s.id] <= done]
        if not ready:
            cyc = sorted(remaining)[:3]
            raise ElicitError(f"the pipeline graph has a cycle through {', '.join(cyc)}")
        for s in ready:
            order.append(s)
            done.add(s.id)
            del remaining[s.id]
    return tuple(order)
