"""`marionette log FLIGHT.bin`: the summary, --csv and --plot of real flight
records (made by `marionette play --record`), checked against the record as
read_flight_record reads it; and bad files, reported with exit status 2."""
import csv
import re

import numpy as np
import pytest

from conftest import run_cli
from marionette import _core
from marionette.cli.log import FLAGS
from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.music.feature import wav_frames
from marionette.music.follower import STATES
from marionette.music.report import follow_share
from marionette.recorder import FlightRecorder, read_flight_record
from marionette.show import Show, load_show
from marionette.teach.make_sample import sample_path


@pytest.fixture(scope="module")
def step_record(tmp_path_factory):
    """The bundled show in step mode."""
    path = tmp_path_factory.mktemp("step") / "flight.bin"
    result = run_cli("play", "--record", path)
    assert result.returncode == 0, result.stderr
    return path


@pytest.fixture(scope="module")
def music_record(tmp_path_factory):
    """A 45 s show on the bundled sample's loudness and onsets (the demo's
    motion, repeated), played with --music on the sample itself."""
    tmp = tmp_path_factory.mktemp("music")
    config = load_config(None)
    music = sample_path("music.wav")
    loud, onset = wav_frames(music, config.tick_period)
    demo = load_show(DEMO_SHOW, config)
    repeated = np.arange(len(loud)) % demo.positions.shape[1]
    show = Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=demo.positions[:, repeated],
                loudness=loud, onsets=onset, tick_period=config.tick_period)
    show.save(tmp / "show.npz")
    path = tmp / "flight.bin"
    result = run_cli("play", tmp / "show.npz", "--music", music, "--record", path)
    assert result.returncode == 0, result.stderr
    return path


def number(pattern, text):
    match = re.search(pattern, text)
    assert match, f"{pattern!r} not in:\n{text}"
    return match.group(1)


def check_summary(path, out):
    meta, rec = read_flight_record(path)
    n = len(rec)
    assert f"ticks: {n} (tick 0 .. {n - 1})" in out
    assert meta["show"] in out and meta["figure"] in out
    span = (rec["time_ns"][-1] - rec["time_ns"][0]) * 1e-9
    assert float(number(r"time span ([\d.]+) s", out)) == pytest.approx(span, abs=5e-4)
    assert int(number(r"acted on (\d+) axis-ticks", out)) == int(rec["limited_axes"].sum())
    assert int(number(r"axis-ticks in (\d+) ticks", out)) == int(np.sum(rec["limited_axes"] > 0))
    flags = number(r"flags \[ticks\]: (.*)", out)
    for bit, name in FLAGS.items():
        assert f"{name} {int(np.sum((rec['flags'] & bit) != 0))}" in flags
    assert int(number(r"bad inputs refused: on (\d+) ticks", out)) == \
        int(np.sum((rec["flags"] & _core.FLAG_BAD_INPUT) != 0))
    # each axis's recorded excess agrees with the tick's count of limited axes
    np.testing.assert_array_equal((rec["excess"] != 0).sum(axis=1), rec["limited_axes"])
    return meta, rec


def test_flag_names_come_from_the_binding():
    assert FLAGS[_core.FLAG_LIMITED] == "limited"
    assert FLAGS[_core.FLAG_SOURCE_LOST] == "source_lost"
    assert len(FLAGS) == len([k for k in vars(_core) if k.startswith("FLAG_")])


def test_summary_of_the_bundled_show_in_step_mode(step_record):
    result = run_cli("log", step_record)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    meta, rec = check_summary(step_record, out)
    assert len(rec) == 1000
    assert "music follower: none" in out and "node alarms: none" in out
    # the limited axis-ticks by axis, from the recorded excess, with the largest excess
    hits = rec["excess"] != 0
    assert hits.any()
    by_axis = number(r"by axis \[axis-ticks\]: (.*)", out)
    for j, name in enumerate(meta["axis_names"]):
        if hits[:, j].any():
            assert f"{name} {int(hits[:, j].sum())}" in by_axis
            largest = np.abs(rec["excess"][:, j]).max()
            assert f"{name}: {int(hits[:, j].sum())} ticks" in out and f"{largest:.4g}" in out


def test_summary_with_music(music_record):
    result = run_cli("log", music_record)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    _, rec = check_summary(music_record, out)
    states = number(r"music follower: ([^;]*)", out)
    for code, name in enumerate(STATES):
        share = np.mean(rec["follow_state"] == code)
        if share:
            assert f"{name} {share:.1%}" in states
    assert f"{np.mean(rec['follow_state'] == 1):.1%}" in states and \
        np.mean(rec["follow_state"] == 1) > 0.9                     # it did follow
    share = follow_share(rec)
    assert f"music not followed: {share.share:.1%} of the ticks" in out
    assert f"flag unfollowed on {share.unfollowed} ticks" in out


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


