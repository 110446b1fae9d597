"""When thresholds can be trusted, and when they are noise presented as a result.

A grid search over (λ, η) always finds *some* thresholds that separate a few contrast
demonstrations in sample — even two sets of the same operator's demos. So a fit is judged by
checks that do not reuse the demos it was fitted on, and by the one set of demonstrations the
thresholds must accept: the base policy's own training data.

Problems (the fit is written, marked ``trustworthy: false``, and the output says why):
  * **no margin** — the chosen thresholds sit on the edge of the best region (0 grid steps): a
    slightly different demonstration would flip a decision;
  * **leave-one-out well below in-sample** — held-out decisions are right less often than the
    in-sample decisions on the same demonstrations, by more than :data:`LOO_GAP`: the
    thresholds fit these demos, not a difference between the sets;
  * **no held-out check** — one demonstration per set, so leave-one-out is impossible;
  * **few pairs** — a set with fewer than :data:`MIN_PAIRS` state-action pairs;
  * **weak separation** — in-sample balanced accuracy below :data:`WEAK_ACCURACY`;
  * **one operator** — both contrast sets come from the same operator: the fit separates
    demonstrations of one person, not styles;
  * **contrast set inside the training data** — a contrast demonstration is one the base
    policy was trained on (same observations and actions): the policy has fitted it, so it
    looks more compatible than any new demonstration would.

Severe problems (the fit is *meaningless*: ``fit-thresholds`` refuses to write it without
``--force``):
  * **held-out decisions at chance** — leave-one-out accuracy at most :data:`CHANCE_ACCURACY`;
  * **rejects the compatible operators' own demos** — more than half of the demonstrations of
    the operators in the compatible set (outside the incompatible set) are rejected by the 5%
    rule under the fitted thresholds;
  * **rejects the base policy's training demos** — more than :data:`TRAINING_SHARE` (10%) of
    the demonstrations the base policy was trained on are rejected by the 5% rule.

A check that could not be run (no record of the training data, its file gone) is listed under
``unchecked``: the verdict is then not *clean*, and every command that loads the thresholds
says so.

Example:
    >>> verdict = assess_fit(report, compatible_operators={"base"}, ...)
    >>> verdict.trustworthy, verdict.problems
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

MIN_PAIRS = 50
LOO_GAP = 0.15
CHANCE_ACCURACY = 0.6
WEAK_ACCURACY = 0.75
MOST = 0.5
TRAINING_SHARE = 0.10
SCORER_TRAINING_DEMOS = "training demos of the policy that scored (D_base)"
"""What checks (a) and (c) are against when a policy of its own scored (a pipeline's
``[scorer]``, trained on the same D_base as the base policy)."""
_OLD = (
    "the checks against the base policy's training data were not run (written by an older "
    "elicit-jax): refit to run them"
)


@dataclasses.dataclass(frozen=True)
class Verdict:
    """Whether thresholds can be trusted: the problems found and the checks not run.

    Attributes:
      problems: every problem found (severe ones included).
      severe: the problems that make a fit meaningless.
      unchecked: checks that could not be run, each with the reason.
      forced: a meaningless fit written anyway (``--force``).
    """

    problems: tuple[str, ...] = ()
    severe: tuple[str, ...] = ()
    unchecked: tuple[str, ...] = ()
    forced: bool = False

    @property
    def trustworthy(self) -> bool:
        """No problem found."""
        return not self.problems

    @property
    def meaningless(self) -> bool:
        """A severe problem found."""
        return bool(self.severe)

    @property
    def clean(self) -> bool:
        """No problem found and every check run."""
        return not self.problems and not self.unchecked

    def __add__(self, other: Verdict) -> Verdict:
        return Verdict(
            self.problems + other.problems,
            self.severe + other.severe,
            self.unchecked + other.unchecked,
            self.forced or other.forced,
        )

    def headline(self) -> str:
        """``MEANINGLESS``, ``NOT TRUSTWORTHY``, ``NOT FULLY CHECKED`` or ``no problems found``."""
        if self.meaningless:
            return "MEANINGLESS"
        if self.problems:
            return "NOT TRUSTWORTHY"
        return "NOT FULLY CHECKED" if self.unchecked else "no problems found"

    def summary(self) -> str:
        """One line: the headline, the problems, then what was not checked."""
        parts = list(self.problems) + [f"not checked: {u}" for u in self.unchecked]
        forced = " (written with --force)" if self.forced else ""
        return self.headline() + forced + (": " + "; ".join(parts) if parts else "")

    def to_dict(self) -> dict[str, Any]:
        """The JSON form stored under ``report.trust`` of a thresholds artifact."""
        return {
            "trustworthy": self.trustworthy,
            "meaningless": self.meaningless,
            "problems": list(self.problems),
            "severe": list(self.severe),
            "unchecked": list(self.unchecked),
            "forced": self.forced,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Verdict:
        """Inverse of :meth:`to_dict`; a verdict written before ``unchecked`` existed says the
        training-data checks were not run."""
        unchecked = d.get("unchecked", [_OLD])
        return cls(
            tuple(map(str, d.get("problems", []))),
            tuple(map(str, d.get("severe", []))),
            tuple(map(str, unchecked)),
            bool(d.get("forced", False)),
        )


def thresholds_verdict(header: Mapping[str, Any]) -> Verdict:
    """The verdict recorded in a thresholds artifact's header (``report.trust``)."""
    trust = (header.get("report") or {}).get("trust")
    if not trust:
        return Verdict(
            unchecked=(
                "no trust verdict recorded (hand-set without contrast sets, or written by an "
                "older elicit-jax): record them again with fit-thresholds to check them",
            )
        )
    return Verdict.from_dict(trust)


