"""Who a simulated person is: a starting style and five learning traits, and a population.

A person is written as an operator spec, ``person:STYLE[,trait=value,...]``, e.g.
``person:conflict-flip-pause,imitation=0.6,uptake=0.75,explore=0.3,noise=2,practice=0.25,seed=3``.
The spec is the whole person: a session records it, so the same spec replays the same person.

:func:`make_population` draws a seeded population: person ``i`` starts from the ``i``-th of
the given styles (cycling) and draws each trait uniformly from its range.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from elicit_jax.errors import ElicitError

PROBABILITIES = ("imitation", "uptake", "explore")
TRAITS = (*PROBABILITIES, "noise", "practice", "seed")
DEFAULT_RANGES: Mapping[str, tuple[float, float]] = {
    "imitation": (0.3, 0.9),
    "uptake": (0.4, 0.9),
    "explore": (0.2, 0.6),
    "noise": (1.5, 3.0),
    "practice": (0.15, 0.4),
}
"""Ranges a population's traits are drawn from (uniform)."""


@dataclasses.dataclass(frozen=True)
class PersonTraits:
    """A simulated person (see ``docs/people.md`` for the model).

    Attributes:
      style: the scripted style it starts from (a name in the task's registry).
      imitation: probability of adopting each change the prompt's demonstrations suggest.
      uptake: probability of acting on each flagged window of a rejection's feedback.
      explore: probability of trying another way after a demonstration the live indicator
        lit red more often than the rule allows.
      noise: motor noise (and hesitation, waypoint jitter) at the first episode, as a multiple
        of the starting style's (>= 1).
      practice: fraction of the excess noise lost per episode done (0: never improves).
      seed: the person's own randomness (which changes it takes up).
    """

    style: str
    imitation: float = 0.6
    uptake: float = 0.6
    explore: float = 0.3
    noise: float = 2.0
    practice: float = 0.25
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.style or "," in self.style or "=" in self.style:
            raise ElicitError(f"person: bad starting style {self.style!r}")
        for name in PROBABILITIES:
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ElicitError(f"person: {name} must be in [0, 1], got {value}")
        if not (np.isfinite(self.noise) and self.noise >= 1.0):
            raise ElicitError(f"person: noise must be >= 1 (a multiple), got {self.noise}")
        if not 0.0 <= self.practice <= 1.0:
            raise ElicitError(f"person: practice must be in [0, 1], got {self.practice}")
        if self.seed < 0:
            raise ElicitError(f"person: seed must be >= 0, got {self.seed}")

    def noise_multiplier(self, n: int) -> float:
        """Motor-noise multiple after n episodes: ``1 + (noise - 1) * (1 - practice) ** n``."""
        return 1.0 + (self.noise - 1.0) * (1.0 - self.practice) ** n

    def spec(self) -> str:
        """The operator spec naming this person (``person:STYLE,imitation=...``)."""
        parts = [self.style] + [f"{k}={_fmt(getattr(self, k))}" for k in TRAITS]
        return "person:" + ",".join(parts)


def _fmt(value: float | int) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


def parse_person(name: str) -> PersonTraits:
    """The person named by the part of a spec after ``person:`` (``STYLE[,trait=value...]``).

    Raises:
      ElicitError: unknown trait, malformed or out-of-range value.
    """
    style, *rest = name.split(",")
    values: dict[str, float | int] = {}
    for item in rest:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or key not in TRAITS:
            raise ElicitError(
                f"person:{name}: expected trait=value with a trait among {', '.join(TRAITS)}, "
                f"got {item!r}"
            )
        try:
            values[key] = int(text) if key == "seed" else float(text)
        except ValueError:
            raise ElicitError(f"person:{name}: {key} needs a number, got {text!r}") from None
        if not np.isfinite(values[key]):
            raise ElicitError(f"person:{name}: {key} must be finite, got {text!r}")
    return PersonTraits(style=style.strip(), **values)  # type: ignore[arg-type]


def make_population(
    styles: Sequence[str],
    size: int,
    seed: int,
    ranges: Mapping[str, Sequence[float]] | None = None,
) -> list[PersonTraits]:
    """A seeded population of ``size`` people.

    Args:
      styles: starting styles; person ``i`` takes ``styles[i % len(styles)]``.
      size: how many people.
      seed: the population's seed (traits and each person's own seed derive from it).
      ranges: ``trait -> (low, high)`` overriding :data:`DEFAULT_RANGES`.

    Returns:
      The people, traits rounded to 3 decimals (so their specs round-trip exactly).
    """
    if size < 1 or not styles:
        raise ElicitError(f"a population needs at least one person and one style (size {size})")
    bounds = dict(DEFAULT_RANGES)
    for key, value in (ranges or {}).items():
        if key not in DEFAULT_RANGES:
            raise ElicitError(
                f"unknown trait range '{key}' (choose from {', '.join(DEFAULT_RANGES)})"
            )
        lo, hi = (float(v) for v in value)
        if not lo <= hi:
            raise ElicitError(f"trait range {key}: low {lo} above high {hi}")
        bounds[key] = (lo, hi)
    rng = np.random.default_rng([int(seed), 7919])
    people = []
    for i in range(size):
        drawn = {k: round(float(rng.uniform(lo, hi)), 3) for k, (lo, hi) in bounds.items()}
        people.append(
            PersonTraits(style=styles[i % len(styles)], seed=int(seed) * 1000 + i, **drawn)
        )
    return people
