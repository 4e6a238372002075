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
