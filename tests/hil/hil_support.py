"""Hardware-in-the-loop support (imported by the tests, fixtures included): `marionette sim` in its own process behind
a real pty (serial protocol, or an slcan CAN adapter)."""
import json
import subprocess
import sys
import tempfile

import numpy as np
import pytest

from marionette.config import load_config
from marionette.show import Show


class SimProcess:
    """`marionette sim ARGS` with a pipe to its control stdin."""

    def __init__(self, *args):
        self.proc = subprocess.Popen([sys.executable, "-m", "marionette.cli", "sim", *map(str, args)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, cwd=tempfile.gettempdir())
        self.ready = self._line()
        assert self.ready.get("ready"), self.ready

    def _line(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"simulator ended: {self.proc.stderr.read()}")
        return json.loads(line)

    def control(self, command: str) -> dict:
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        return self._line()

    def quit(self) -> dict:
        """Ends the run; returns its summary."""
        self.proc.stdin.write("quit\n")
        self.proc.stdin.flush()
        out, err = self.proc.communicate(timeout=20)
        assert self.proc.returncode == 0, err
        return json.loads(out.strip().splitlines()[-1])["summary"]

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


@pytest.fixture
def sim():
    """sim(*args) starts a simulator; all are killed at the end of the test."""
    started = []

    def start(*args):
        s = SimProcess(*args)
        started.append(s)
        return s

    yield start
    for s in started:
        s.kill()


@pytest.fixture
def figure():
    return load_config(None)


def dance_from_home(config, seconds: float, seed: int, fraction: float = 0.25) -> Show:
    """A slow random dance that starts and ends at rest at home (where the
    simulated nodes start) and stays well inside every limit."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds / config.tick_period))
    t = np.arange(n) * config.tick_period
    envelope = np.sin(np.pi * t / t[-1]) ** 2                  # 0 at both ends, smooth
    positions = np.empty((len(config.axes), n))
    for j, a in enumerate(config.axes):
        f = rng.uniform(0.3, 0.8)                              # [Hz]
        amp = min(fraction * (a.max - a.min) / 2, 0.3 * a.max_speed / (2 * np.pi * f),
                  0.2 * a.max_accel / (2 * np.pi * f) ** 2)
        room = min(a.home - a.min, a.max - a.home)
        positions[j] = a.home + min(amp, 0.8 * room) * envelope * np.sin(2 * np.pi * f * t)
    return Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=positions, loudness=np.zeros(n), tick_period=config.tick_period,
                source=f"dance_from_home seed {seed}")
