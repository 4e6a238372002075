"""`marionette conformance` against `marionette sim`, each in its own
process, over a pty (serial) and slcan on a pty (CAN): the simulator passes
every check; a node that does not answer, or a bad option, fails."""
import json

import pytest

from conftest import run_cli

SECTIONS = {"2 Conventions", "3.3 Receiving", "4 CONFIG", "4 STATUS", "6 SYNC", "6 HEARTBEAT",
            "6 SETPOINT", "6 Following", "6 Watchdog", "6 E-stop", "6 Receiving"}


@pytest.mark.parametrize("link", ["serial", "can"])
def test_the_simulator_passes_every_check(sim, link):
    # at SCHED_FIFO where permitted, so a busy machine does not make its answers late
    s = sim("--serial" if link == "serial" else "--can=slcan", "--priority", "30")
    where = ["--serial", s.ready["serial"]] if link == "serial" else ["--can", f"slcan:{s.ready['channel']}"]
    # node 5 has channels 0..3: the checks of a channel it lacks run on CAN too
    result = run_cli("conformance", *where, "--node", "5", "--json", timeout=60)
    report = json.loads(result.stdout)
    failed = [c for checks in report["sections"].values() for c in checks if not c["ok"]]
    assert result.returncode == 0 and not failed, failed
    assert SECTIONS <= set(report["sections"])
    names = " ".join(c["name"] for checks in report["sections"].values() for c in checks)
    reasons = ["ACCEPTED", "BAD_CONFIG", "BAD_CHANNEL", "ESTOP_LATCHED", "BAD_LENGTH", "BAD_VALUE"]
    reasons += ["CONFIG_INCOMPLETE", "STALE"] if link == "can" else ["BAD_VERSION", "BAD_TYPE"]
    assert all(r in names for r in reasons), names
    assert report["checks"] == report["passed"] >= (39 if link == "can" else 41)
    s.quit()


def test_a_node_that_does_not_answer_fails(sim):
    s = sim("--serial", "--silent", "1")
    result = run_cli("conformance", "--serial", s.ready["serial"], timeout=60)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "FAIL the node answers SYNC with STATUS: no STATUS from node 1" in result.stdout


@pytest.mark.parametrize("args, message", [
    (["--serial", "/dev/no-such-port"], "--serial /dev/no-such-port"),
    (["--serial", "/dev/null@fast"], "baud rate 'fast'"),
    (["--can", "slcan"], "expected INTERFACE:CHANNEL[@BITRATE]"),
    (["--can", "virtual:x", "--node", "128"], "--node 128: a node address is 1..127 on CAN"),
])
def test_bad_options_are_named(args, message):
    result = run_cli("conformance", *args)
    assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr, \
        result.stderr
