"""The thresholds (λ, η): one value from the file (or flag, or preset) to the scoring kernel.

:class:`Thresholds` is the only carrier of (λ, η) along the data path: ``read_thresholds``
returns it, configs hold it, commands and pipeline stages pass it whole. It keeps where the
values came from (``source``), the trust verdict recorded when they were fitted, the units
they are in (``action_scale``) and the policy they were fitted for (a content hash of its
parameters, ``policy``). Only the kernels (:mod:`elicit_jax.compat.measures`,
:mod:`elicit_jax.compat.scorer`) take the two floats.

This module is also the one place that knows how thresholds are spelled in JSON: the
``thresholds`` artifact ``fit-thresholds`` writes (:func:`write_thresholds`,
:func:`read_thresholds`), the ``thresholds`` block of a scores header
(:func:`scores_thresholds`), a score config's and a filter config's fields
(:func:`config_fields`, :func:`from_config_fields`) and a session header's
(:func:`session_fields`, :func:`from_session_fields`). The fit itself is in
:mod:`elicit_jax.compat.threshold_fit`.

Example:
    >>> t = read_thresholds("thresholds.json")
    >>> t.pair, t.source, t.policy
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from elicit_jax.compat.trust import Verdict, thresholds_verdict
from elicit_jax.errors import ElicitError

THRESHOLDS_KIND = "thresholds"
SCHEMA_VERSION = 1
LAMBDA_KEY = "lambda"
ETA_KEY = "eta"
POLICY_KEY = "policy_sha256"
"""Where a thresholds file and a scores header's ``policy`` block keep the content hash of
the policy's parameters (:func:`elicit_jax.policy.loaded.policy_sha256`)."""
STAND_IN = "raw-unit preset"
"""How the recorded source of a raw-unit preset standing in on std-scaled scores begins."""


def check_thresholds(lam: Any, eta: Any, source: str | Path | None = None) -> tuple[float, float]:
    """The one validation of (λ, η) every command applies: both real numbers (not strings or
    booleans), finite and > 0.

    Returns:
      ``(float(lam), float(eta))``.

    Raises:
      ElicitError: naming ``source`` (a thresholds file) when given.
    """
    if not all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in (lam, eta)):
        raise ElicitError(f"thresholds must be numbers, got lambda={lam!r}, eta={eta!r}", source)
    pair = float(lam), float(eta)
    for name, v in zip((LAMBDA_KEY, ETA_KEY), pair, strict=True):
        if not (math.isfinite(v) and v > 0):
            raise ElicitError(f"{name} must be a finite number > 0, got {v:g}", source)
    return pair


@dataclasses.dataclass(frozen=True)
class Thresholds:
    """Resolved thresholds.

    Attributes:
      lam: likelihood-error threshold λ (finite, > 0).
      eta: novelty threshold η (finite, > 0).
      source: where they came from: ``"file PATH"``, ``"preset NAME"``, ``"given"``, ...
      file: the thresholds file, when they came from one.
      verdict: the trust verdict recorded when the file was fitted (None unless from a file).
      action_scale: the units: ``none`` (raw action units) or ``std`` (per-dim scaled).
      policy: content hash of the parameters of the policy they were fitted for (None: not
        recorded).
      stand_in: a raw-unit preset standing in on std-scaled scores: its M and accept/reject
        are not verdicts.
    """

    lam: float
    eta: float
    source: str
    file: Path | None = None
    verdict: Verdict | None = None
    action_scale: str = "none"
    policy: str | None = None
    stand_in: bool = False

    def __post_init__(self) -> None:
        lam, eta = check_thresholds(self.lam, self.eta, self.file)
        object.__setattr__(self, "lam", lam)
        object.__setattr__(self, "eta", eta)

    @property
    def pair(self) -> tuple[float, float]:
        """``(λ, η)``: what the kernels take."""
        return self.lam, self.eta

    def to_json(self) -> dict[str, float]:
        """``{"lambda": λ, "eta": η}``: how every artifact spells them."""
        return {LAMBDA_KEY: self.lam, ETA_KEY: self.eta}

    def describe(self) -> str:
        """One line for the user: the values and where they came from."""
        return f"λ={self.lam:.4g}, η={self.eta:.4g} from {self.source}"

    def verdict_line(self) -> str | None:
        """The line to show the user about the file's recorded verdict, or None when clean."""
        if self.verdict is None or self.verdict.clean:
            return None
        what = "warning" if self.verdict.problems else "note"
        return f"{what}: {self.file}: judged when fitted: {self.verdict.summary()}"


