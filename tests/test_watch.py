"""`vrecho watch` through a real audio server: JACK's dummy backend (a real clock, no sound card),
a JACK client that puts a simulated room in the loop (loudspeaker port -> the walk's impulse
responses -> microphone port, in real time, with a delay of its own), and the headset call in a
`vrecho watch` process that knows nothing of either."""

import os
import re
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest
from scipy.signal import fftconvolve

from conftest import small_room
from vrecho.headset import ProbeSchedule, ranging_probe
from vrecho.sim.walks import walk_responses

FS = 48000
PERIOD = 256  # JACK's period: 5.3 ms
EXTRA_S = 0.037  # the room client's own delay, on top of JACK's periods
STEP_S = 0.02  # the walk's impulse responses, one every 20 ms


@pytest.fixture(scope="module")
def jack_server():
    """A JACK server of its own (dummy backend), stopped after the module."""
    assert shutil.which("jackd"), "jackd is missing: ./install.sh --test installs Debian's jackd2"
    name = f"vrecho-test-{os.getpid()}"
    env = {**os.environ, "JACK_NO_AUDIO_RESERVATION": "1", "JACK_DEFAULT_SERVER": name}
    server = subprocess.Popen(["jackd", "-n", name, "--no-realtime", "-d", "dummy", "-r", str(FS), "-p", str(PERIOD)],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    import jack  # JACK-Client (install.sh --test)

    for _ in range(50):
        try:
            probe = jack.Client("vrecho-probe", servername=name, no_start_server=True)
            probe.close()
            break
        except jack.JackOpenError:
            time.sleep(0.1)
    else:
        server.kill()
        pytest.fail("jackd did not start")
    yield name, env
    server.terminate()
    server.wait(5)


class Room:
    """The JACK client: what the loudspeaker plays, through the walk's room, into the microphone."""

    def __init__(self, server: str, responses: list, delay: int):
        import jack

        self.responses, self.n_ir = responses, len(responses[0])
        self.history = np.zeros(self.n_ir + 8192, np.float32)
        self.delayed = np.zeros(delay + 8192, np.float32)  # the client's own delay line
        self.delay = delay
        self.started = None  # the frame at which the loudspeaker was first heard: the walk starts
        self.frame = 0
        self.rng = np.random.default_rng(0)
        self.client = jack.Client("vrecho-room", servername=server, no_start_server=True)
        self.inp = self.client.inports.register("in")
        self.out = self.client.outports.register("out")
        self.client.set_process_callback(self.process)
        self.client.activate()

    def process(self, frames: int) -> None:
        x = self.inp.get_array()
        if self.started is None and np.abs(x).max() > 0:
            self.started = self.frame
        walked = 0 if self.started is None else (self.frame - self.started) / FS
        h = self.responses[min(int(walked / STEP_S), len(self.responses) - 1)]
        hist = self.history[:self.n_ir + frames]
        hist[:self.n_ir] = hist[frames:frames + self.n_ir]
        hist[self.n_ir:] = x
        y = fftconvolve(hist, h)[self.n_ir:self.n_ir + frames] + 1e-4 * self.rng.standard_normal(frames)
        line = self.delayed[:self.delay + frames]
        line[self.delay:] = y
        self.out.get_array()[:] = line[:frames]
        line[:self.delay] = line[frames:frames + self.delay].copy()
        self.frame += frames

    def close(self) -> None:
        self.client.deactivate()
        self.client.close()


def _walk_responses():
    """A walk toward the small room's window at 1 m/s from 2.4 m, standing 0.5 s first: the
    room's impulse response every 20 ms."""
    scene = small_room()
    d = scene.discontinuities[0]
    origin, u, normal = scene.room.wall_frame(0)
    target = origin + d.center_u_m * u + [0.0, 0.0, 1.55]
    grid = ProbeSchedule(FS, ranging_probe(FS), period_s=STEP_S, dither_s=0.0)  # (the schedule only times the grid)
    walk = walk_responses(scene, target - 2.4 * normal, target, 1.0, grid, (origin, normal),
                          np.random.default_rng(0), lead_s=0.5)
    return walk


def test_watch_warns_of_the_window_through_jack(jack_server):
    server, env = jack_server
    import jack

    walk = _walk_responses()
    room = Room(server, walk.responses, int(EXTRA_S * FS))
    watcher = subprocess.Popen([sys.executable, "-m", "vrecho", "watch", "--seconds", "5.5"], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        client = room.client
        for _ in range(100):  # PortAudio's ports, once the stream is open: the room goes between them
            if client.get_ports("PortAudio:in_0") and client.get_ports("PortAudio:out_0"):
                break
            time.sleep(0.05)
        else:
            pytest.fail("vrecho watch opened no stream: " + watcher.stderr.read())
        for port in client.get_ports("PortAudio:in_"):
            for other in client.get_all_connections(port):
                client.disconnect(other, port)
        for port in client.get_ports("PortAudio:out_"):
            for other in client.get_all_connections(port):
                client.disconnect(port, other)
        client.connect("PortAudio:out_0", "vrecho-room:in")
        client.connect("vrecho-room:out", "PortAudio:in_0")
        out, err = watcher.communicate(timeout=30)
    finally:
        if watcher.poll() is None:
            watcher.kill()
        room.close()
    assert watcher.returncode == 0, err
    lines = out.splitlines()
    # It found the round trip: the room's own delay plus JACK's periods (a few).
    locked = [float(m.group(1)) for m in (re.match(r"round trip ([\d.]+) ms", line) for line in lines) if m]
    assert locked, out
    assert EXTRA_S * 1e3 < locked[-1] < EXTRA_S * 1e3 + 4 * PERIOD / FS * 1e3 + 1, out
    # Caution, then stop, and the stop at the window's half metre (give or take the walk since).
    levels = [line.split(":")[0] for line in lines if line.startswith(("caution", "stop", "clear"))]
    assert "caution" in levels and "stop" in levels and levels.index("caution") < levels.index("stop"), out
    stop = next(line for line in lines if line.startswith("stop"))
    assert 0.2 < float(re.search(r"at ([\d.]+) m", stop).group(1)) < 0.75, out
    assert room.started is not None


def test_watch_lists_the_devices_and_says_when_there_are_none(jack_server):
    """``--list-devices`` in a fresh process: the JACK server's devices where one runs; elsewhere
    the machine's, or one line saying there are none, and then ``watch`` exits with one line."""
    server, env = jack_server
    listed = subprocess.run([sys.executable, "-m", "vrecho", "watch", "--list-devices"], env=env,
                            capture_output=True, text=True, timeout=60)
    assert listed.returncode == 0 and "JACK" in listed.stdout, listed.stdout + listed.stderr
    alone = {**env, "JACK_DEFAULT_SERVER": f"{server}-absent", "JACK_NO_START_SERVER": "1"}
    listed = subprocess.run([sys.executable, "-m", "vrecho", "watch", "--list-devices"], env=alone,
                            capture_output=True, text=True, timeout=60)
    assert listed.returncode == 0 and listed.stdout.strip(), listed.stderr
    if listed.stdout.startswith("no sound devices"):  # (a machine with a sound card lists it instead)
        assert listed.stdout.count("\n") == 1
        run = subprocess.run([sys.executable, "-m", "vrecho", "watch", "--seconds", "1"], env=alone,
                             capture_output=True, text=True, timeout=60)
        assert run.returncode == 2 and run.stdout == "", run.stdout
        assert run.stderr.count("\n") == 1 and "no usable audio device" in run.stderr, run.stderr
