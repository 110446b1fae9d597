"""An elicitation study's report (:data:`LAYOUT`): its tables, figures and intro, for the one
report path of every study kind (:func:`elicit_jax.pipeline.report_folder.write_report`: the
filtering report's Markdown and self-contained HTML page, figures inlined as base64 PNG, no
external asset).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.pipeline.elicitation.evidence import study_to_json
from elicit_jax.pipeline.elicitation.gather import StudyData
from elicit_jax.pipeline.elicitation.success import (
    CONDITION_LABELS,
    cells_of,
    diff_text,
    study_differences,
)
from elicit_jax.pipeline.elicitation.tables import (
    ablation_table,
    ablation_tests,
    dagger_table,
    filter_table,
    learning_curves,
    learning_table,
    length_table,
    person_table,
    table2,
    table2_tests,
    threshold_table,
)
from elicit_jax.pipeline.evidence import selection_lines
from elicit_jax.pipeline.report_folder import ReportLayout, intro_lines
from elicit_jax.pipeline.tables import STD_NOTE
from elicit_jax.render import FigureRenderer, html_figure
from elicit_jax.stats import significant

FIGURES = "figures"
INTERVAL_NOTE = (
    "Differences are in success points, paired by person: each person's mean over training "
    "seeds in one condition minus the other, with a 95% Student t interval over people. A "
    "difference from Base is each person's mean against the base policy's mean, Welch's t "
    "over the people and the base policy's seeds. Each table's differences are a family: "
    "their p-values are Holm-adjusted together (the adjusted p-value is printed beside each "
    "interval) and `*` marks only an adjusted p-value below 0.05. Without `*`, the difference "
    "is inside the noise of this many people, seeds and tests."
)
MODEL_NOTE = (
    "The people are simulated (docs/people.md): the task's phase machine driven by each "
    "person's own parameters and motor traits, changed only by fitting what the interface "
    "shows (and, in every mode, by trials judged by their own success). What they learn, "
    "and how fast, is a consequence of that model, not a measurement of human operators."
)


def _verdicts(data: StudyData) -> list[str]:
    out = []
    for task, model, a, b, d, adjusted in study_differences(data):
        if d is None:
            continue
        real = significant(d.excludes_zero, adjusted)
        out.append(
            f"**{task}** ({model}): {CONDITION_LABELS[a]} − {CONDITION_LABELS[b]}, "
            f"{d.n} people, in points: {diff_text(d, adjusted)} — "
            + (
                "beyond the noise, after adjusting for the table's other differences."
                if real
                else "inside the noise once the table's other differences are counted "
                "(not a demonstrated effect)."
                if d.excludes_zero
                else "inside the noise (not a demonstrated effect)."
            )
        )
    return out


def _figure(data: StudyData, task: str, model: str) -> bytes | None:
    from matplotlib.figure import Figure

    from elicit_jax.render import figure_png

    curves = learning_curves(data, task, model)
    if not curves:
        return None
    fig = Figure(figsize=(9, 3.6))
    left, right = fig.subplots(1, 2)
    for cond, curve in curves.items():
        x = np.arange(1, len(curve) + 1)
        left.plot(x, 100 * curve[:, 0], marker="o", ms=3, label=CONDITION_LABELS[cond])
        right.plot(x, 100 * curve[:, 1], marker="o", ms=3, label=CONDITION_LABELS[cond])
    left.set_ylabel("incompatible pairs (%)")
    right.set_ylabel("rule accepts (%)")
    for ax in (left, right):
        ax.set_xlabel("demonstration attempt")
    left.legend(fontsize=7)
    fig.suptitle(f"{task} ({model}): mean over the population, by attempt", fontsize=10)
    fig.tight_layout()
    return figure_png(fig)


def _sections(data: StudyData, folder: Path) -> list[tuple[str, Any]]:
    title = (
        "Base / Naive / Naive + M-filtered / Informed (success %, mean (std) over seeds; "
        f"differences Holm-adjusted over the {table2_tests(data)} of this table)"
    )
    blocks: list[tuple[str, Any]] = [(title, table2(data))]
    for task, model in cells_of(data):
        where = f"{task} ({model})"
        blocks.append((f"{where}: per person", person_table(data, task, model)))
        abl = ablation_table(data, task, model)
        if abl[1]:
            blocks.append(
                (
                    f"{where}: which part of the interface does the work (vs Naive "
                    f"Holm-adjusted over the {ablation_tests(data, task, model)} of its column)",
                    abl,
                )
            )
        learning = learning_table(data, task, model)
        blocks.append((f"{where}: do the people learn, and how fast?", learning))
        name = f"{task}-{model}-learning.png"
        if (folder / FIGURES / name).is_file():
            blocks.append((f"{where}: learning curves", [("figure", name)]))
    blocks.append(("Demonstration lengths: accepted demonstrations against D_base",
                   length_table(data)))  # fmt: skip
    dagger = dagger_table(data)
    if dagger[1]:
        blocks.append(("HG-DAgger: interventions", dagger))
    if data.filters:
        blocks.append(("What the M-filter kept of each naive session", filter_table(data)))
    if data.thresholds:
        blocks.append(("Thresholds (every session and the M-filter)", threshold_table(data)))
    return blocks


def _intro(data: StudyData) -> list[str]:
    lines = intro_lines(data, "Study")
    lines += [MODEL_NOTE, *selection_lines(data.results), INTERVAL_NOTE, STD_NOTE]
    return [*lines, *_verdicts(data), *data.notes]


def summary_tables(data: StudyData) -> list[tuple[str, Any]]:
    """The tables a finished study prints: Table 2 and, per task × model, its ablation."""
    tables = [("Base / Naive / Naive + M-filtered / Informed (success %)", table2(data))]
    return tables + [
        (f"{t} ({m}): ablation", ablation_table(data, t, m)) for t, m in cells_of(data)
    ]


def _draw(folder: Path, data: StudyData) -> tuple[StudyData, list[str]]:
    """Draw each cell's learning curves into ``folder/figures``."""
    (folder / FIGURES).mkdir()
    drawn = []
    for task, model in cells_of(data):
        png = _figure(data, task, model)
        if png is not None:
            name = f"{task}-{model}-learning.png"
            (folder / FIGURES / name).write_bytes(png)
            drawn.append(f"{FIGURES}/{name}")
    return data, drawn


def _figures(folder: Path) -> tuple[FigureRenderer, FigureRenderer]:
    """Learning curves: linked under ``figures/`` in Markdown, inlined from the folder being
    written in HTML."""

    def markdown(title: str, item: tuple[str, str]) -> list[str]:
        return [f"![{title}]({FIGURES}/{item[1]})", ""]

    def page(title: str, item: tuple[str, str]) -> list[str]:
        return [html_figure((folder / FIGURES / item[1]).read_bytes(), title)]

    return markdown, page


LAYOUT = ReportLayout(
    kind="study-report",
    title="elicit-jax study",
    definition="Study definition",
    notes=(MODEL_NOTE,),
    intro=_intro,
    sections=_sections,
    draw=_draw,
    figures=_figures,
    to_json=study_to_json,
    fields=lambda data: {"n_sessions": len(data.sessions)},
)
"""An elicitation study's report, for :func:`~elicit_jax.pipeline.report_folder.write_report`:
Table 2, per cell its people, ablation and learning (with its curves), the demonstration
lengths, HG-DAgger's interventions, the M-filter's counts and the thresholds."""
