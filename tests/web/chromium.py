"""Where Debian's Chromium is and how the browser tests start it (shared by every browser test)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

CHROMIUM_NAMES = ("chromium", "chromium-browser")
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader",
]


def find_chromium() -> str | None:
    """$ELICIT_JAX_CHROMIUM if set (it must exist), else `chromium` / `chromium-browser`."""
    given = os.environ.get("ELICIT_JAX_CHROMIUM")
    if given:
        return given if Path(given).is_file() else None
    return next(filter(None, map(shutil.which, CHROMIUM_NAMES)), None)


def page_with_errors(browser: Any, viewport: dict | None = None) -> tuple[Any, list[str]]:
    """A new page of ``browser`` (at ``viewport`` if given) and the list its uncaught
    JavaScript errors are appended to (tests assert it stays empty)."""
    page = browser.new_page(viewport=viewport) if viewport else browser.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    return page, errors


def sign_in(page: Any, url: str, name: str) -> None:
    """Open the operator page at ``url`` and type ``name`` into its name field, as a person
    does (click, keys, Enter)."""
    page.goto(url)
    page.wait_for_selector("#name")
    page.click("#name")
    page.keyboard.type(name)
    page.keyboard.press("Enter")
