"""A real audio stack for the live-source tests: a PulseAudio server with a
null sink; what is played into the sink (paplay) is recorded from its
monitor through PortAudio's ALSA 'pulse' device (the ALSA pulse plugin),
with PULSE_SOURCE naming the monitor.

Without pulseaudio, the ALSA pulse plugin, PortAudio or sounddevice the
tests skip and say which is missing; with MARIONETTE_REQUIRE_AUDIO=1 (set by
.ci/run) they fail instead."""
from __future__ import annotations

import os
import shutil
import subprocess
import time

import pytest

SINK = "marionette_hil"                 # the null sink the tests play into
SERVER_START = 5.0                      # a started server answers within this [s]


def unavailable(reason: str):
    if os.environ.get("MARIONETTE_REQUIRE_AUDIO") == "1":
        pytest.fail(f"the audio stack is required here (MARIONETTE_REQUIRE_AUDIO=1): {reason}")
    pytest.skip(reason)


def server_answers() -> bool:
    return subprocess.run(["pactl", "info"], capture_output=True, timeout=10).returncode == 0


def start_server() -> None:
    """A PulseAudio server for this user (root too: it warns and runs), with
    no idle exit, and the test sink."""
    if not server_answers():
        # -D forks a daemon and returns; as root it warns that it is not
        # meant to run as root and runs (checked with PulseAudio 16.1)
        subprocess.run(["pulseaudio", "-D", "--exit-idle-time=-1"], capture_output=True, timeout=20)
        deadline = time.monotonic() + SERVER_START
        while not server_answers():
            if time.monotonic() > deadline:
                unavailable("pulseaudio -D started no server that answers pactl info")
            time.sleep(0.1)
    sinks = subprocess.run(["pactl", "list", "short", "sinks"], capture_output=True, text=True,
                           timeout=10).stdout
    if SINK not in sinks.split():
        subprocess.run(["pactl", "load-module", "module-null-sink", f"sink_name={SINK}"],
                       check=True, capture_output=True, timeout=10)


def stop_server() -> None:
    """Ends the server the way a crash would look to its clients."""
    subprocess.run(["pulseaudio", "-k"], capture_output=True, timeout=10)
    deadline = time.monotonic() + SERVER_START
    while server_answers() and time.monotonic() < deadline:
        time.sleep(0.05)


def pulse_device() -> dict:
    """Checks the stack and starts the server; the PortAudio input that
    records through PulseAudio (index, name, ...)."""
    for tool in ("pulseaudio", "pactl", "paplay"):
        if shutil.which(tool) is None:
            unavailable(f"no {tool} (Debian: apt-get install pulseaudio pulseaudio-utils)")
    # first the server: PortAudio lists the ALSA devices it could open when
    # it starts (at the import of sounddevice), 'pulse' only with a server
    start_server()
    from marionette.music.feature import AudioError
    from marionette.music.sound_card import input_devices
    try:
        devices = input_devices()
    except AudioError as exc:           # no sounddevice package, or no PortAudio library
        unavailable(str(exc))
    for d in devices:
        if d["name"] == "pulse":
            return d
    unavailable(f"PortAudio lists no 'pulse' input (the ALSA pulse plugin, Debian: "
                f"apt-get install libasound2-plugins); inputs: {devices}")


def play_into_sink(wav) -> subprocess.Popen:
    return subprocess.Popen(["paplay", f"--device={SINK}", str(wav)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def recording_env() -> dict:
    """The environment of a process that records the test sink's monitor."""
    return dict(os.environ, PULSE_SOURCE=f"{SINK}.monitor")
