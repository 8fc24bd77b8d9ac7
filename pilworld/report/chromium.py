"""Finding the system's Chromium, for checking in a real browser that the pages we generate render.

The report's and the annotation app's browser tests drive it through Playwright (``tests/pilworld/browser.py``)
and wait on page conditions, never on a time budget: the former ``--virtual-time-budget`` command-line
driver failed on a loaded machine, where media decode in real time while virtual time runs out. The binary
is the system's ``chromium`` (Debian package, installed by ``scripts/install-chromium.sh``), Chrome, or
whatever ``PILWORLD_CHROMIUM`` names; no browser is ever downloaded.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

ENV_VAR = "PILWORLD_CHROMIUM"
NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")


def find_chromium() -> str | None:
    """Path of a Chromium/Chrome binary: ``$PILWORLD_CHROMIUM`` if set, else the first of :data:`NAMES` on PATH."""
    env = os.environ.get(ENV_VAR, "").strip()
    if env:
        return env if Path(env).is_file() and os.access(env, os.X_OK) else shutil.which(env)
    for name in NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None
