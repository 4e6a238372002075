"""Shared fixtures: small figures and shows made on the spot, the CLI, and
the C sources' sanitizer build."""
import concurrent.futures
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from marionette.config import config_from_dict, load_config
from marionette.show import Show


def figure_dict(n_axes=3, period=0.02, **overrides):
    """A valid figure document with n_axes axes; overrides apply to every axis."""
    axes = []
    for j in range(n_axes):
        axis = dict(name=f"a{j}", node=1, channel=j, unit="m", min=-1.0, max=1.0, home=0.0,
                    max_speed=2.0, max_accel=20.0, dead_time=0.04, time_constant=0.06,
                    scale=1000.0, offset=0.0)
        axis.update(overrides)
        axes.append(axis)
    return {"figure": {"name": "test", "tick_period": period}, "axis": axes}


def make_figure(n_axes=3, period=0.02, **overrides):
    return config_from_dict(figure_dict(n_axes, period, **overrides), "test.toml")


def make_show(config, positions, loudness=None):
    positions = np.asarray(positions, dtype=float)
    if loudness is None:
        loudness = np.zeros(positions.shape[1])
    return Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=positions, loudness=np.asarray(loudness, dtype=float),
                tick_period=config.tick_period)


def smooth_dance(config, ticks, rng, fraction=0.4):
    """Random slow sinusoids inside each axis's limits and comfortably within its speed."""
    t = np.arange(ticks) * config.tick_period
    out = np.empty((len(config.axes), ticks))
    for j, a in enumerate(config.axes):
        f = rng.uniform(0.1, 0.4)                                   # [Hz]
        amp = min(fraction * (a.max - a.min) / 2, 0.3 * a.max_speed / (2 * np.pi * f),
                  0.3 * a.max_accel / (2 * np.pi * f) ** 2)
        out[j] = (a.min + a.max) / 2 + amp * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.28))
    return out


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)


def run_cli(*args, timeout=120):
    """The marionette command in its own process, started outside the source
    tree so that it imports the installed package, as a user's would."""
    return subprocess.run([sys.executable, "-m", "marionette.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=tempfile.gettempdir())


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


ROOT = Path(__file__).resolve().parents[1]
C_STD = ["-std=c11", "-D_POSIX_C_SOURCE=200809L", "-Wall", "-Wextra", "-Werror"]
# the flags of the follower's and the protocol codec's own builds: plain C11,
# pedantic, and each seeing its own directory's headers alone
FOLLOW_CFLAGS = [*C_STD, "-Wpedantic", "-I", str(ROOT / "ext")]
PROTO_CFLAGS = [*C_STD, "-Wpedantic", "-I", str(ROOT / "firmware_protocol")]
SANITIZE = ["-g", "-O1", "-fsanitize=address,undefined", "-fno-omit-frame-pointer",
            "-fno-sanitize-recover=all"]


class SanitizedBuild:
    """The C sources compiled under AddressSanitizer and UBSan (SANITIZE),
    each source with the same flags once per session into one directory,
    several at once (one per CPU): the standalone C tests link their
    programs from these objects instead of compiling the same files again
    and again. Each object keeps its compiler's return code and messages,
    which link() reports as one gcc call over all the files would."""

    def __init__(self, directory):
        self.directory = directory
        self.done = {}              # (source, flags) -> (object path, returncode, stderr)

    def objects(self, sources, flags):
        """[(object path, returncode, stderr)] of sources compiled with gcc
        flags (and SANITIZE), compiled now where not yet."""
        keys = [(str(s), tuple(flags)) for s in sources]
        todo = [k for k in dict.fromkeys(keys) if k not in self.done]
        paths = {k: self.directory / f"{len(self.done) + i}-{Path(k[0]).stem}.o" for i, k in enumerate(todo)}

        def compile_one(key):
            result = subprocess.run(["gcc", *key[1], *SANITIZE, "-c", key[0], "-o", str(paths[key])],
                                    capture_output=True, text=True)
            return key, (paths[key], result.returncode, result.stderr)

        with concurrent.futures.ThreadPoolExecutor(max(1, len(os.sched_getaffinity(0)))) as pool:
            self.done.update(pool.map(compile_one, todo))
        return [self.done[k] for k in keys]

    def link(self, exe, parts, libs=()):
        """Compiles parts, [(sources, flags)], as objects() and links exe
        from them with libs; a CompletedProcess whose returncode is the
        first failing step's (compile or link, in order) and whose stderr is
        every step's."""
        built = [o for sources, flags in parts for o in self.objects(sources, flags)]
        failed = [rc for _, rc, _ in built if rc != 0]
        stderr = "".join(err for _, _, err in built)
        if failed:
            return subprocess.CompletedProcess([], failed[0], "", stderr)
        result = subprocess.run(["gcc", *SANITIZE, *(str(p) for p, _, _ in built), "-o", str(exe), *libs],
                                capture_output=True, text=True)
        return subprocess.CompletedProcess(result.args, result.returncode, result.stdout,
                                           stderr + result.stderr)


@pytest.fixture(scope="session")
def sanitized_build(tmp_path_factory):
    return SanitizedBuild(tmp_path_factory.mktemp("sanitized"))
