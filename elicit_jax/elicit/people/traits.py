"""Who a simulated person is: a starting style, motor traits and learning traits; populations.

A person is written as an operator spec, ``person:STYLE[,trait=value,...]``, e.g.
``person:conflict-flip-pause,imitation=0.6,uptake=0.75,speed=0.85,gain=1.3,delay=2,seed=3``.
The spec is the whole person: a session records it, so the same spec replays the same person.
The starting style is read for its *choices* only (mapped into the person's parameters θ);
every motor trait is the person's own.

:func:`make_population` draws a seeded population: person ``i`` starts from the ``i``-th of
the given styles (cycling) and draws each trait uniformly from its range.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from elicit_jax.errors import ElicitError

PROBABILITIES = ("imitation", "uptake", "explore")
INTEGERS = ("delay", "memory", "seed")
TRAITS = (
    *PROBABILITIES, "noise", "practice", "speed", "gain", "delay", "memory", "reach", "slip",
    "seed",
)  # fmt: skip
DEFAULT_RANGES: Mapping[str, tuple[float, float]] = {
    "imitation": (0.3, 0.9),
    "uptake": (0.4, 0.9),
    "explore": (0.2, 0.6),
    "noise": (0.04, 0.09),
    "practice": (0.15, 0.4),
    "speed": (0.7, 1.0),
    "gain": (1.0, 2.2),
    "delay": (0, 3),
    "memory": (2, 8),
    "reach": (0.25, 1.0),
    "slip": (0.01, 0.06),
}
"""Ranges a population's traits are drawn from (uniform; integers inclusive)."""
_BOUNDS = {
    "noise": (0.0, 0.5), "practice": (0.0, 1.0), "speed": (0.05, 1.0), "gain": (0.1, 10.0),
    "delay": (0, 20), "memory": (1, 1000), "reach": (0.0, 1.0), "slip": (0.0, 1.0),
}  # fmt: skip


@dataclasses.dataclass(frozen=True)
class PersonTraits:
    """A simulated person (see ``docs/people.md`` for the model).

    Attributes:
      style: the scripted style whose choices it starts from (never the base operator's).
      imitation: probability of fitting its parameters to the prompt's demonstrations.
      uptake: probability of watching each flagged window's retrieved base segment.
      explore: probability of trying a perturbed θ after a failed (or, with the live
        indicator, too red) episode.
      noise: its motor noise (action std) at the first episode.
      practice: fraction of the noise above half of it lost per episode done.
      speed: its largest action magnitude (0-1].
      gain: its proportional gain.
      delay: its reaction delay in control steps (it acts on the state ``delay`` steps ago).
      memory: how many shown segments it remembers (the last ones).
      reach: the part of each parameter's range it can reach, around its starting θ (1: all).
      slip: execution error: std of the offset of an adopted θ, as a fraction of the range.
      seed: its own randomness (starting perturbation, what it takes up, its slips).
    """

    style: str
    imitation: float = 0.6
    uptake: float = 0.6
    explore: float = 0.3
    noise: float = 0.06
    practice: float = 0.25
    speed: float = 0.9
    gain: float = 1.5
    delay: int = 1
    memory: int = 5
    reach: float = 1.0
    slip: float = 0.03
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.style or "," in self.style or "=" in self.style:
            raise ElicitError(f"person: bad starting style {self.style!r}")
        for name in PROBABILITIES:
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ElicitError(f"person: {name} must be in [0, 1], got {value}")
        for name, (lo, hi) in _BOUNDS.items():
            value = getattr(self, name)
            if not (np.isfinite(value) and lo <= value <= hi):
                raise ElicitError(f"person: {name} must be in [{lo}, {hi}], got {value}")
        if self.seed < 0:
            raise ElicitError(f"person: seed must be >= 0, got {self.seed}")

    def noise_at(self, n: int) -> float:
        """Motor noise after n episodes: ``noise * (1 + (1 - practice) ** n) / 2``."""
        return self.noise * (1.0 + (1.0 - self.practice) ** n) / 2.0

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
            values[key] = int(text) if key in INTEGERS else float(text)
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
        drawn: dict[str, float | int] = {}
        for k, (lo, hi) in bounds.items():
            if k in INTEGERS:
                drawn[k] = int(rng.integers(int(lo), int(hi) + 1))
            else:
                drawn[k] = round(float(rng.uniform(lo, hi)), 3)
        people.append(
            PersonTraits(style=styles[i % len(styles)], seed=int(seed) * 1000 + i, **drawn)
        )
    return people