def _number(data: Mapping[str, Any], key: str, path: str | Path | None) -> float:
    """``data[key]`` as a finite float > 0: a JSON number, not a string or a boolean."""
    if key not in data:
        raise ElicitError(f"thresholds lack '{key}'", path)
    v = data[key]
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ElicitError(f"'{key}' must be a number, got {v!r}", path)
    if not (math.isfinite(v) and v > 0):
        raise ElicitError(f"'{key}' must be a finite number > 0, got {v!r}", path)
    return float(v)


def pair_from_json(data: Mapping[str, Any], path: str | Path | None = None) -> tuple[float, float]:
    """``(λ, η)`` of a JSON mapping holding ``lambda`` and ``eta`` (strictly: numbers, finite
    and > 0).

    Raises:
      ElicitError: a key missing, a string, a boolean, a non-finite or non-positive value,
        naming ``path``.
    """
    return _number(data, LAMBDA_KEY, path), _number(data, ETA_KEY, path)


def config_fields(t: Thresholds | None, key: str = LAMBDA_KEY) -> dict[str, float | None]:
    """A config's JSON fields for ``t``: ``{key: λ, "eta": η}`` (``None`` values for none).
    ``key`` is ``lambda`` (score configs) or ``lambda_`` (filter configs, as pipelines store
    them)."""
    return {key: None if t is None else t.lam, ETA_KEY: None if t is None else t.eta}


def from_config_fields(
    d: dict[str, Any], source: str, key: str = LAMBDA_KEY, action_scale: str = "none"
) -> Thresholds | None:
    """Pop :func:`config_fields` out of ``d``; their :class:`Thresholds` (None when both are
    None).

    Raises:
      ElicitError: one given without the other, or values not finite and > 0.
    """
    lam, eta = d.pop(key, None), d.pop(ETA_KEY, None)
    if lam is None and eta is None:
        return None
    if lam is None or eta is None:
        raise ElicitError("give both lambda and eta, or neither")
    return Thresholds(lam, eta, source, action_scale=action_scale)


SESSION_KEYS = (LAMBDA_KEY, ETA_KEY, "thresholds_file")
"""The keys a session header stores its :class:`Thresholds` under."""


def session_fields(t: Thresholds) -> dict[str, Any]:
    """``t`` as a session header stores it: :data:`SESSION_KEYS`."""
    return {**t.to_json(), "thresholds_file": None if t.file is None else str(t.file)}


def from_session_fields(d: dict[str, Any]) -> Thresholds:
    """Pop :data:`SESSION_KEYS` (``lambda_`` read as ``lambda``) out of ``d``; their value.

    Raises:
      ElicitError: λ or η missing, not numbers, or not finite and > 0.
    """
    stored = {k: d.pop(k, None) for k in SESSION_KEYS}
    if "lambda_" in d:
        stored[LAMBDA_KEY] = d.pop("lambda_")
    if stored[LAMBDA_KEY] is None or stored[ETA_KEY] is None:
        raise ElicitError("session config without thresholds (lambda and eta)")
    lam, eta = check_thresholds(stored[LAMBDA_KEY], stored[ETA_KEY])
    file = stored["thresholds_file"]
    if file is None:
        return Thresholds(lam, eta, "given")
    return Thresholds(lam, eta, f"file {file}", file=Path(file))


