"""Run a session with a synchronous operator.

:func:`run_session` is the driving loop (observe → act → step until done) for any
:class:`~elicit_jax.elicit.events.SessionOperator`; listeners see every event (the CLI's
console reporter, ``elicit_jax.cli.session_console``, is one).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from elicit_jax.elicit.events import Event
from elicit_jax.elicit.session import Session


def run_session(
    setup: Any,
    operator: Any,
    listeners: list[Callable[[Session], Callable[[Event], None]]] | None = None,
) -> Session:
    """Run a session to its end with ``operator`` acting.

    Args:
      setup: from :func:`~elicit_jax.elicit.setup.open_session`.
      operator: a :class:`~elicit_jax.elicit.events.SessionOperator`. One that learns
        (a simulated person) may define ``catch_up(setup)``: on a resumed session it is
        called first, to relive the episodes already recorded.
      listeners: factories ``make(session) -> listener`` of more event listeners (called
        after the operator's ``on_event``).

    Returns:
      The finished session (``session.progress`` holds the counts).
    """
    session = Session(setup, [operator.on_event])
    for make in listeners or []:
        session.add_listener(make(session))
    catch_up = getattr(operator, "catch_up", None)
    if catch_up is not None and session.progress.counts.episodes:
        catch_up(setup)  # a learning operator relives the episodes a resumed session holds
    try:
        if not setup.demos_up_to_date(session.progress):
            setup.write_demos(session.progress)
        session.start()
        while not session.done:
            session.step(operator.act(session.observation()))
    finally:
        session.close()
    return session
