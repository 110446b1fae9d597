"""When a threshold fit can be trusted, and when it is noise presented as a result.

A grid search over (λ, η) always finds *some* thresholds that separate a few contrast
demonstrations in sample — even two sets of the same operator's demos. So a fit is judged by
checks that do not reuse the demos it was fitted on:

Problems (the fit is written, marked ``trustworthy: false``, and the output says why):
  * **no margin** — the chosen thresholds sit on the edge of the best region (0 grid steps): a
    slightly different demonstration would flip a decision;
  * **leave-one-out well below in-sample** — held-out decisions are right less often than the
    in-sample decisions on the same demonstrations, by more than :data:`LOO_GAP`: the
    thresholds fit these demos, not a difference between the sets;
  * **no held-out check** — one demonstration per set, so leave-one-out is impossible;
  * **few pairs** — a set with fewer than :data:`MIN_PAIRS` state-action pairs;
  * **weak separation** — in-sample balanced accuracy below :data:`WEAK_ACCURACY`.

Severe problems (the fit is *meaningless*: ``fit-thresholds`` refuses to write it without
``--force``):
  * **held-out decisions at chance** — leave-one-out accuracy at most :data:`CHANCE_ACCURACY`;
  * **rejects the compatible operators' own demos** — more than half of the demonstrations of
    the operators in the compatible set (outside the incompatible set; e.g. the base
    operator's training demos) are rejected by the 5% rule under the fitted thresholds.

Example:
    >>> trust = assess_fit(report, compatible_operators={"base"}, decisions=per_episode)
    >>> trust["trustworthy"], trust["problems"]
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

MIN_PAIRS = 50
LOO_GAP = 0.15
CHANCE_ACCURACY = 0.6
WEAK_ACCURACY = 0.75
MOST = 0.5


def _held_out_in_sample(contrast: list[Mapping[str, Any]]) -> float | None:
    """In-sample accuracy over the demonstrations leave-one-out holds out (sets of size > 1)."""
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
) -> dict[str, Any]:
    """Judge a threshold fit (or hand-set thresholds evaluated on contrast sets).

    Args:
      report: the fit report: ``balanced_accuracy``, ``contrast`` (per demo ``compatible``,
        ``rejected``) and, for a fit, ``margin_steps`` and ``loo_accuracy``.
      compatible_operators: operators whose demos make up the compatible set.
      operator_decisions: operator -> (demos rejected, demos) over the scored demos that are
        NOT in the incompatible set.
      pairs_per_set: state-action pairs in the (compatible, incompatible) sets.

    Returns:
      ``{"trustworthy": bool, "meaningless": bool, "problems": [...], "severe": [...]}``;
      ``problems`` lists every problem, ``severe`` the ones that make the fit meaningless.
    """
    problems: list[str] = []
    severe: list[str] = []
    contrast = list(report.get("contrast", []))
    if report.get("margin_steps") == 0:
        problems.append(
            "no margin: the thresholds sit on the edge of the best region (0 grid steps), so "
            "a slightly different demonstration would flip a decision"
        )
    loo = report.get("loo_accuracy")
    in_sample = _held_out_in_sample(contrast)
    if "loo_accuracy" in report and loo is None:
        problems.append("one demonstration per set: no held-out (leave-one-out) check possible")
    if loo is not None and loo <= CHANCE_ACCURACY:
        severe.append(
            f"leave-one-out accuracy {loo:.2f} is at chance: the sets are not separable under "
            "this policy"
        )
    elif loo is not None and in_sample is not None and loo < in_sample - LOO_GAP:
        problems.append(
            f"leave-one-out accuracy {loo:.2f} is well below the in-sample {in_sample:.2f}: the "
            "thresholds fit these particular demonstrations"
        )
    for name, n in zip(("compatible", "incompatible"), pairs_per_set, strict=True):
        if n < MIN_PAIRS:
            problems.append(f"only {n} state-action pairs in the {name} set (< {MIN_PAIRS})")
    ba = report.get("balanced_accuracy")
    if ba is not None and ba < WEAK_ACCURACY:
        problems.append(f"weak separation: balanced accuracy {ba:.2f} on the contrast sets")
    for op in sorted(compatible_operators):
        rejected, total = operator_decisions.get(op, (0, 0))
        if total >= 2 and rejected > MOST * total:
            severe.append(
                f"the thresholds reject {rejected} of {total} demonstrations of operator "
                f"'{op}', whose demonstrations form the compatible set"
            )
    problems += severe
    return {
        "trustworthy": not problems,
        "meaningless": bool(severe),
        "problems": problems,
        "severe": severe,
    }


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
