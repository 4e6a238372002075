"""`marionette conformance` against `marionette sim`, each in its own
process, over a pty (serial) and slcan on a pty (CAN): the simulator passes
every check; a node that does not answer, or a bad option, fails."""
import json

import pytest

from conftest import run_cli
from marionette.music.feature import write_wav
from marionette.sim.music import synthesize

SECTIONS = {"2 Conventions", "3.3 Receiving", "4 CONFIG", "4 STATUS", "6 SYNC", "6 HEARTBEAT",
            "6 SETPOINT", "6 Following", "6 Watchdog", "6 E-stop", "6 Receiving"}


@pytest.fixture(scope="module")
def music(tmp_path_factory):
    """10 s of synthesized music for the node to measure."""
    piece = synthesize("pop", seed=3)
    path = tmp_path_factory.mktemp("music") / "music.wav"
    write_wav(path, piece.samples[:int(10 * piece.sample_rate)], int(piece.sample_rate))
    return path


@pytest.mark.parametrize("link, form", [("serial", "6 bands"), ("can", "6 bands"),
                                        ("can", "the loudness alone")])
def test_the_simulator_passes_every_check(sim, music, link, form):
    # at SCHED_FIFO where permitted, so a busy machine does not make its answers late;
    # node 5, the figure's last, measures the music
    s = sim("--serial" if link == "serial" else "--can=slcan", "--priority", "30", "--music", music,
            *(["--loudness-only"] if form == "the loudness alone" else []))
    where = ["--serial", s.ready["serial"]] if link == "serial" else ["--can", f"slcan:{s.ready['channel']}"]
    # node 5 has channels 0..3: the checks of a channel it lacks run on CAN too
    result = run_cli("conformance", *where, "--node", "5", "--json", timeout=60)
    report = json.loads(result.stdout)
    failed = [c for checks in report["sections"].values() for c in checks if not c["ok"]]
    assert result.returncode == 0 and not failed, failed
    assert SECTIONS | {"4 LOUDNESS", "6 LOUDNESS"} <= set(report["sections"])
    assert report["figures"]["loudness"] == form
    names = " ".join(c["name"] for checks in report["sections"].values() for c in checks)
    reasons = ["ACCEPTED", "BAD_CONFIG", "BAD_CHANNEL", "ESTOP_LATCHED", "BAD_LENGTH", "BAD_VALUE"]
    reasons += ["CONFIG_INCOMPLETE", "STALE"] if link == "can" else ["BAD_VERSION", "BAD_TYPE"]
    assert all(r in names for r in reasons), names
    assert report["checks"] == report["passed"] >= (44 if link == "can" else 46)
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