def held_out_in_sample(contrast: list[Mapping[str, Any]]) -> float | None:
    """In-sample accuracy over the demonstrations leave-one-out holds out (sets of size > 1):
    the fraction decided right by the fitted thresholds, the number leave-one-out is compared
    with (and the one the report shows next to it)."""
    labels = [bool(c["compatible"]) for c in contrast]
    held = [c for c in contrast if labels.count(bool(c["compatible"])) > 1]
    if not held:
        return None
    return float(np.mean([bool(c["rejected"]) != bool(c["compatible"]) for c in held]))


def assess_fit(
    report: Mapping[str, Any],
    *,
    compatible_operators: Collection[str],
    operator_decisions: Mapping[str, tuple[int, int]],
    pairs_per_set: tuple[int, int],
) -> Verdict:
    """Judge a threshold fit (or hand-set thresholds evaluated on contrast sets).

    Args:
      report: the fit report: ``balanced_accuracy``, ``contrast`` (per demo ``compatible``,
        ``rejected``) and, for a fit, ``margin_steps``, ``loo_accuracy`` and
        ``in_sample_accuracy`` (:func:`held_out_in_sample`).
      compatible_operators: operators whose demos make up the compatible set.
      operator_decisions: operator -> (demos rejected, demos) over the scored demos that are
        NOT in the incompatible set.
      pairs_per_set: state-action pairs in the (compatible, incompatible) sets.

    Returns:
      The :class:`Verdict` of the contrast checks.
    """
    problems: list[str] = []
    severe: list[str] = []
    if report.get("margin_steps") == 0:
        problems.append(
            "no margin: the thresholds sit on the edge of the best region (0 grid steps), so "
            "a slightly different demonstration would flip a decision"
        )
    loo = report.get("loo_accuracy")
    in_sample = report.get("in_sample_accuracy")
    if "loo_accuracy" in report and loo is None:
        problems.append("one demonstration per set: no held-out (leave-one-out) check possible")
    if loo is not None and loo <= CHANCE_ACCURACY:
        severe.append(
            f"leave-one-out accuracy {loo:.3f} is at chance: the sets are not separable under "
            "this policy"
        )
    elif loo is not None and in_sample is not None and loo < in_sample - LOO_GAP:
        problems.append(
            f"leave-one-out accuracy {loo:.3f} is well below the in-sample accuracy "
            f"{in_sample:.3f} of the same {report.get('n_loo')} demonstrations: the "
            "thresholds fit these particular demonstrations"
        )
    for name, n in zip(("compatible", "incompatible"), pairs_per_set, strict=True):
        if n < MIN_PAIRS:
            problems.append(f"only {n} state-action pairs in the {name} set (< {MIN_PAIRS})")
    ba = report.get("balanced_accuracy")
    if ba is not None and ba < WEAK_ACCURACY:
        problems.append(f"weak separation: balanced accuracy {ba:.3f} on the contrast sets")
    for op in sorted(compatible_operators):
        rejected, total = operator_decisions.get(op, (0, 0))
        if total >= 2 and rejected > MOST * total:
            severe.append(
                f"the thresholds reject {rejected} of {total} demonstrations of operator "
                f"'{op}', whose demonstrations form the compatible set"
            )
    return Verdict(tuple(problems + severe), tuple(severe))


