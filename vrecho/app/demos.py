"""``vrecho demo``: the whole of vrecho on one scene, as a meshcat walkthrough (:mod:`demo`)."""

from __future__ import annotations

from pathlib import Path

import demo as walkthrough_demo


def demo(out: str | Path = "vrecho-out", *, scene=None, html=None, browser: bool = True, seed: int = 0,
         serve: bool = False, force: bool = False, progress: bool = True):
    """``vrecho demo``: :func:`demo.run` on the built-in living room (or ``scene``, a scene JSON file).

    Parameters
    ----------
    out : str or path
        Output folder (default ``vrecho-out``).
    scene : str or path, optional
        A scene JSON file instead of the built-in living room.
    html : str or path, optional
        The walkthrough page (default ``out/walkthrough.html``).
    browser : bool
        Open the page in a browser where there is a display.
    seed : int
        Seed of the simulated recordings.
    serve : bool
        Also show the walkthrough on a live meshcat server until Ctrl-C.
    force : bool
        Write into a folder holding files the demo did not write.
    progress : bool
        Progress bars and step lines.

    Returns
    -------
    demo.DemoRun
        The decisions against the truth, the files written and each step's time.

    Raises
    ------
    VrechoError
        For a bad scene file, a scene with nothing to repair, an ``html`` path that is not a
        .html file, or an output folder that cannot be written.
    """
    return walkthrough_demo.run(out, scene=scene, html=html, browser=browser, seed=seed, serve=serve, force=force,
                                progress=progress)