@pytest.mark.parametrize("which", ["step_record", "music_record"])
def test_csv_holds_every_field_of_every_tick(which, request, tmp_path):
    path = request.getfixturevalue(which)
    out = tmp_path / "flight.csv"
    result = run_cli("log", path, "--csv", out)
    assert result.returncode == 0, result.stderr
    meta, rec = read_flight_record(path)
    header, rows = read_csv(out)
    assert len(rows) == len(rec)
    per_axis = ("command", "excess")
    scalars = [f for f in rec.dtype.names if f not in per_axis]
    names = meta["axis_names"]
    assert header == scalars + [f"{f}_{name}" for f in per_axis for name in names]
    assert all(len(r) == len(header) for r in rows)
    cols = list(zip(*rows))
    for k, field in enumerate(scalars):
        kind = rec.dtype[field].kind
        values = np.array([float(v) if kind == "f" else int(v) for v in cols[k]],
                          dtype=rec.dtype[field])
        np.testing.assert_array_equal(values, rec[field], err_msg=field)   # bit for bit, NaN too
    for i, field in enumerate(per_axis):
        start = len(scalars) + i * len(names)
        values = np.array(cols[start:start + len(names)], dtype=float).T
        np.testing.assert_array_equal(values, rec[field], err_msg=field)


def test_plot_writes_a_png(music_record, step_record, tmp_path):
    out = tmp_path / "log.png"
    result = run_cli("log", music_record, "--plot", out, "--axes", "x,winch_head")
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20000
    assert "commands of x, winch_head" in result.stdout
    default = step_record.with_suffix(".png")          # --plot without a name: beside the record
    result = run_cli("log", step_record, "--plot")
    assert result.returncode == 0, result.stderr
    assert default.stat().st_size > 20000


def test_node_alarms_and_unknown_flags_are_counted(tmp_path):
    config = load_config(None)
    dtype = _core.record_dtype(len(config.axes))
    rec = np.zeros(50, dtype=dtype)
    rec["tick"] = np.arange(50)
    rec["time_ns"] = np.arange(50) * 20_000_000
    rec["follow_state"] = -1
    rec["node_alarms"][10:20] = 0b10              # the second node, one alarm of 10 ticks
    rec["node_alarms"][30:35] = 0b10
    rec["flags"][40:] = _core.FLAG_END | (1 << 20)
    path = tmp_path / "alarms.bin"
    recorder = FlightRecorder(dtype, config.axis_names, path,
                              dict(figure=config.name, config=config.source, show="synthetic",
                                   tick_period=config.tick_period, lead="none",
                                   interpolation="linear"))
    recorder.add(rec)
    recorder.close()
    result = run_cli("log", path)
    assert result.returncode == 0, result.stderr
    second = sorted({a.node for a in config.axes})[1]
    assert f"node alarms: node {second} 15 ticks (from 0.20 s, 2 time(s))" in result.stdout
    assert "end 10" in result.stdout and "unknown bits 0x100000 10" in result.stdout


def test_bad_files_are_errors_that_name_the_file(step_record, tmp_path):
    data = step_record.read_bytes()
    cases = {
        "truncated.bin": data[:-7],                   # the last record cut short
        "empty.bin": b"",
        "random.bin": np.random.default_rng(1).bytes(5000),
        "headless.bin": data[:40],                    # cut inside the header line
        "badjson.bin": b"MARIONETTE-FLIGHT 1 {not json\n" + bytes(100),
    }
    for name, content in cases.items():
        path = tmp_path / name
        path.write_bytes(content)
        result = run_cli("log", path, "--csv", tmp_path / "out.csv")
        assert result.returncode == 2, (name, result.stdout, result.stderr)
        assert str(path) in result.stderr and "Traceback" not in result.stderr, result.stderr
        assert not (tmp_path / "out.csv").exists()
    assert "not a whole number" in run_cli("log", tmp_path / "truncated.bin").stderr
    result = run_cli("log", tmp_path / "missing.bin")
    assert result.returncode == 2 and "argument record: " in result.stderr and "missing.bin: no such file" in result.stderr
    result = run_cli("log", step_record, "--plot", tmp_path / "x.png", "--axes", "x,nose")
    assert result.returncode == 2 and "no axis 'nose'" in result.stderr


def test_record_size_is_the_documented_one(step_record):
    """72 bytes and 16 per axis (docs/formats.md); the file's records read back at that size,
    and the engine (which checks its C record against record_dtype) wrote them."""
    meta, rec = read_flight_record(step_record)
    n = len(meta["axis_names"])
    assert rec.dtype.itemsize == meta["record_bytes"] == 72 + 16 * n
    assert rec.dtype == _core.record_dtype(n)
