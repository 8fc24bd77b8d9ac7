"""Headless Chromium for the tests, driven by Playwright, waiting on conditions instead of time budgets.

Every wait polls a JavaScript condition against a real-time deadline (``page.evaluate``: the annotation
app's CSP forbids the ``eval`` that ``wait_for_function`` needs). Nothing here depends on how fast the
machine is: a loaded machine only makes the waits longer, and the deadline (``PILWORLD_BROWSER_TIMEOUT``
seconds, default 120) is there to end a page that never gets there, not to measure it.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from playwright.sync_api import Browser, Page, sync_playwright

from pilworld.report.chromium import find_chromium

TIMEOUT_ENV = "PILWORLD_BROWSER_TIMEOUT"
POLL_S = 0.03


def deadline_s() -> float:
    """The real-time limit of one wait, from ``$PILWORLD_BROWSER_TIMEOUT`` (seconds), default 120."""
    raw = os.environ.get(TIMEOUT_ENV, "").strip()
    if not raw:
        return 120.0
    try:
        value = float(raw)
    except ValueError:
        raise ValueError(f"${TIMEOUT_ENV}: expected seconds, got {raw!r}") from None
    if value <= 0:
        raise ValueError(f"${TIMEOUT_ENV}: expected a positive number of seconds, got {raw!r}")
    return value


@contextmanager
def chromium() -> Iterator[Browser]:
    """The system's Chromium (``find_chromium``; never a downloaded browser), closed on exit."""
    binary = find_chromium()
    if binary is None:
        raise RuntimeError("no Chromium found; run scripts/install-chromium.sh or set PILWORLD_CHROMIUM")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=binary, args=["--no-sandbox", "--disable-gpu"])
        try:
            yield browser
        finally:
            browser.close()


def wait_for(page: Page, expression: str, what: str, timeout: float | None = None) -> Any:
    """Poll the JS ``expression`` until it is truthy and return its value; AssertionError after ``timeout``."""
    limit = deadline_s() if timeout is None else timeout
    deadline = time.monotonic() + limit
    while True:
        value = page.evaluate(expression)
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {limit:.0f} s waiting for {what} ({expression})")
        time.sleep(POLL_S)
