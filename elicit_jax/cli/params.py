"""From a command's parsed flags to its frozen config.

Two helpers keep the commands thin: :func:`with_flags` adds a set of flags declared once
(e.g. ``import``'s, which ``watch`` shares) to a command's parameters, and
:func:`from_params` builds a config dataclass from the parameters named like its fields.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

Command = TypeVar("Command", bound=Callable[..., Any])
Config = TypeVar("Config")


def with_flags(
    flags: Sequence[tuple[str, type, Any]], before: str | None = None
) -> Callable[[Command], Command]:
    """Add ``flags`` to a command's parameters (before the parameter ``before``, else last).

    The flags are declared once instead of in each command's signature; the command takes
    them as ``**flags`` and reads them from ``ctx.params``.

    Args:
      flags: (parameter name, type, ``typer.Option``) of each flag.
      before: the command's parameter to place them before (None: after the last).

    Returns:
      A decorator that sets the command's signature, which Typer reads.
    """

    def add(command: Command) -> Command:
        own = [
            p.replace(kind=inspect.Parameter.KEYWORD_ONLY)
            for p in inspect.signature(command).parameters.values()
            if p.kind is not inspect.Parameter.VAR_KEYWORD
        ]
        extra = [
            inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=opt, annotation=kind)
            for name, kind, opt in flags
        ]
        at = len(own) if before is None else [p.name for p in own].index(before)
        signature = inspect.Signature([*own[:at], *extra, *own[at:]])
        command.__signature__ = signature  # type: ignore[attr-defined]
        return command

    return add


def field_params(cls: type, params: Mapping[str, Any]) -> dict[str, Any]:
    """The parameters of a command (``ctx.params``) named like a field of the dataclass
    ``cls``."""
    names = {f.name for f in dataclasses.fields(cls)}
    return {k: v for k, v in params.items() if k in names}


def from_params(cls: type[Config], params: Mapping[str, Any], **values: Any) -> Config:
    """A config dataclass from a command's parameters.

    Args:
      cls: the config class (a dataclass).
      params: the command's parameters (``ctx.params``); those named like a field fill it.
      **values: fields given otherwise (converted, resolved); they take precedence.

    Returns:
      The config; fields neither names keep their defaults.
    """
    return cls(**(field_params(cls, params) | values))
