"""Simulated people for elicitation studies: their own parameters, changed by what they see.

* :mod:`.traits` — who a person is (starting style, motor and learning traits), as an operator
  spec ``person:STYLE[,trait=value,...]``, and seeded populations;
* :mod:`.space` — per task, the continuous parameters θ a person adjusts and their bounds;
* :mod:`.imagine` — "what would I do at these states" (teacher forcing, calm controller);
* :mod:`.learn` — the generic fit of θ to shown segments (compass search);
* :mod:`.person` — :class:`~.person.SimulatedPerson`, the operator, and its update rules.

Importing this package registers the ``person`` operator kind, so sessions accept
``--operator person:conflict-flip-pause,uptake=0.8``. The model, its assumptions and what
would make it wrong are in ``docs/people.md``.
"""

from __future__ import annotations

from typing import Any

from elicit_jax.elicit.operators import OperatorContext, in_session, register_operator
from elicit_jax.elicit.people.person import SimulatedPerson
from elicit_jax.elicit.people.traits import PersonTraits, make_population, parse_person


def make_person(name: str, context: OperatorContext) -> Any:
    """The ``person:NAME`` operator of a session (NAME: ``STYLE[,trait=value,...]``)."""
    person = SimulatedPerson(context.task, parse_person(name), context.base)
    return in_session(person, context)


def person_of(operator: Any) -> SimulatedPerson | None:
    """The simulated person behind a session operator (unwrapping the DAgger intervener)."""
    inner = getattr(operator, "operator", operator)
    return inner if isinstance(inner, SimulatedPerson) else None


register_operator("person", make_person)

__all__ = ["PersonTraits", "SimulatedPerson", "make_person", "make_population", "parse_person"]
