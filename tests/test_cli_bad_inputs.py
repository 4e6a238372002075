"""Every command driven with generated bad input: damaged files of each kind
the commands read, values outside the range of every numeric option (found
in the argparse parsers, not listed here), missing inputs and unwritable
outputs. Each must end in exit status 2 and one short line on stderr that
names the file or option and the value; never a traceback (in-process, an
exception would fail the test; a few cases also run as a real process).
Fixed seed; a damaged file that happens to stay valid may run (status 0 or 1)."""
import argparse
import subprocess
import sys

import numpy as np
import pytest

from marionette.cli import build_parser, main
from marionette.cli.options import Number, image_file, input_file, output_file
from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.music.feature import write_wav
from marionette.show import load_show
from marionette.teach.make_sample import sample_path

SEED = 20261202
DATA = sample_path("x").parent.parent         # marionette/data
MAX_ERROR_LINES = 1


def parsers():
    """(argv prefix, parser) of every command, and of every bench."""
    out = []

    def walk(prefix, parser):
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            out.append((prefix, parser))
        for sub in subs:
            for name, child in sub.choices.items():
                walk(prefix + [name], child)
    walk([], build_parser())
    return out


def cli(capsys, argv):
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def assert_refused(status, err, argv, *names):
    assert status == 2, (argv, err)
    lines = err.strip().splitlines()
    assert 1 <= len(lines) <= MAX_ERROR_LINES and "Traceback" not in err, (argv, err)
    for name in names:
        assert str(name) in err, (argv, name, err)


def outside(number: Number, rng) -> list[str]:
    """Values that Number must refuse: under and over its range, not finite,
    not a number, and for whole numbers a fraction."""
    values = ["nan", "inf", "-inf", "seven", ""]
    if number.low is not None:
        values.append(repr(number.low) if number.above else repr(number.low - 1))
        values.append(repr(number.low - float(rng.uniform(1, 1e6))) if number.kind is float
                      else str(number.low - int(rng.integers(1, 10**6))))
    if number.high is not None:
        values.append(repr(number.high + (1 if number.kind is int else float(rng.uniform(1e-6, 1e6)))))
    if number.kind is int:
        values.append(f"{rng.uniform(1, 100):.3f}")
    return values


def test_every_numeric_option_has_a_range_and_refuses_what_is_outside(capsys):
    rng = np.random.default_rng(SEED)
    tried = 0
    for prefix, parser in parsers():
        for action in parser._actions:
            if action.type in (int, float):
                raise AssertionError(f"marionette {' '.join(prefix)} {action.option_strings}: "
                                     "a number without its range (use options.Number)")
            if not isinstance(action.type, Number) or not action.option_strings:
                continue
            option = action.option_strings[-1]
            assert action.type.range in " ".join(parser.format_help().split()), (prefix, option)
            for value in outside(action.type, rng):
                argv = prefix + [f"{option}={value}"]       # '=': '-inf' is not taken for an option
                status, _, err = cli(capsys, argv)
                assert_refused(status, err, argv, option, repr(value))
                tried += 1
    assert tried > 200


def test_missing_inputs_and_unwritable_outputs_are_named(tmp_path, capsys):
    folder = tmp_path / "a folder"
    folder.mkdir()
    missing = tmp_path / "no such folder" / "f.txt"
    tried = 0
    for prefix, parser in parsers():
        for action in parser._actions:
            if action.type in (output_file, image_file) or getattr(action.type, "__name__", "") == "_plot_file":
                bad = [missing.with_suffix(".png"), folder]
            elif action.type is input_file:
                bad = [missing, folder]
            else:
                continue
            for path in bad:
                argv = prefix + ([action.option_strings[-1]] if action.option_strings else []) + [path]
                status, _, err = cli(capsys, argv)
                assert_refused(status, err, argv, path)
                tried += 1
    assert tried >= 40


