"""Elicitation sessions: the method's live loop and the folder watcher.

* :mod:`.events` — the operator interface (observe → act; prompt, indicator, feedback events);
* :mod:`.session` — the protocol's state machine, driven one control step at a time;
* :mod:`.setup`, :mod:`.run` — loading and checking a session's inputs; the driving loop;
* :mod:`.live` — one compiled single-state scorer per session;
* :mod:`.rules`, :mod:`.explain` — accept/reject rules; field-level feedback;
* :mod:`.store`, :mod:`.progress`, :mod:`.replay` — durable per-episode storage and resume;
* :mod:`.operators` — scripted operators and the HG-DAgger intervener behind the interface;
* :mod:`.retrain` — π_new between batches;
* :mod:`.watch`, :mod:`.pages`, :mod:`.report` — demonstrations landing in a folder; pages;
  the session report.

Nothing below this package (``sim``, ``compat``, ``policy``, ``data``) knows about sessions.
"""
