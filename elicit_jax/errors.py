"""The one exception type users see: a single line naming the file and what is wrong."""

from __future__ import annotations

from pathlib import Path


class ElicitError(Exception):
    """A user-facing error: bad input, a mismatched checkpoint, a missing key.

    The CLI prints ``str(error)`` as one line and exits non-zero (no traceback unless
    ``--debug``).
    """

    def __init__(self, message: str, path: str | Path | None = None) -> None:
        self.path = None if path is None else str(path)
        text = " ".join(str(message).split())
        super().__init__(f"{self.path}: {text}" if self.path else text)
