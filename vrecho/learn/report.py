"""The benchmark's report: the paper's tables (Markdown and CSV), confusion matrices and the
activation-maximisation figure, from what :func:`vrecho.learn.evaluate.evaluate` measured."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import torch  # the figure's gradient ascent: this module judges models

from ..device import MIC_ABOVE_EMITTER_M
from ..io import atomic_write_text
from ..models import CLASS_HEADS, DEPTH_BINS_M, EchoCNN
from ..signals import FS, SPEED_OF_SOUND


COLUMNS = (("open", "open/closed %"), ("material", "material %"), ("depth_ft", "depth 1/2/3 ft %"),
           ("depth_ft_closed", "closed: 1/2/3 ft %"), ("depth_bin", "depth 0.5 m %"),
           ("depth_bin_closed", "closed: 0.5 m %"), ("depth_median_cm", "depth median cm"), ("depth_p90_cm", "depth p90 cm"),
           ("src_cell", "source cell %"), ("src_median_m", "source median m"))


def _fmt(key: str, v: float) -> str:
    if v != v:  # NaN: the head does not apply
        return "-"
    if key.endswith("_cm") or key.endswith("_m"):
        return f"{v:.2f}" if key.endswith("_m") else f"{v:.1f}"
    return f"{100 * v:.1f}"


TABLES = {
    "real": ("Real-scene protocol (the paper's Table 1): depth in 1/2/3 ft classes",
             ("open", "material", "depth_ft", "depth_ft_closed", "depth_median_cm", "depth_p90_cm")),
    "synthetic": ("Synthetic protocol (the paper's Table 2): depth in 0.5 m steps (+/- 0.25 m)",
                  ("open", "material", "depth_bin", "depth_bin_closed", "depth_median_cm", "depth_p90_cm", "src_cell",
                   "src_median_m")),
}


def _devices_table(results: dict, meta: dict) -> list[str]:
    """The lines of EchoCNN-E's and EchoCNN-A's tables on other devices' frames (``vrecho evaluate --devices``)."""
    lines = []
    for name, how in (("EchoCNN-E", "the probe known"), ("EchoCNN-A", "the probe unknown, the paper's protocol")):
        judged = results.get(name, {}).get("devices")
        if not judged:
            continue
        lines += [f"## Other devices: {name} on {meta['devices']}, {how} (issue 27)", "",
                  "Each condition of the operating envelope on its own row (`vrecho.sim.devices`); without the "
                  "surface's distance (the model), and with it (`surface_m`: the truth plus a normal 2 cm, the physics; "
                  "it needs the probe). Calibration error: expected, 10 bins. Depth on closed surfaces.", "",
                  "| condition | frames | open | open/closed % | calibration error % | depth median cm | closed within 10 cm % "
                  "| with surface_m: open/closed % | calibration error % |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for c, r in judged.items():
            surface = (f"{100 * r['surface_open_acc']:.1f} | {100 * r['surface_calibration_error']:.1f}"
                       if not np.isnan(r["surface_open_acc"]) else "- | -")
            lines.append(f"| {c} | {r['frames']} | {100 * r['open_share']:.0f} % | {100 * r['open_acc']:.1f} | "
                         f"{100 * r['calibration_error']:.1f} | {r['depth_median_cm']:.1f} | {100 * r['depth_within_10cm']:.0f} | "
                         f"{surface} |")
        lines.append("")
    return lines


def write_tables(results: dict, methods, meta: dict, out: Path) -> None:
    """``tables.md`` (the two paper tables per protocol and the per-sound breakdown) and
    ``results.csv`` (every metric of every method).

    Parameters
    ----------
    results : dict of str to dict
        Per method name, its metrics with ``by_group`` (:func:`evaluate`).
    methods : list of Method
    meta : dict
        ``seed``, ``data`` and ``n`` (frames per protocol and split); ``devices``, the devices
        folder EchoCNN-E's ``devices`` results were judged on, if any.
    out : pathlib.Path
    """
    names = dict(COLUMNS)
    lines = [f"Seed {meta['seed']}; dataset {meta['data']}. Test: held-out sounds in unseen rooms (paper protocol); "
             "vrecho's probe and random broadband probes in unseen rooms (product protocol). Depth errors on closed "
             "surfaces (an opening returns no echo from its own plane).", ""]
    for protocol in ("paper", "product"):
        ms = [m for m in methods if m.protocol == protocol]
        if not ms:
            continue
        n = meta["n"][protocol]
        lines.append(f"## {protocol.capitalize()} protocol (train {n['train']}, val {n['val']}, test {n['test']} frames)")
        lines.append("")
        for title, keys in TABLES.values():
            lines += [f"### {title}", "", "| method | " + " | ".join(names[k] for k in keys) + " |",
                      "|---|" + "---:|" * len(keys)]
            for m in ms:
                r = results[m.name]
                lines.append(f"| {m.name} | " + " | ".join(_fmt(k, r[k]) for k in keys) + " |")
            lines.append("")
        groups = sorted({g for m in ms for g in results[m.name]["by_group"]})
        keys = ("open", "material", "depth_bin", "depth_median_cm")
        lines += ["### Per test sound: " + ", ".join(names[k] for k in keys), "",
                  "| sound | " + " | ".join(m.name for m in ms) + " |", "|---|" + "---:|" * len(ms)]
        for g in groups:
            cells = [" / ".join(_fmt(k, results[m.name]["by_group"].get(g, {}).get(k, float("nan"))) for k in keys)
                     for m in ms]
            lines.append(f"| {g} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += _devices_table(results, meta)
    atomic_write_text(out / "tables.md", "\n".join(lines))
    keys = [k for k in next(iter(results.values())) if k not in ("by_group", "devices")]
    with open(out / "results.csv.tmp", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["method", "protocol", "group"] + keys)
        for m in methods:
            r = results[m.name]
            w.writerow([m.name, m.protocol, "all"] + [r[k] for k in keys])
            for g, rg in r["by_group"].items():
                w.writerow([m.name, m.protocol, g] + [rg.get(k, "") for k in keys])
    (out / "results.csv.tmp").replace(out / "results.csv")


def confusion_figures(outputs: dict, methods, harness, out: Path) -> list[Path]:
    """One PNG per class head: a confusion matrix per method (rows true, columns predicted,
    normalised per true class).

    Parameters
    ----------
    outputs : dict of str to dict
        Per method name, its outputs on the test frames (class scores per head).
    methods : list of Method
    harness : Harness
    out : pathlib.Path

    Returns
    -------
    list of pathlib.Path
        ``out/confusion_<head>.png`` for each of :data:`vrecho.models.CLASS_HEADS`.
    """
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed
    from sklearn.metrics import confusion_matrix  # heavy (1.7 s to import): only this figure needs it

    labels = {"open": ("closed", "open"), "material": ("glass", "mirror"),
              "depth_bin": tuple(f"{d:g}" for d in DEPTH_BINS_M), "depth_ft": ("1 ft", "2 ft", "3 ft")}
    paths = []
    for head in CLASS_HEADS:
        n = len(methods)
        cols = min(n, 4)
        rows = (n + cols - 1) // cols
        fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.0 * rows), squeeze=False)
        for ax, m in zip(axes.flat, methods):
            y = harness.frames(m.protocol, "test").y[head]
            keep = y != -100
            k = len(labels[head])
            cm = confusion_matrix(y[keep].numpy(), outputs[m.name][head].argmax(1)[keep].numpy(), labels=range(k))
            cmn = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)
            ax.imshow(cmn, vmin=0, vmax=1, cmap="Blues")
            for i in range(k):
                for j in range(k):
                    if k <= 3 or cm[i, j]:
                        ax.text(j, i, f"{100 * cmn[i, j]:.0f}", ha="center", va="center", fontsize=7,
                                color="white" if cmn[i, j] > 0.5 else "black")
            ax.set_xticks(range(k), labels[head], fontsize=7, rotation=45 if k > 3 else 0)
            ax.set_yticks(range(k), labels[head], fontsize=7)
            ax.set_title(f"{m.name} ({m.protocol})", fontsize=8)
        for ax in list(axes.flat)[n:]:
            ax.axis("off")
        fig.suptitle(f"Confusion matrices, {head.replace('_', ' ')} (rows: truth, columns: prediction, % of row)",
                     fontsize=9)
        fig.tight_layout()
        path = out / f"confusion_{head}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def activation_maximisation(models: dict[str, EchoCNN], path, *, steps: int = 300, seed: int = 0) -> Path:
    """For each depth class of the depth head, the input that excites it most: gradient ascent on
    the class logit with an L2 pull toward a neutral input and a smoothness penalty.

    ``models`` maps a method name to its model: a log-mel model (EchoCNN-A) gets one row of
    spectrograms; an echo model (EchoCNN-E) a panel of recovered impulse-response envelopes,
    with each class's depth range marked where its echo should be.

    Parameters
    ----------
    models : dict of str to EchoCNN
        Left in evaluation mode, their parameters requiring gradients afterwards.
    path : str or path
        The PNG to write.
    steps, seed : int
        Adam steps of the ascent (default 300), and the seed of the starting inputs' noise.

    Returns
    -------
    pathlib.Path
    """
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed

    k = len(DEPTH_BINS_M)
    idx = torch.arange(k)
    fig, axes = plt.subplots(len(models), k, figsize=(2.3 * k, 2.8 * len(models)), squeeze=False)
    for row, (name, model) in enumerate(models.items()):
        model.eval()
        trainable = [p.requires_grad for p in model.parameters()]  # given back as they were
        for p in model.parameters():
            p.requires_grad_(False)
        g = torch.Generator().manual_seed(seed)
        echo = "echo" in model.inputs
        if echo:  # log10 envelope / 4: a direct sound at 0, a -60 dB floor
            base = torch.full((k, 1323), -0.75)
            base[:, :40] = 0.0
            bands = torch.zeros(k, 7, 20)
        else:
            base = torch.zeros(k, 62, 25)
        x = (base + 0.01 * torch.randn(base.shape, generator=g)).requires_grad_(True)

        def objective(x):
            """Per class: its logit (log-mel); for an echo model, the log share of the delay
            attention that falls within the class's depth range (the unit the depth is read from)."""
            if not echo:
                return model({"mel": x})["depth_bin"][idx, idx]
            out = model({"envelope": 10 ** (4 * x), "bands": bands})
            logp = torch.log_softmax(out["delay_scores"], dim=1)
            centres = torch.tensor(DEPTH_BINS_M)[:, None]
            inside = (out["depth_at"][None] - centres).abs() <= 0.25
            return torch.logsumexp(logp.masked_fill(~inside, -1e4), dim=1)

        opt = torch.optim.Adam([x], lr=0.02)
        for _ in range(steps):
            rough = (x[..., 1:] - x[..., :-1]).pow(2).sum()
            loss = -objective(x).sum() + 0.02 * (x - base).pow(2).sum() + (0.5 if echo else 0.05) * rough
            opt.zero_grad()
            loss.backward()
            opt.step()
        for p, was in zip(model.parameters(), trainable):
            p.requires_grad_(was)
        with torch.no_grad():
            probs = torch.exp(objective(x)) if echo else torch.softmax(model({"mel": x})["depth_bin"], 1)[idx, idx]
        a = x.detach().numpy()
        for c, ax in enumerate(axes[row]):
            title = f"{DEPTH_BINS_M[c]:g} m class ({'attention' if echo else 'p'}={probs[c]:.2f})"
            if echo:
                travel = SPEED_OF_SOUND * np.arange(a.shape[1]) / FS  # emitter -> surface -> microphone
                ax.plot(np.sqrt(np.maximum(travel ** 2 - MIC_ABOVE_EMITTER_M ** 2, 0)) / 2, 80 * a[c], lw=0.7)
                ax.axvspan(DEPTH_BINS_M[c] - 0.25, DEPTH_BINS_M[c] + 0.25, color="r", alpha=0.2)
                ax.set_xlim(0, 3.5)
                ax.set_xlabel("echo distance (m)", fontsize=7)
                if c == 0:
                    ax.set_ylabel(f"{name}\nenvelope (dB)", fontsize=7)
            else:
                lim = np.abs(a).max()
                ax.imshow(a[c], origin="lower", aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, extent=(0, 1000, 0, 62))
                ax.set_xlabel("time (ms)", fontsize=7)
                if c == 0:
                    ax.set_ylabel(f"{name}\nmel band", fontsize=7)
            ax.set_title(title, fontsize=8)
            ax.tick_params(labelsize=6)
    fig.suptitle("Depth head, activation maximisation: the input that most excites each depth class", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
