"""Bad input to the marionette command, as issue 19 found it: each one a short
message that names the file or option and the value, exit status 2, no
traceback. In-process through main(argv), as the console script runs it."""
import os

import numpy as np
import pytest

from marionette.cli import main
from marionette.demo import DEMO_SHOW
from marionette.show import load_show


def cli(capsys, *argv):
    """(exit status, stdout, stderr) of `marionette ARGV`, run in this process."""
    try:
        status = main([str(a) for a in argv])
    except SystemExit as exc:           # argparse: --help, --version, a refused value
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


def refused(capsys, *argv, names=()):
    status, out, err = cli(capsys, *argv)
    assert status == 2, (argv, out, err)
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for part in names:
        assert part in err, (argv, err)
    return err


@pytest.fixture(scope="module")
def show_npz(tmp_path_factory):
    path = tmp_path_factory.mktemp("show") / "show.npz"
    load_show(DEMO_SHOW).save(path)
    return path


@pytest.mark.parametrize("command", ["check", "play", "plot"])
def test_an_empty_or_truncated_npz_names_the_file(command, show_npz, tmp_path, capsys):
    extra = ["--axis", "x", "-o", tmp_path / "p.png"] if command == "plot" else []
    empty, cut = tmp_path / "empty.npz", tmp_path / "cut.npz"
    empty.write_bytes(b"")
    cut.write_bytes(show_npz.read_bytes()[:5000])
    refused(capsys, command, empty, *extra, names=[str(empty), "empty"])
    err = refused(capsys, command, cut, *extra, names=[str(cut), "damaged"])
    assert "pickle" not in err


@pytest.mark.parametrize("option, value, said", [
    ("--rate", "-1", "[0, 10]"), ("--rate", "100", "[0, 10]"), ("--rate", "nan", "finite"),
    ("--ticks", "-5", ">= 1"), ("--ticks", "0", ">= 1"), ("--ticks", "2.5", "whole number"),
    ("--priority", "100", "[0, 99]")])
def test_play_refuses_an_option_out_of_its_range(option, value, said, capsys):
    refused(capsys, "play", option, value, names=[option, repr(value), said])


def test_realtime_play_refuses_zero_ticks_rather_than_running_forever(capsys):
    refused(capsys, "play", "--realtime", "--ticks", "0", names=["--ticks", "'0'"])


@pytest.mark.parametrize("option", ["--record", "--output"])
def test_play_refuses_an_unwritable_path_before_it_runs(option, tmp_path, capsys):
    missing = tmp_path / "no" / "such" / "folder" / "f.bin"
    refused(capsys, "play", option, missing, names=[option, str(missing), "does not exist"])
    refused(capsys, "play", option, tmp_path, names=[option, str(tmp_path), "folder"])
    if os.geteuid() != 0:                       # root may write anywhere
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        refused(capsys, "play", option, locked / "f.bin", names=[option, "permission"])


def test_help_and_version(capsys):
    status, out, _ = cli(capsys, "--version")
    assert status == 0 and out.startswith("marionette 0.")
    status, out, _ = cli(capsys, "--help")
    assert status == 0 and "The ``marionette`` command" not in out and "marionette demo" in out
    status, out, _ = cli(capsys, "bench", "--help")
    assert status == 0 and all(name in out for name in ("tick", "jitter", "moves", "fuzz", "link", "sync"))
    status, out, _ = cli(capsys, "play", "--help")
    for said in ("[0, 10]", "dead_time_lag (default)", "Catmull-Rom", "Play a show"):
        assert said in " ".join(out.split()), said


def test_plot_refuses_an_unknown_image_format_or_a_missing_folder(show_npz, tmp_path, capsys):
    refused(capsys, "plot", show_npz, "--axis", "x", "-o", tmp_path / "p.xyz",
            names=["-o/--output", "p.xyz", "'.xyz'", ".png"])
    missing = tmp_path / "none" / "p.png"
    refused(capsys, "plot", show_npz, "--axis", "x", "-o", missing,
            names=["-o/--output", str(missing), "does not exist"])


@pytest.mark.parametrize("argv, said", [
    (["--drop", "2"], ["--drop", "'2'", "[0, 1]"]),
    (["--corrupt", "-0.1"], ["--corrupt", "'-0.1'"]),
    (["--silent", "9"], ["--silent 9", "no node 9", "1, 2, 3, 4, 5"]),
    (["--silent", "1", "x"], ["--silent", "'x'"]),
    (["--loudness-node", "7"], ["--loudness-node 7", "no node 7"]),
    (["--loudness-only"], ["--loudness-only", "no --music"]),
    (["--watchdog-ticks", "0"], ["--watchdog-ticks", "'0'"])])
def test_sim_refuses_bad_faults_before_it_starts(argv, said, capsys):
    refused(capsys, "sim", "--seconds", "0.1", *argv, names=said)


def test_sim_control_lines_are_checked():
    from marionette.sim.faults import Faults
    from marionette.errors import MarionetteError
    faults = Faults(nodes=frozenset({1, 2, 5}))
    for line, said in [("silence 99", "no node 99"), ("silence x", "'x' is not a whole number"),
                       ("corrupt abc", "'abc' is not a number"), ("drop 2", "at most 1"),
                       ("delay -1", ">= 0"), ("wobble 1", "unknown fault"), ("silence", "expected")]:
        with pytest.raises(MarionetteError) as info:
            faults.apply(line)
        assert repr(line) in str(info.value) and said in str(info.value), line
    assert faults.apply("silence 5") == "node 5 silenced" and faults.silent == {5}
    assert faults.apply("corrupt 0.25") == "corrupt_rate = 0.25"


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
def test_a_flight_record_that_cannot_be_written_is_named(capsys):
    refused(capsys, "play", "--ticks", "5", "--record", "/dev/full",
            names=["/dev/full", "cannot write the flight record", "No space left"])


def test_sim_names_music_it_cannot_measure(tmp_path, capsys):
    from marionette.music.feature import write_wav
    low = tmp_path / "low.wav"
    write_wav(low, np.zeros(4000), 4000)                       # under the 8 kHz the band needs
    refused(capsys, "sim", "--seconds", "0.1", "--music", low, names=[str(low), "4000"])


def test_sim_answers_bad_control_lines_with_an_error_and_runs_on(sim):
    """Through the simulator process's stdin, as an operator types them."""
    s = sim("--serial")
    for line, said in [("silence 99", "there is no node 99 (nodes: 1, 2, 3, 4, 5)"),
                       ("corrupt abc", "'abc' is not a number")]:
        answer = s.control(line)
        assert set(answer) == {"error"} and repr(line) in answer["error"] and said in answer["error"]
    assert s.control("silence 5") == {"ok": "node 5 silenced"}
    s.quit()
