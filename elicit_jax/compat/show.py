"""The compatibility layer's work on a console: the ``fit-thresholds`` report as rich tables
(the thresholds and their quality, rejections per operator, the contrast decisions and the
trust verdict) and the scoring progress bar.

A rendering module on the console its caller passes: the CLI and the pipeline's stages pass
:func:`print_report` (bound to their console) to
:func:`~elicit_jax.compat.fit.fit_scores_file` and :func:`scoring_bar` to
:func:`~elicit_jax.compat.score_file.score_file`, which never print themselves.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from elicit_jax.compat.thresholds import ETA_KEY, LAMBDA_KEY
from elicit_jax.compat.trust import Verdict


def print_report(header: dict[str, Any], console: Any) -> None:
    """Rich tables on ``console``: the thresholds and their quality, then rejections per
    operator."""
    from rich.table import Table

    rep = header["report"]
    t = Table(title=f"thresholds ({header['method']})")
    t.add_column("quantity")
    t.add_column("value", justify="right")
    t.add_row("lambda", f"{header[LAMBDA_KEY]:.4g}")
    t.add_row("eta", f"{header[ETA_KEY]:.4g}")
    if rep.get("balanced_accuracy") is not None:
        t.add_row("balanced accuracy", f"{rep['balanced_accuracy']:.3f}")
    if "margin_steps" in rep:
        quantile = rep.get("margin_quantile", rep.get("margin"))
        t.add_row("margin (grid steps / quantile)", f"{rep['margin_steps']} / {quantile:.3f}")
    for key, label in (("lambda_range", "lambda"), ("eta_range", "eta")):
        if rep.get(key):
            lo, hi = rep[key]
            t.add_row(f"{label} range in margin", f"{lo:.4g} .. {hi:.4g}")
    if "loo_accuracy" in rep:
        loo = rep["loo_accuracy"]
        t.add_row(
            "leave-one-out accuracy",
            "n/a (one demo per set)" if loo is None else f"{loo:.3f} ({rep['n_loo']} held out)",
        )
    if rep.get("in_sample_accuracy") is not None:
        t.add_row("in-sample accuracy of those demos", f"{rep['in_sample_accuracy']:.3f}")
    check = rep.get("training_check") or {}
    if check.get("demos"):
        t.add_row(
            "scoring policy's training demos rejected",  # short: fits 80 columns
            f"{check['rejected']} / {check['demos']} ({check['source']})",
        )
    if "n_compatible" in rep:
        t.add_row(
            "contrast demos (compatible / incompatible)",
            f"{rep['n_compatible']} / {rep['n_incompatible']}",
        )
    console.print(t)
    ops = Table(title="rejections under these thresholds")
    for col in ("operator", "pairs", "incompatible pairs", "episodes", "rejected episodes"):
        ops.add_column(col, justify="left" if col == "operator" else "right")
    for op, r in rep.get("per_operator", {}).items():
        share = 100 * r["incompatible_pairs"] / max(r["pairs"], 1)
        ops.add_row(
            op,
            str(r["pairs"]),
            f"{r['incompatible_pairs']} ({share:.1f}%)",
            str(r["episodes"]),
            str(r["rejected_episodes"]),
        )
    console.print(ops)
    print_trust(rep, console)


def print_trust(report: dict[str, Any], console: Any) -> None:
    """The contrast decisions (with source names) and the trust verdict, loudly when bad."""
    from rich.panel import Panel
    from rich.table import Table

    contrast = report.get("contrast", [])
    if 0 < len(contrast) <= 30:
        t = Table(title="contrast demonstrations")
        for col in ("episode", "source episode", "set", "incompatible %", "decision"):
            t.add_column(col, justify="left" if col in ("set", "decision") else "right")
        for c in contrast:
            ok = c["rejected"] != c["compatible"]
            t.add_row(
                str(c["episode"]),
                str(c.get("source_episode", "-")),
                "compatible" if c["compatible"] else "incompatible",
                f"{100 * c['fraction_incompatible']:.1f}",
                ("rejected" if c["rejected"] else "accepted") + ("" if ok else " (wrong)"),
            )
        console.print(t)
    if not report.get("trust"):
        return
    verdict = Verdict.from_dict(report["trust"])
    unchecked = "\n".join(f"• not checked: {u}" for u in verdict.unchecked)
    if verdict.trustworthy:
        console.print(
            "[green]trust: no problems found[/] (margin, held-out check, pair counts, operators, "
            "the scoring policy's training demos (D_base))" + ("" if verdict.clean else ", but:")
        )
        if unchecked:
            console.print(f"[yellow]{unchecked}[/]")
        return
    forced = " (written because of --force)" if verdict.forced else ""
    body = "\n".join([*(f"• {p}" for p in verdict.problems), unchecked]).strip()
    console.print(
        Panel(body, title=f"[bold]this fit is {verdict.headline()}{forced}", border_style="red")
    )


@contextmanager
def scoring_bar(total: int) -> Iterator[Callable[[int], None]]:
    """A "scoring pairs" progress bar over ``total`` pairs, yielding ``advance(n)``."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    bar = Progress("[bold]scoring pairs", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    bar.start()
    try:
        task = bar.add_task("score", total=total)
        yield lambda n: bar.advance(task, n)
    finally:
        bar.stop()
