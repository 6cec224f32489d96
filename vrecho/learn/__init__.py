"""Learning: datasets, training and evaluation of every model vrecho ships.

- datasets.py: ``vrecho generate``'s datasets (rooms simulated in parallel, Zarr arrays, labels,
  splits by room) and :class:`~.datasets.Dataset` to read them;
- devices.py: echo frames of other devices of the operating envelope (``vrecho generate --preset
  devices``), for EchoCNN-E's training (``vrecho train --devices``) and a test set of every
  condition (``vrecho evaluate --devices``);
- train.py: targets, losses and the resumable training loop (:func:`~.train.fit`);
- evaluate.py: the paper's methods and baselines trained and judged side by side (``vrecho train``,
  ``vrecho evaluate``), and the classifier's weights bundled; report.py: their tables and figures;
- cluster.py: generation and training on a Ray cluster (``--ray``; Ray is an extra);
- headset_view.py, masknet.py: the headset view's glass/mirror model and localization's mask
  network, each trained again by ``python3 -m vrecho.learn.<name>``.

Learning draws its data from the simulator (:mod:`vrecho.sim`); the models it trains live with the
method (:mod:`vrecho.models`, :mod:`vrecho.headset.view`, :mod:`localization.masknet`). Nothing
here is imported by the method, and the modules that train import torch when imported.
"""
