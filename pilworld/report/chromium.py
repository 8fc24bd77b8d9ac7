"""Headless Chromium, driven directly from its command line: screenshots and the DOM after scripts ran.

Used to check that pages we generate (``report.html``, later the judge UI) render in a real browser,
without Playwright or a browser download: the system's ``chromium`` (Debian package, installed by
``scripts/install-chromium.sh``), Chrome, or whatever ``PILWORLD_CHROMIUM`` names. Every run gets a fresh
profile folder and all of Chromium's background networking switched off, so nothing leaves the machine.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

ENV_VAR = "PILWORLD_CHROMIUM"
NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")
OFFLINE_FLAGS = (
    "--headless",
    "--no-sandbox",  # containers and CI run as root, where the sandbox cannot start
    "--disable-gpu",
    "--disable-dev-shm-usage",  # small /dev/shm in containers
    "--disable-quic",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--mute-audio",
    "--hide-scrollbars",
)


class ChromiumError(RuntimeError):
    """Chromium could not be found, timed out, or failed; the message says which."""


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


def _run(args: list[str], timeout: float) -> subprocess.CompletedProcess[bytes]:
    binary = find_chromium()
    if binary is None:
        raise ChromiumError(
            f"no Chromium found (tried ${ENV_VAR}, {', '.join(NAMES)}); run scripts/install-chromium.sh"
        )
    with tempfile.TemporaryDirectory(prefix="pilworld-chromium-") as profile:
        cmd = [binary, *OFFLINE_FLAGS, f"--user-data-dir={profile}", *args]
        # Own process group, so a hung browser and its helper processes can be ended together.
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            raise ChromiumError(f"Chromium did not finish within {timeout:.0f} s: {' '.join(cmd[:2])} …") from None
    if proc.returncode != 0:
        tail = err.decode(errors="replace").strip().splitlines()[-5:]
        raise ChromiumError(f"Chromium exited with {proc.returncode}: {' | '.join(tail)}")
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def _url(page: str | Path) -> str:
    text = str(page)
    return text if text.startswith(("file:", "data:", "about:")) else Path(page).resolve().as_uri()


def screenshot(
    page: str | Path,
    png: str | Path,
    *,
    size: tuple[int, int] = (1280, 1600),
    budget_ms: int = 3000,
    timeout: float = 120.0,
) -> Path:
    """Render ``page`` (a file or URL) at ``size`` (width, height) and write a PNG screenshot of the viewport.

    ``budget_ms`` of virtual time lets scripts run and media load before the capture.
    """
    png = Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    png.unlink(missing_ok=True)
    _run(
        [
            f"--screenshot={png}",
            f"--window-size={size[0]},{size[1]}",
            f"--virtual-time-budget={budget_ms}",
            _url(page),
        ],
        timeout,
    )
    if not png.is_file():
        raise ChromiumError(f"Chromium exited without writing {png}")
    return png


def dump_dom(page: str | Path, *, budget_ms: int = 5000, timeout: float = 120.0) -> str:
    """The serialised DOM of ``page`` after its scripts ran for ``budget_ms`` of virtual time."""
    result = _run([f"--virtual-time-budget={budget_ms}", "--dump-dom", _url(page)], timeout)
    return result.stdout.decode("utf-8", errors="replace")
