"""demo: the whole of vrecho on one scene, and its meshcat walkthrough (``vrecho demo``).

- :func:`run` (run.py): the simulated capture walk, the scan and its repair with EchoCNN, the
  sources heard, separated and placed, the headset call on walks toward each surface, the USD
  export, the figures, a table of every decision against the truth, and the walkthrough page.
- walkthrough.py: the meshcat scene of a run and its self-contained page.
- browser.py: headless Chromium, for the page's screenshot.
"""

from .run import DemoRun, run

__all__ = ["DemoRun", "run"]
