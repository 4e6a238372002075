"""`marionette sim --serial &` from an interactive shell, as the README
says: a real background job on a real terminal (a pty that is the shell's
controlling terminal, job control on) runs and ends by itself instead of
being stopped for reading its terminal; in the foreground it still takes
control lines from the terminal."""
import fcntl
import os
import subprocess
import sys
import tempfile
import termios
import time

import pytest


def _shell_on_a_pty(script: str, seconds: float, typed: str = ""):
    """bash -c script with a fresh pty as its controlling terminal (stdin,
    stdout, stderr); typed is typed on the terminal once the simulator is
    ready. Returns (exit status or None if still running after seconds,
    everything it wrote)."""
    master, slave = os.openpty()

    def take_terminal():
        os.setsid()
        fcntl.ioctl(0, termios.TIOCSCTTY, 0)

    proc = subprocess.Popen(["bash", "-c", script], stdin=slave, stdout=slave, stderr=slave,
                            preexec_fn=take_terminal, cwd=tempfile.gettempdir(),
                            env={**os.environ, "PY": sys.executable})
    os.close(slave)
    out, end = b"", time.monotonic() + seconds
    os.set_blocking(master, False)
    while time.monotonic() < end and proc.poll() is None:
        try:
            out += os.read(master, 65536)
            if typed and b'"ready": true' in out:
                os.write(master, typed.encode())
                typed = ""
        except BlockingIOError:
            time.sleep(0.02)
        except OSError:         # EIO: every writer closed
            break
    status = proc.poll()
    if status is None:
        os.killpg(proc.pid, 9)
        proc.wait()
    try:
        out += os.read(master, 65536)
    except OSError:
        pass
    os.close(master)
    return status, out.decode(errors="replace")


@pytest.mark.parametrize("foreground", [False, True])
def test_sim_in_the_background_of_a_terminal_is_not_stopped(foreground):
    sim = '"$PY" -m marionette.cli sim --serial --seconds 2'
    if foreground:      # the terminal is its: it reads a control line typed there
        script = f'set -m; {sim}; echo "rc=$?"'
    else:               # a background job with job control: stopped if it read the terminal
        script = (f'set -m; {sim} & pid=$!; sleep 3.5; '
                  'if ps -o stat= -p $pid | grep -q T; then echo STOPPED; kill -9 $pid; fi; '
                  'wait $pid; echo "rc=$?"')
    status, out = _shell_on_a_pty(script, 20, "silence 2\n")
    assert status == 0 and "rc=0" in out and "STOPPED" not in out, out
    assert '"summary"' in out, out
    if foreground:
        assert '"ok": "node 2 silenced"' in out, out
