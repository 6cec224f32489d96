"""Headless Chromium (Debian's ``chromium`` package): a screenshot of a page, and opening the
walkthrough in the user's own browser."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import webbrowser
from pathlib import Path

from vrecho.errors import VrechoError

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
# NOTES.md: meshcat's WebGL renders in headless Chromium through SwiftShader.
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--disable-quic", "--no-first-run", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", "--hide-scrollbars", "--mute-audio")


def chromium() -> str | None:
    """The path of a Chromium (or Chrome) on this machine, or None.

    Returns
    -------
    str or None
        The first of :data:`CHROMIUM_NAMES` found on ``PATH``.
    """
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


def screenshot(page: str | Path, png: str | Path, *, size: tuple[int, int] = (1280, 800), budget_ms: int = 8000,
               timeout_s: float = 120.0) -> Path:
    """Open ``page`` (an HTML file) in headless Chromium and save what it shows to ``png``.

    ``budget_ms``: Chromium's virtual time for the page to load and draw before the picture.
    Raises :class:`VrechoError` when no Chromium is installed or it fails.

    Parameters
    ----------
    page : str or path
        The HTML file.
    png : str or path
        The picture to write.
    size : tuple of int
        The window's width and height in pixels (default 1280 x 800).
    budget_ms : int
        Virtual time in milliseconds (default 8000).
    timeout_s : float
        Wall-clock limit in seconds for Chromium (default 120).

    Returns
    -------
    pathlib.Path
        ``png``, resolved.

    Raises
    ------
    VrechoError
        When no Chromium is installed, ``page`` is not a file, or Chromium fails or runs past
        ``timeout_s``.
    """
    exe = chromium()
    if exe is None:
        raise VrechoError("screenshot: no Chromium found (Debian: apt-get install chromium)")
    page, png = Path(page).resolve(), Path(png).resolve()
    if not page.is_file():
        raise VrechoError(f"screenshot: no page at {page}")
    with tempfile.TemporaryDirectory(prefix="vrecho-chromium-") as profile:
        cmd = [exe, *FLAGS, f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}",
               f"--virtual-time-budget={budget_ms}", f"--screenshot={png}", page.as_uri()]
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise VrechoError(f"screenshot: Chromium did not finish within {timeout_s:.0f} s") from None
    if r.returncode != 0 or not png.is_file():
        last = (r.stderr.strip().splitlines() or ["no message"])[-1]
        raise VrechoError(f"screenshot: Chromium failed (exit {r.returncode}): {last}")
    return png


def open_in_browser(page: str | Path) -> bool:
    """Open ``page`` in the user's browser when there is a display; False when none could be.

    Parameters
    ----------
    page : str or path
        The HTML file.

    Returns
    -------
    bool
        Whether a browser was opened.
    """
    if os.name == "posix" and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) \
            and not shutil.which("open"):  # no display (macOS has `open`)
        return False
    try:
        return webbrowser.open(Path(page).resolve().as_uri())
    except webbrowser.Error:
        return False
