"""The live view of `marionette play`: the console in a real terminal (tmux),
the headless status lines, and Ctrl-C; every one a real play process."""
import json
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from marionette import _core
from marionette.recorder import read_flight_record

from conftest import run_cli as run

T = 0.02
PLAY = [sys.executable, "-m", "marionette.cli", "play"]


class Tmux:
    """A detached tmux session of a fixed size running one command."""

    def __init__(self, command: list, width=120, height=60):
        if shutil.which("tmux") is None:
            pytest.fail("tmux is not installed (apt-get install tmux; .ci/run installs it)")
        self.name = f"marionette-test-{uuid.uuid4().hex[:8]}"
        self.status_file = f"{tempfile.gettempdir()}/{self.name}.status"
        # the exit status lands in a file, and the pane stays for capture; the
        # terminal's own size, not pytest's COLUMNS and LINES (80 x 24)
        shell = (f"env -u COLUMNS -u LINES {shlex.join(map(str, command))}; "
                 f"echo $? > {self.status_file}; sleep 600")
        subprocess.run(["tmux", "new-session", "-d", "-s", self.name, "-x", str(width),
                        "-y", str(height), "-c", tempfile.gettempdir(), shell], check=True)

    def screen(self) -> str:
        return subprocess.run(["tmux", "capture-pane", "-p", "-t", self.name], check=True,
                              capture_output=True, text=True).stdout

    def wait_for(self, text: str, timeout=15.0) -> str:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            screen = self.screen()
            if text in screen:
                return screen
            time.sleep(0.1)
        raise AssertionError(f"{text!r} not on the screen after {timeout} s:\n{self.screen()}")

    def send(self, key: str) -> None:
        subprocess.run(["tmux", "send-keys", "-t", self.name, key], check=True)

    def exit_status(self, timeout=20.0) -> int:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                return int(Path(self.status_file).read_text())
            except (FileNotFoundError, ValueError):
                time.sleep(0.1)
        raise AssertionError(f"play did not end:\n{self.screen()}")

    def kill(self) -> None:
        subprocess.run(["tmux", "kill-session", "-t", self.name], capture_output=True)


@pytest.fixture
def tmux():
    sessions = []

    def start(command, **size):
        t = Tmux(command, **size)
        sessions.append(t)
        return t

    yield start
    for t in sessions:
        t.kill()


def test_console_keys_pause_resume_estop_release_quit(tmux, sim, tmp_path):
    s = sim("--serial")
    flight = tmp_path / "flight.bin"
    term = tmux(PLAY + ["--realtime", "--priority", "0", "--record", flight,
                        "--link", f"serial:{s.ready['serial']}"])
    screen = term.wait_for("servo nodes")
    assert "space pause/resume" in screen and "e e-stop" in screen and "q stop and quit" in screen
    for panel in ("music", "limiter by axis", "wake latency p99", "flight recorder", "round trip"):
        assert panel in screen, screen
    screen = term.wait_for(" alive ")
    assert "SILENT" not in screen, screen
    time.sleep(1.0)

    term.send("Space")
    term.wait_for("paused: limited stop")
    screen = term.wait_for("HOLDING")                 # the stop ramp ended: the figure holds
    assert "PAUSED" in screen
    time.sleep(1.0)
    term.send("Space")
    term.wait_for("resumed: blending back in")
    time.sleep(1.5)
    term.send("e")
    term.wait_for("E-STOP")
    screen = term.wait_for("ESTOP ")                  # the nodes report their latch
    time.sleep(0.5)
    term.send("r")
    term.wait_for("e-stop released")
    time.sleep(0.5)
    term.send("b")
    term.wait_for("blending in")
    time.sleep(1.0)
    term.send("q")
    screen = term.wait_for("played ")                 # the summary, on the normal screen
    assert term.exit_status() == 0
    assert "ended early by q" in screen and "Traceback" not in screen
    s.quit()

    _, r = read_flight_record(flight)
    holding = (r["flags"] & _core.FLAG_HOLDING) != 0
    moving = (r["flags"] & _core.FLAG_MOVING) != 0
    playing = ~holding & ~moving
    # pause: a limited stop (a move), a hold at one place in the show; then a
    # blend back in, and the show plays on from there
    first_hold = np.flatnonzero(holding)[0]
    assert moving[first_hold - 1]
    held = first_hold + np.flatnonzero(~holding[first_hold:])[0]
    assert held - first_hold > 25                     # held for about a second
    assert np.ptp(r["position"][first_hold:held]) == 0
    resumed = held + np.flatnonzero(playing[held:])[0]
    assert r["position"][resumed + 25] > r["position"][held] + 20
    # e-stop: the nodes' alarms in the records while latched, the commands held
    alarms = np.flatnonzero(r["node_alarms"])
    assert len(alarms) and alarms[0] > resumed
    assert np.all(holding[alarms[5]:alarms[-1]] | moving[alarms[5]:alarms[-1]])
    # release, blend in: the show plays again; q: a controlled stop, then the end
    assert np.any(playing[alarms[-1]:])
    assert holding[-1] and len(r) < 1000