def read_thresholds_header(path: str | Path) -> dict[str, Any]:
    """The header of a thresholds artifact, checked: kind, schema version, λ and η.

    Raises:
      ElicitError: a missing file, a file that is not JSON (a Parquet scores file given by
        mistake, ...), an artifact of another kind, a newer schema version, or λ, η that are
        not numbers (strings, booleans), not finite or not > 0; each naming the file.
    """
    from elicit_jax.artifact import check_artifact, read_json

    try:
        data = read_json(path)
    except ElicitError as e:
        if "Parquet" not in str(e):
            raise
        raise ElicitError(
            "is a Parquet file, not a thresholds .json: give the thresholds.json that "
            "fit-thresholds writes",
            path,
        ) from e
    check_artifact(data, path, THRESHOLDS_KIND, SCHEMA_VERSION, what="thresholds")
    pair_from_json(data, path)
    return data


def read_thresholds(path: str | Path) -> Thresholds:
    """The :class:`Thresholds` of a thresholds artifact (the JSON ``fit-thresholds`` writes):
    values, the file, its recorded verdict, units and policy.

    Raises:
      ElicitError: as :func:`read_thresholds_header`.
    """
    data = read_thresholds_header(path)
    lam, eta = pair_from_json(data, path)
    policy = data.get(POLICY_KEY)
    return Thresholds(
        lam,
        eta,
        f"file {path}",
        file=Path(path),
        verdict=thresholds_verdict(data),
        action_scale=str(data.get("action_scale", "none")),
        policy=str(policy) if policy else None,
    )


def write_thresholds(
    path: str | Path,
    thresholds: Thresholds,
    *,
    method: str,
    inputs: Mapping[str, str | Path],
    config: Mapping[str, Any],
    report: Mapping[str, Any],
) -> dict[str, Any]:
    """Write a ``thresholds`` artifact (JSON): λ and η, their units (``action_scale``:
    ``none`` = raw action units, ``std`` = each dim divided by the training actions' std) and
    the policy they were fitted for (:data:`POLICY_KEY`, null when unknown), with the inputs
    (the scores file they were fitted on), settings and report.

    Returns:
      The header written.
    """
    from elicit_jax.artifact import make_header, write_json

    header = make_header(
        THRESHOLDS_KIND,
        SCHEMA_VERSION,
        config=config,
        inputs=inputs,
        method=method,
        report=dict(report),
        action_scale=thresholds.action_scale,
        **{POLICY_KEY: thresholds.policy},
        **thresholds.to_json(),
    )
    write_json(path, header)
    return header


def fitted_on(t: Thresholds, scores_header: Mapping[str, Any]) -> Thresholds:
    """``t`` bound to the scores they were fitted on: their units and their policy."""
    scale = str(dict(scores_header.get("config") or {}).get("action_scale", "none"))
    return dataclasses.replace(t, action_scale=scale, policy=scores_policy(scores_header))


def scores_fields(t: Thresholds) -> dict[str, Any]:
    """How a scores header records the thresholds it was judged under: ``thresholds``
    (``{lambda, eta}``) and ``thresholds_source`` (read back by :func:`scores_thresholds`)."""
    return {"thresholds": t.to_json(), "thresholds_source": t.source}


def scores_policy(header: Mapping[str, Any]) -> str | None:
    """The policy content hash a scores header records (None for files written before)."""
    value = dict(header.get("policy") or {}).get(POLICY_KEY)
    return str(value) if value else None


def scores_thresholds(header: Mapping[str, Any], path: str | Path) -> Thresholds:
    """The thresholds a scores file was judged under (its ``thresholds`` block and
    ``thresholds_source``), as :class:`Thresholds` whose source names the file.

    Raises:
      ElicitError: the block missing or not valid numbers, naming ``path``.
    """
    lam, eta = pair_from_json(dict(header.get("thresholds") or {}), path)
    recorded = str(header.get("thresholds_source", "given"))
    return Thresholds(
        lam,
        eta,
        f"the values stored in {path} ({recorded})",
        action_scale=str(header.get("config", {}).get("action_scale", "none")),
        policy=scores_policy(header),
        stand_in=recorded.startswith(STAND_IN),
    )
