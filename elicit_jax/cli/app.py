"""The Typer application, its global options and the entry point's error handling.

Command modules register on :data:`app`; they import JAX, MuJoCo and friends lazily,
inside the commands, so that ``elicit-jax --help`` starts fast.
"""

from __future__ import annotations

import inspect
import sys
from typing import Any

import typer
from typer.core import TyperGroup

from elicit_jax.errors import ElicitError

# Help panels, in the order of the workflow; each command names its panel when it registers.
DATA = "1. Bring demonstrations"
POLICY = "2. Base policy"
COMPAT = "3. Compatibility"
HAND_BACK = "4. Hand back and evaluate"
ELICIT = "5. Elicit demonstrations"
PIPELINES = "Pipelines"
INSPECT = "Inspect"
COMMAND_ORDER = (
    "import",
    "make-example",
    "collect",
    "demos",
    "train",
    "score",
    "fit-thresholds",
    "filter",
    "quality",
    "map",
    "export",
    "evaluate",
    "elicit",
    "watch",
    "serve",
    "review",
    "quickstart",
    "pipeline",
    "report",
    "info",
    "tasks",
)


def check_seed(param: typer.CallbackParam, value: int | None) -> int | None:
    """Callback of every seed option (``--seed``, ``--dropout-seed``): a seed is an integer
    >= 0 in every command (numpy's generators refuse negative ones, JAX's would take them)."""
    if value is not None and value < 0:
        raise ElicitError(f"{param.opts[0]} must be an integer >= 0, got {value}")
    return value


def repeated_options(command: Any, args: list[str]) -> list[tuple[str, int]]:
    """Single-valued options of ``command`` that ``args`` give more than once, as
    ``(option, times)``: Click would silently keep the last value."""
    owner: dict[str, str] = {}
    for p in command.params:
        if getattr(p, "param_type_name", "") == "option" and not (p.multiple or p.count):
            for opt in (*p.opts, *p.secondary_opts):
                owner[opt] = p.name
    seen: dict[str, list[str]] = {}
    for a in args:
        if a == "--":
            break
        key = a.split("=", 1)[0] if a.startswith("--") else a
        if key in owner:
            seen.setdefault(owner[key], []).append(key)
    return [(used[0], len(used)) for used in seen.values() if len(used) > 1]


def unwrap_help(text: str) -> str:
    """A docstring's paragraphs each on one line: the help formatter keeps single line breaks,
    so a docstring wrapped at 96 columns came out broken mid-sentence at 80. Paragraphs
    (blank-line separated), lines starting with ``-``, ``*`` or ``elicit-jax`` (one example per
    line) and paragraphs starting with ``\\b`` stay apart."""
    paragraphs = []
    for para in inspect.cleandoc(text).split("\n\n"):
        lines = para.splitlines()
        if lines and lines[0].startswith("\b"):
            paragraphs.append(para)
            continue
        out: list[str] = []
        for line in lines:
            if out and not line.lstrip().startswith(("- ", "* ", "elicit-jax ")):
                out[-1] = f"{out[-1]} {line.strip()}"
            else:
                out.append(line.rstrip())
        paragraphs.append("\n".join(out))
    return "\n\n".join(paragraphs)


def _literal_help(command: Any) -> None:
    """Unwrap the command's help and escape what Rich would take for markup in it and in its
    options' help: ``[runs/<name>-<profile>]`` (a default in brackets) was swallowed as a
    tag, leaving "Run directory ."."""
    from rich.markup import escape

    if command.help:
        command.help = escape(unwrap_help(command.help))
    for param in getattr(command, "params", ()):
        if getattr(param, "help", None):
            param.help = escape(param.help)
    command._help_ready = True


