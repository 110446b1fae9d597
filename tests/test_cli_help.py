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


def _commands(group, prefix=()):
    import typer.main

    cmd = typer.main.get_command(group) if not hasattr(group, "commands") else group
    for name, sub in cmd.commands.items():
        if hasattr(sub, "commands"):
            yield from _commands(sub, (*prefix, name))
        else:
            yield (*prefix, name), sub


def test_every_seed_option_is_validated_the_same_way():
    from elicit_jax.cli.app import check_seed

    seeded = [
        " ".join(path)
        for path, cmd in _commands(app)
        for p in cmd.params
        if "--seed" in getattr(p, "opts", ())
    ]
    assert {"collect", "score", "filter", "evaluate", "elicit", "serve"} <= set(seeded)
    seed_flags = {"--seed", "--dropout-seed"}  # --policy-seed names a run's seed directory
    for path, cmd in _commands(app):
        for p in cmd.params:
            if seed_flags & set(getattr(p, "opts", ())):
                callback = getattr(p.callback, "__wrapped__", p.callback)
                assert callback is check_seed, " ".join(path)


def test_a_negative_seed_and_a_port_out_of_range_are_one_line_errors(tmp_path):
    from elicit_jax.errors import ElicitError

    out = tmp_path / "x.parquet"
    for args in (
        ["collect", "--task", "reach-pillar", "--seed", "-1", "-o", out],
        ["make-example", "--seed", "-1", "-o", tmp_path / "x.hdf5"],
        ["train", "--demos", tmp_path / "d.parquet", "--out", tmp_path / "r", "--seeds", "0,-1"],
        ["review", tmp_path / "d.parquet", "--port", "70000"],
        ["score", "--policy", tmp_path, "--demos", out, "-o", out, "--dropout-seed", "-1"],
    ):
        r = CliRunner().invoke(app, [str(a) for a in args])
        assert isinstance(r.exception, ElicitError), (args, r.output, r.exception)
        assert "-1" in str(r.exception) or "70000" in str(r.exception)
    assert not list(tmp_path.iterdir())


def test_brackets_in_help_are_shown_not_taken_for_markup():
    """ "Run directory [runs/<name>-<profile>]." was shown as "Run directory ." (Rich took the
    default in brackets for a style tag); every bracketed text of an option's help shows."""
    checked = 0
    for path, cmd in _commands(app):
        wanted = [
            m
            for p in cmd.params
            for m in re.findall(r"\[[^\]]*\]", getattr(p, "help", None) or "")
            if not m.startswith("\\")
        ]
        if not wanted:
            continue
        out = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "250"}).output
        text = re.sub(r"[ \u2502]+", " ", out)
        for m in wanted:
            assert re.sub(r"\s+", " ", m) in text, (" ".join(path), m)
        checked += 1
    assert checked >= 3
