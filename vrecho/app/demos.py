"""``vrecho demo``: the whole of vrecho on one scene, as a meshcat walkthrough (:mod:`demo`)."""

from __future__ import annotations

from pathlib import Path

import demo as walkthrough_demo


def demo(out: str | Path = "vrecho-out", *, scene=None, html=None, browser: bool = True, seed: int = 0,
         serve: bool = False, progress: bool = True):
    """``vrecho demo``: :func:`demo.run` on the built-in living room (or ``scene``, a scene JSON file)."""
    return walkthrough_demo.run(out, scene=scene, html=html, browser=browser, seed=seed, serve=serve, progress=progress)