class OrderedGroup(TyperGroup):
    """A command group that lists commands in workflow order, shows each command's help
    unwrapped (:func:`unwrap_help`) and literally (no Rich markup), and refuses an option
    given twice (e.g. ``--scores a --scores b``) instead of silently keeping the last one."""

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        command = super().get_command(ctx, cmd_name)
        if command is not None and not getattr(command, "_help_ready", False):
            _literal_help(command)
        return command

    def list_commands(self, ctx: Any) -> list[str]:
        rank = {n: i for i, n in enumerate(COMMAND_ORDER)}
        return sorted(super().list_commands(ctx), key=lambda n: rank.get(n, len(rank)))

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        name = next((a for a in args if not a.startswith("-")), None)
        command = self.get_command(ctx, name) if name else None
        if command is not None and not hasattr(command, "commands"):
            for opt, times in repeated_options(command, args[args.index(name) + 1 :]):
                raise typer.BadParameter(
                    f"given {times} times; give it once (only the last would count)",
                    ctx=ctx,
                    param_hint=f"'{opt}' of '{name}'",
                )
        return super().parse_args(ctx, args)


app = typer.Typer(
    name="elicit-jax",
    cls=OrderedGroup,
    help=(
        "Measure and elicit demonstrations compatible with a base policy.\n\n"
        "Stages pass Parquet artifacts: import/collect -> train -> score -> fit-thresholds "
        "-> filter -> train -> evaluate; elicit and watch judge demonstrations as they are "
        "recorded. Run any command with --help for an example."
    ),
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def command_group(name: str, help: str, panel: str) -> typer.Typer:
    """A group of subcommands (``elicit-jax NAME ...``) registered on :data:`app`."""
    group = typer.Typer(help=help, no_args_is_help=True, cls=OrderedGroup)
    app.add_typer(group, name=name, rich_help_panel=panel)
    return group


_state: dict = {"debug": False, "log": None}


@app.callback()
def _root(
    debug: bool = typer.Option(
        False, "--debug", help="Show full tracebacks on errors, and log records on stderr."
    ),
) -> None:
    _state["debug"] = debug


def _steps_mjx(argv: list[str]) -> bool:
    """The command line asks for the MJX backend (``--backend mjx`` or ``--backend=mjx``):
    XLA's CPU pool must then be sized for MJX before JAX starts (see
    :func:`elicit_jax.runtime.check_mjx_threads`)."""
    pairs = zip(argv, [*argv[1:], ""], strict=True)
    if any(a == "--backend=mjx" or (a == "--backend" and b == "mjx") for a, b in pairs):
        return True
    return _definition_steps_mjx(argv)


def _definition_steps_mjx(argv: list[str]) -> bool:
    """``pipeline run DEFINITION`` where the definition evaluates with MJX (an ``evaluate``
    table with ``backend = "mjx"``, at any level). Unreadable definitions count as no: the
    command itself then reports them."""
    import tomllib

    from elicit_jax.pipeline.spec import resolve_path

    run_at = [i for i in range(len(argv) - 1) if argv[i : i + 2] == ["pipeline", "run"]]
    if not run_at:
        return False
    for arg in argv[run_at[0] + 2 :]:
        if arg.startswith("-"):
            continue
        try:
            data = tomllib.loads(resolve_path(arg).read_text())
        except (ElicitError, OSError, ValueError):
            continue
        if _evaluates_with_mjx(data):
            return True
    return False


def _evaluates_with_mjx(table: object) -> bool:
    if isinstance(table, list):
        return any(_evaluates_with_mjx(t) for t in table)
    if not isinstance(table, dict):
        return False
    evaluate = table.get("evaluate")
    if isinstance(evaluate, dict) and evaluate.get("backend") == "mjx":
        return True
    return any(_evaluates_with_mjx(v) for v in table.values())


def main() -> None:
    """Console-script entry point: set up JAX, run the app, print errors as one line."""
    from elicit_jax import cli as _commands  # noqa: F401  (registers the commands)
    from elicit_jax.runtime import configure, configure_console, configure_logging

    configure(mjx=_steps_mjx(sys.argv[1:]))
    configure_console()
    debug = "--debug" in sys.argv[1:]
    _state["log"] = configure_logging(echo=debug)
    try:
        app()
    except ElicitError as e:
        if debug:
            raise
        typer.echo(f"error: {e}", err=True)
        sys.exit(1)
    except (OSError, ValueError) as e:
        if debug:
            raise
        typer.echo(f"error: {type(e).__name__}: {e}", err=True)
        sys.exit(1)
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        sys.exit(130)


def log_path() -> str:
    """Where this run's log records go (for messages that point the user there)."""
    return str(_state["log"]) if _state["log"] is not None else "(no log file)"
