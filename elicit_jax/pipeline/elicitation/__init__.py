"""Elicitation studies: simulated people through the elicitation interface, end to end; what
the study kind ``elicitation`` adds to the one pipeline engine
(:mod:`elicit_jax.pipeline.study_kinds`).

* :mod:`.spec` — the study definition (``[pipeline] kind = "elicitation"``);
* :mod:`.plan` — its stage graph (sessions per person and condition, retraining, evaluation);
* :mod:`.stages` — the session, session M-filter and report stages;
* :mod:`.gather`, :mod:`.tables`, :mod:`.report` — the study report.
"""