def test_a_pause_moves_the_show_s_end_later_and_the_show_plays_to_it(tmux, tmp_path):
    """Paused for 1.5 s in a 3 s real-time show: the show still plays to its
    last tick (the run ends at the show's end, not after the show's ticks of
    wall time), about 1.5 s later than it would have."""
    from marionette.config import load_config
    from conftest import make_show, smooth_dance
    config = load_config(None)
    ticks = 150
    show_path = tmp_path / "short.csv"
    make_show(config, smooth_dance(config, ticks, np.random.default_rng(8))).save(show_path)
    flight = tmp_path / "flight.bin"
    term = tmux(PLAY + [show_path, "--realtime", "--priority", "0", "--record", flight])
    term.wait_for("flight recorder")
    time.sleep(0.5)
    term.send("Space")
    term.wait_for("HOLDING")
    time.sleep(1.5)
    term.send("Space")
    term.wait_for("resumed: blending back in")
    screen = term.wait_for("played ", timeout=20.0)
    assert term.exit_status() == 0
    assert "ended early" not in screen and "Traceback" not in screen
    _, r = read_flight_record(flight)
    holding = (r["flags"] & _core.FLAG_HOLDING) != 0
    assert holding.sum() > 60                          # paused for about 1.5 s
    assert r["position"].max() >= ticks - 1.5          # ... and still played to the show's last tick
    assert len(r) > ticks + 60
    assert r["flags"][-1] & _core.FLAG_END


def test_console_without_rich_falls_back_to_headless(tmux):
    code = ("import sys; sys.modules['rich'] = None; from marionette.cli import main; "
            "sys.exit(main(['play', '--ticks', '10']))")
    term = tmux([sys.executable, "-c", code])
    screen = term.wait_for("played ")
    assert "no live console without the 'console' extra" in screen
    assert term.exit_status() == 0


def test_stderr_lines_during_the_console_are_shown_and_kept(tmux):
    """What other threads print on stderr (a lost-music line, say) shows in
    the console, and again on the normal screen after it."""
    code = ("import sys, threading; from marionette.cli import main; "
            "threading.Timer(1.0, lambda: print('a line from a thread', file=sys.stderr)).start(); "
            "sys.exit(main(['play', '--realtime', '--priority', '0', '--ticks', '150']))")
    term = tmux([sys.executable, "-c", code])
    screen = term.wait_for("a line from a thread")
    assert "messages" in screen and "space pause/resume" in screen
    screen = term.wait_for("played ")
    assert term.exit_status() == 0
    assert "a line from a thread" in screen.split("played ")[0]


def test_headless_status_lines_and_json():
    result = run("play", "--realtime", "--priority", "0", "--ticks", "120", "--json")
    assert result.returncode == 0, result.stderr
    lines = [json.loads(line) for line in result.stderr.splitlines()]
    if "warning" in lines[-1]:          # the limits acted on the demo show (limiter_report)
        assert "axis-ticks" in lines.pop()["warning"]
    assert len(lines) >= 2
    assert lines[-1]["tick"] > lines[0]["tick"] and lines[-1]["show_total_s"] == 19.98
    assert {"rate", "wake_p99_us", "overruns", "limited_by_axis", "recorder"} <= set(lines[0])
    assert result.stdout.startswith("played ")        # the summary alone on stdout
    result = run("play", "--realtime", "--priority", "0", "--ticks", "120", "--headless")
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stderr.splitlines() if not line.startswith("warning: the limits")]
    assert len(lines) >= 2 and all(line.startswith("status: show ") for line in lines), lines
    assert "wake p99" in lines[0] and "rec " in lines[0]
    # step mode runs as fast as it can: no status lines (only the limiter's warning)
    result = run("play", "--ticks", "200", "--headless")
    assert result.returncode == 0
    assert [line for line in result.stderr.splitlines() if not line.startswith("warning: the limits")] == []


def play_process(flight):
    return subprocess.Popen(PLAY + ["--realtime", "--priority", "0", "--record", str(flight)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tempfile.gettempdir())


def test_ctrl_c_is_a_controlled_stop_then_the_summary(tmp_path):
    flight = tmp_path / "flight.bin"
    proc = play_process(flight)
    time.sleep(2.5)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "play: ended early by Ctrl-C" in err
    assert out.startswith("played ") and "flight recorder" in out and "wake latency" in out
    _, r = read_flight_record(flight)
    assert len(r) < 500
    holding = (r["flags"] & _core.FLAG_HOLDING) != 0
    moving = (r["flags"] & _core.FLAG_MOVING) != 0
    assert holding[-1] and np.any(moving)             # a stop ramp, then at rest
    stop = np.flatnonzero(moving)[0]
    assert np.all(moving[stop:] | holding[stop:])


def test_a_second_ctrl_c_estops_and_ends(tmp_path):
    proc = play_process(tmp_path / "flight.bin")
    time.sleep(2.5)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "ended early by second Ctrl-C: e-stop" in err
    assert out.startswith("played ")


def test_sigterm_estops_and_ends_with_the_summary(tmp_path):
    proc = play_process(tmp_path / "flight.bin")
    time.sleep(2.0)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, err
    assert "Traceback" not in err and "ended early by SIGTERM: e-stop" in err
    assert out.startswith("played ")
