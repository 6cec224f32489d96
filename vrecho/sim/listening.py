"""What the device hears in front of each surface of a scene: simulated frames with vrecho's
probe, the echo read back from them by deconvolution, and the truth beside it.

``vrecho demo`` (:mod:`demo`) writes its figure (the surfaces' echoes) and its table (EchoCNN's
answers, the shipped weights, beside the truth) as one step of the whole run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..features import echo_response, logmel
from ..scene import Scene
from ..signals import FS, emitted_sound, probe
from .acoustics import device_direct_amplitude, device_impulse_response, echo_delay_s, record_pulse
from .render import World, crop

ECHO_WINDOW_S = 0.3e-3


@dataclass
class Observation:
    """One device pose: the truth about the surface it faces and what its microphone heard.

    Attributes
    ----------
    pose : int
        Index of the pose in the scene's ``poses``.
    surface : int
        Index of the discontinuity it faces.
    kind : str
        That discontinuity's kind (open, glass or mirror).
    depth_m : float
        The device's distance from the surface in metres.
    incidence_deg : float
        Angle between the device's axis and the surface's normal in degrees.
    echo_delay_ms : float
        Expected echo delay after the direct sound, from geometry, in milliseconds.
    echo_level_db : float
        Measured echo peak at that delay (within 0.3 ms) relative to the direct sound, in dB.
    frame : numpy.ndarray [shape=(44100,)], float32
        The probe's 1 s frame.
    response : numpy.ndarray [shape=(1323,)], float32
        Impulse response estimated from it (first 30 ms).
    ir : numpy.ndarray [shape=(44100,)], float32
        The simulated impulse response behind the frame.
    """

    pose: int
    surface: int
    kind: str
    depth_m: float
    incidence_deg: float
    echo_delay_ms: float  # expected, from geometry
    echo_level_db: float  # measured: echo peak at that delay relative to the direct sound
    frame: np.ndarray  # the probe's 1 s frame
    response: np.ndarray  # impulse response estimated from it (first 30 ms)
    ir: np.ndarray  # the simulated impulse response behind the frame


def listen(scene: Scene, rng: np.random.Generator | None = None, *, progress: bool = True) -> list[Observation]:
    """Simulate the probe at every pose of ``scene`` that faces a discontinuity.

    Parameters
    ----------
    scene : Scene
        The scene; poses without a target are skipped.
    rng : numpy.random.Generator, optional
        Source of the recordings' noise (``default_rng(0)`` by default).
    progress : bool
        Whether to show a progress bar (default True).

    Returns
    -------
    list of Observation
        One per pose that faces a discontinuity, in the scene's order (30 dB background noise).
    """
    rng = np.random.default_rng(0) if rng is None else rng
    sound = probe()
    out = []
    for i, pose in enumerate(tqdm(scene.poses, desc="simulate poses", unit="pose", disable=not progress)):
        if pose.target is None:
            continue
        ir = device_impulse_response(scene, pose)[0]
        frame = record_pulse(ir, sound, device_direct_amplitude(scene, pose), rng, snr_db=30)
        h = echo_response(frame, sound)
        direct = int(np.argmax(np.abs(h[:int(0.002 * FS)])))
        delay = echo_delay_s(scene, pose)
        centre, half = direct + int(round(delay * FS)), int(round(ECHO_WINDOW_S * FS))
        echo = np.max(np.abs(h[centre - half:centre + half + 1]))
        d = scene.discontinuities[pose.target]
        out.append(Observation(i, pose.target, d.kind, scene.depth_m(pose), scene.incidence_deg(pose), 1e3 * delay,
                               float(20 * np.log10(echo / np.abs(h[direct]))), frame, h, ir))
    return out


def table(observations: list[Observation], predictions=None) -> str:
    """The observations as a Markdown table, with EchoCNN's answers beside the truth when given.

    Parameters
    ----------
    observations : list of Observation
        From :func:`listen`.
    predictions : list of vrecho.classifier.Prediction, optional
        One per observation: its open or closed answer (with the material), confidence and depth
        in metres.

    Returns
    -------
    str
        The table, one row per observation.
    """
    head = "| pose | surface | kind | depth (m) | incidence (deg) | echo delay (ms) | echo level (dB re direct) |"
    rule = "|---:|---:|:---|---:|---:|---:|---:|"
    if predictions is not None:
        head += " EchoCNN says (open/closed confidence) | EchoCNN depth (m) |"
        rule += ":---|---:|"
    lines = [head, rule]
    for i, o in enumerate(observations):
        line = (f"| {o.pose} | {o.surface} | {o.kind} | {o.depth_m:.2f} | {o.incidence_deg:.1f} | "
                f"{o.echo_delay_ms:.2f} | {o.echo_level_db:.1f} |")
        if predictions is not None:
            p = predictions[i]
            said = "open" if p.is_open else p.material
            line += f" {said} ({100 * p.confidence:.0f}%) | {p.depth_m:.2f} |"
        lines.append(line)
    return "\n".join(lines)


def figure(scene: Scene, observations: list[Observation], path: Path) -> Path:
    """Per surface: the clap's log-mel spectrogram, the probe's echo response with the expected
    echo marked, and the camera's crop.

    Each surface is shown from its pose nearest 1.5 m, one column per surface.

    Parameters
    ----------
    scene : Scene
        The scene the observations come from.
    observations : list of Observation
        From :func:`listen`.
    path : pathlib.Path
        The image file to write (its format from its suffix).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import matplotlib  # heavy (0.8 s to import): only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # once the Agg backend is chosen: no display needed

    world = World(scene)
    first = {}  # per surface, the pose nearest 1.5 m: its echo stands clear of the direct sound
    for o in observations:
        if o.surface not in first or abs(o.depth_m - 1.5) < abs(first[o.surface].depth_m - 1.5):
            first[o.surface] = o
    fig, axes = plt.subplots(3, len(first), figsize=(3.2 * len(first), 8.5), squeeze=False,
                             gridspec_kw={"height_ratios": [1, 1, 1.3]})
    rng = np.random.default_rng(1)
    for col, o in enumerate(first.values()):
        pose = scene.poses[o.pose]
        clap = record_pulse(o.ir, emitted_sound("clap", FS, rng), device_direct_amplitude(scene, pose), rng)
        axes[0, col].imshow(logmel(clap), origin="lower", aspect="auto", cmap="magma")
        axes[0, col].set_title(f"{o.kind}, {o.depth_m:.2f} m\nclap log-mel (62 x 25)", fontsize=9)
        axes[0, col].set_xlabel("time bin (40 ms)")
        t = 1e3 * np.arange(len(o.response)) / FS
        env = np.abs(o.response) / np.max(np.abs(o.response))
        axes[1, col].plot(t, 20 * np.log10(np.maximum(env, 1e-4)), lw=0.7)
        t_echo = o.echo_delay_ms + 1e3 * 0.07 / 343  # after the emission
        axes[1, col].axvspan(t_echo - 0.3, t_echo + 0.3, color="r", alpha=0.25, label="expected echo")
        axes[1, col].set_ylim(-70, 3)
        axes[1, col].set_xlabel("ms after emission")
        axes[1, col].set_ylabel("dB")
        axes[1, col].legend(fontsize=7, loc="upper right")
        axes[1, col].set_title("probe: deconvolved response", fontsize=9)
        axes[2, col].imshow(crop(world, pose), cmap="gray", vmin=0, vmax=255)
        axes[2, col].set_title("camera crop (64 x 25)", fontsize=9)
        axes[2, col].axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
