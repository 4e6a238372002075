"""`marionette demo`: the sample taught, the simulator in its own process,
the show played on it with its music; the summaries; no simulator left
behind, whichever way the demo ends."""
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

import pytest

from conftest import run_cli

SIM_PID = re.compile(r"marionette sim --serial, pid (\d+)\)")


def gone(pid: int, within: float = 10.0) -> bool:
    """The process has ended (and was reaped: no zombie either)."""
    end = time.monotonic() + within
    while os.path.exists(f"/proc/{pid}"):
        if time.monotonic() >= end:
            return False
        time.sleep(0.05)
    return True


def test_demo_headless_runs_and_stops_the_simulator():
    out = run_cli("demo", "--headless", "--duration", 3, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    lines = out.stdout.splitlines()
    assert any(line.startswith("played ") and "in real time" in line for line in lines), out.stdout
    assert any(re.match(r"\s+output serial:/dev/\S+: \d+ ticks sent, \d+ bytes, 0 lost", line)
               for line in lines), out.stdout
    assert "  music follower (smooth):" in out.stdout          # the sample's music, followed
    assert "SILENT" not in out.stdout
    assert "  watchdog trips: 0" in lines, out.stdout          # the show's end told the nodes
    pid = int(SIM_PID.search(out.stdout).group(1))
    assert gone(pid, within=0.0)
    assert re.search(r"^status: show ", out.stderr, re.M), out.stderr    # headless status lines


def _demo(*args, tmp=None):
    env = dict(os.environ, TMPDIR=str(tmp)) if tmp is not None else None   # its taught show
    # Ctrl-C as in a shell's foreground job: a test run started in the
    # background (nohup, &) hands its children SIGINT ignored, and Python
    # then raises no KeyboardInterrupt before the show's view takes SIGINT
    return subprocess.Popen([sys.executable, "-m", "marionette.cli", "demo", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tempfile.gettempdir(), env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _sim_pid(proc) -> int:
    for line in proc.stdout:
        m = SIM_PID.search(line)
        if m:
            return int(m.group(1))
    raise AssertionError(f"no simulator line: {proc.stderr.read()}")


@pytest.mark.parametrize("sig,when", [(signal.SIGINT, "at once"), (signal.SIGINT, "in the show"),
                                      (signal.SIGTERM, "at once"), (signal.SIGTERM, "in the show")])
def test_demo_ctrl_c_or_sigterm_leaves_no_simulator(sig, when, tmp_path):
    """Ctrl-C (SIGINT) or SIGTERM, while the simulator starts or in the show:
    the simulator is stopped, the summaries printed (in the show), exit 130
    or 143."""
    proc = _demo("--headless", "--duration", 30, tmp=tmp_path)
    try:
        pid = _sim_pid(proc)
        if when == "in the show":
            for line in proc.stderr:                          # the first status line
                if line.startswith("status: show"):
                    break
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 128 + sig, err
        assert gone(pid), f"simulator {pid} left behind"
        if when == "in the show":                             # a controlled stop, the summaries
            assert "played " in out and "watchdog trips:" in out, out + err
            assert "ended early by " + ("Ctrl-C" if sig == signal.SIGINT else "SIGTERM") in err
            if sig == signal.SIGINT:                          # stopped at rest: the nodes were told
                assert "  watchdog trips: 0" in out.splitlines(), out
        assert list(tmp_path.iterdir()) == []                 # its temporary directory removed
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def test_demo_killed_takes_the_simulator_with_it(tmp_path):
    """SIGKILL gives the demo no chance to stop it: the kernel's parent-death
    signal (SIGTERM) does. (Its temporary directory is left: in tmp_path.)"""
    proc = _demo("--headless", "--duration", 30, tmp=tmp_path)
    try:
        pid = _sim_pid(proc)
        proc.kill()
        proc.communicate(timeout=30)
        end = time.monotonic() + 10
        while time.monotonic() < end:           # an orphan is reparented; gone or a zombie
            try:
                with open(f"/proc/{pid}/stat") as f:
                    if f.read().split(") ")[1].split()[0] == "Z":
                        break
            except FileNotFoundError:
                break
            time.sleep(0.05)
        else:
            os.kill(pid, signal.SIGKILL)
            pytest.fail(f"simulator {pid} outlived the killed demo")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