def training_rejections(rejected: int, total: int, source: str, *, scorer: bool = False) -> Verdict:
    """Check (a): thresholds must accept the scoring policy's own training demonstrations.

    Args:
      rejected: training demos the 5% rule rejects under the thresholds.
      total: training demos checked (0: the check could not be run).
      source: where their scores came from (said in the message).
      scorer: the scores come from a policy of their own trained on D_base (a pipeline's
        ``[scorer]``), not the base policy: the message names that policy's training demos.
    """
    if total == 0:
        return Verdict()
    if rejected > TRAINING_SHARE * total:
        share = f"{100 * rejected / total:.0f}% > {100 * TRAINING_SHARE:.0f}%; {source}"
        msg = (
            f"the thresholds reject {rejected} of the {total} {SCORER_TRAINING_DEMOS} "
            f"({share}): they would reject the very data that policy learned from"
            if scorer
            else f"the thresholds reject {rejected} of the base policy's {total} own training "
            f"demonstrations ({share}): they would reject the very data the policy learned from"
        )
        return Verdict((msg,), (msg,))
    return Verdict()


def one_operator(compatible_ops: Collection[str], incompatible_ops: Collection[str]) -> Verdict:
    """Check (b): contrast sets drawn from one operator separate demos, not styles."""
    ops = set(compatible_ops) | set(incompatible_ops)
    if len(ops) != 1:
        return Verdict()
    (op,) = ops
    if op in ("", "unknown"):
        return Verdict(
            unchecked=(
                "whether the contrast sets come from different operators (every demo is "
                f"labelled '{op or 'unknown'}')",
            )
        )
    return Verdict(
        (
            f"both contrast sets are demonstrations of operator '{op}': the fit separates "
            "demonstrations of one person, not a compatible style from an incompatible one",
        )
    )


def training_overlap(
    sets: Mapping[str, Collection[int]],
    digests: Mapping[int, str],
    training: Collection[str],
    *,
    scorer: bool = False,
) -> Verdict:
    """Check (c): no contrast demonstration may be one the scoring policy was trained on.

    Args:
      sets: set name (``compatible``/``incompatible``) -> episode ids in the scores.
      digests: episode id -> content hash of the scored demonstrations.
      training: content hashes of the scoring policy's training demonstrations.
      scorer: as for :func:`training_rejections`.
    """
    problems = []
    train = set(training)
    where = SCORER_TRAINING_DEMOS if scorer else "base policy's training data"
    for name, ids in sets.items():
        inside = sorted(e for e in ids if digests.get(int(e)) in train)
        if inside:
            more = f" and {len(inside) - 5} more" if len(inside) > 5 else ""
            problems.append(
                f"{len(inside)} of the {len(ids)} demonstrations of the {name} set "
                f"(episode {', '.join(map(str, inside[:5]))}{more}) are in the {where}: "
                "the policy has fitted them, so their scores say nothing "
                "about new demonstrations"
            )
    return Verdict(tuple(problems))


def operator_decisions(
    episode: np.ndarray,
    operator: np.ndarray,
    rejected_episodes: Collection[int],
    excluded: Collection[int],
) -> dict[str, tuple[int, int]]:
    """Operator -> (rejected demos, demos), over episodes not in ``excluded``.

    Args:
      episode: (N,) episode id per pair.
      operator: (N,) operator per pair.
      rejected_episodes: ids of the episodes the 5% rule rejects.
      excluded: ids left out (the incompatible set).
    """
    ids, first = np.unique(np.asarray(episode), return_index=True)
    ops = np.asarray(operator)[first].astype(str)
    keep = ~np.isin(ids, np.asarray(list(excluded), dtype=ids.dtype))
    rej = np.isin(ids, np.asarray(list(rejected_episodes), dtype=ids.dtype))
    out: dict[str, tuple[int, int]] = {}
    for op in sorted(set(ops[keep].tolist())):
        sel = keep & (ops == op)
        out[op] = (int((rej & sel).sum()), int(sel.sum()))
    return out