def damaged(data: bytes, rng, n: int) -> list[bytes]:
    """n damaged copies: empty, cut at random points, bytes overwritten
    (anywhere, or in the first 64, where binary formats keep their header),
    a line swapped for garbage."""
    out = [b""]
    for k in range(n - 1):
        d = bytearray(data)
        if k % 4 == 0:
            d = d[:int(rng.integers(1, len(d)))]
        elif k % 4 in (1, 2):
            end = len(d) if k % 4 == 1 else min(64, len(d))
            for i in rng.integers(0, end, size=int(rng.integers(1, 12))):
                d[i] = int(rng.integers(0, 256))
        else:
            lines = bytes(d).split(b"\n")
            i = int(rng.integers(0, len(lines)))
            lines[i] = bytes(rng.integers(32, 127, size=int(rng.integers(1, 40))).astype(np.uint8))
            d = bytearray(b"\n".join(lines))
        out.append(bytes(d))
    return out


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A valid file of each kind the commands read, small, and the argv that reads it."""
    d = tmp_path_factory.mktemp("good")
    show = load_show(DEMO_SHOW, load_config())
    show.positions, show.loudness = show.positions[:, :60], show.loudness[:60]
    show.save(d / "show.csv")
    show.save(d / "show.npz")
    rate = 16000
    t = np.arange(2 * rate) / rate
    write_wav(d / "music.wav", 0.3 * np.sin(2 * np.pi * 440 * t) * (1 + np.sin(2 * np.pi * t)), rate)
    assert main(["calibrate", "--sample", "-o", str(d / "cameras.toml")]) == 0
    assert main(["play", str(d / "show.csv"), "--ticks", "30", "--record", str(d / "flight.bin")]) == 0
    (d / "truth.csv").write_text("tick,position_s\n" + "".join(f"{k},{k * 0.02}\n" for k in range(40)))
    out = d / "out"
    return {  # kind: (good file, argv with FILE where it goes)
        "show .csv": (d / "show.csv", ["check", "FILE"]),
        "show .npz": (d / "show.npz", ["play", "FILE", "--ticks", "5"]),
        "taught .npz": (d / "show.npz", ["plot", "FILE", "--axis", "winch_head", "-o", f"{out}.png"]),
        "shape .csv": (d / "show.csv", ["shape", "FILE", "-o", f"{out}.npz"]),
        "figure .toml": (DATA / "hoffmann1996.toml", ["check", str(d / "show.csv"), "--config", "FILE"]),
        "teach settings .toml": (DATA / "hoffmann1996_teach.toml",
                                 ["teach", "--sample", "--cameras", str(d / "cameras.toml"),
                                  "--settings", "FILE", "-o", f"{out}.npz", "-q", "--no-shape"]),
        "cameras .toml": (d / "cameras.toml", ["teach", "--sample", "--cameras", "FILE",
                                               "-o", f"{out}.npz", "-q", "--no-shape"]),
        "guess .toml": (d / "cameras.toml", ["calibrate", "--sample", "--guess", "FILE",
                                             "-o", f"{out}.toml", "--max-iter", "3"]),
        "markers .csv": (sample_path("markers.csv"), ["calibrate", "FILE", "-o", f"{out}.toml",
                                                      "--max-iter", "3"]),
        "recording .csv": (sample_path("recording.csv"),
                           ["teach", "FILE", "--music", str(d / "music.wav"), "--cameras",
                            str(d / "cameras.toml"), "-o", f"{out}.npz", "-q", "--no-shape"]),
        "music .wav": (d / "music.wav", ["sync-sim", "--taught", "FILE", "--live", str(d / "music.wav"),
                                         "--out", f"{out}.csv"]),
        "live .wav": (d / "music.wav", ["play", str(d / "show.npz"), "--music", "FILE", "--ticks", "5"]),
        "truth .csv": (d / "truth.csv", ["sync-sim", "--taught", str(d / "music.wav"), "--live",
                                         str(d / "music.wav"), "--out", f"{out}.csv", "--truth", "FILE"]),
        "flight .bin": (d / "flight.bin", ["log", "FILE"]),
    }


CASES = 9           # damaged copies per kind of file


@pytest.mark.parametrize("kind", ["show .csv", "show .npz", "taught .npz", "shape .csv", "figure .toml",
                                  "teach settings .toml", "cameras .toml", "guess .toml", "markers .csv",
                                  "recording .csv", "music .wav", "live .wav", "truth .csv",
                                  "flight .bin"])
def test_damaged_files_are_refused_by_name(kind, files, tmp_path, capsys):
    good, template = files[kind]
    rng = np.random.default_rng([SEED, sum(kind.encode())])
    path = tmp_path / f"damaged{good.suffix}"
    refused = 0
    for data in damaged(good.read_bytes(), rng, CASES):
        path.write_bytes(data)
        argv = [str(path) if a == "FILE" else a for a in template]
        status, _, err = cli(capsys, argv)
        if status != 2:                 # still valid after the damage: it ran (play may say 1)
            continue
        assert_refused(status, err, argv, path)
        refused += 1
    assert refused >= 2, kind           # the empty file at least, and a cut or garbled one


def test_as_a_process_the_message_is_the_same(files, tmp_path):
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    for argv, names in [(["check", empty], [str(empty), "empty"]),
                        (["play", "--rate", "100"], ["--rate", "'100'", "[0, 10]"]),
                        (["sim", "--drop", "2"], ["--drop", "'2'"])]:
        result = subprocess.run([sys.executable, "-m", "marionette.cli", *map(str, argv)],
                                capture_output=True, text=True, timeout=60,
                                cwd=tmp_path)        # outside the source tree: the installed package
        assert_refused(result.returncode, result.stderr, argv, *names)
