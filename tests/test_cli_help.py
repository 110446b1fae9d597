"""Command help reads as paragraphs: a docstring hard-wrapped in the source is not shown
broken mid-sentence (the help formatter keeps single line breaks)."""

import re

from typer.testing import CliRunner

from elicit_jax.cli import app
from elicit_jax.cli.app import unwrap_help


def test_unwrap_joins_lines_of_a_paragraph_and_keeps_the_rest_apart():
    text = """First line
    of a sentence.

    Examples:
    elicit-jax a --x 1
    --y 2
    elicit-jax b

    - one item
    - another
    """
    assert unwrap_help(text) == (
        "First line of a sentence.\n\n"
        "Examples:\nelicit-jax a --x 1 --y 2\nelicit-jax b\n\n"
        "- one item\n- another"
    )


def test_filter_help_shows_a_wrapped_sentence_on_one_line():
    result = CliRunner().invoke(app, ["filter", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    text = re.sub(r"[ \u2502]+", " ", result.output)
    assert "Dropped rows and reasons go to OUT.dropped.parquet." in text
    example = "Example: elicit-jax filter --method deminf --demos new.parquet --base base.parquet"
    assert example in text
