"""CSV recording reader/writer."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from marionette.teach.recording import (
    Recording,
    RecordingError,
    format_recording,
    parse_recording,
    read_recording,
    write_recording,
)
from marionette.teach.synthetic import synthetic_recording

GOOD = """# sample
time_s,camera,led,R,T
0.0,0,1,100,200
0.0,1,1,101.5,199

0.02,1,2,120,210
0.04,0,3,130,220
"""


def test_parse_good_file(tmp_path):
    p = tmp_path / "rec.csv"
    p.write_text(GOOD)
    rec = read_recording(p)
    assert len(rec) == 4
    np.testing.assert_array_equal(rec.time_s, [0.0, 0.0, 0.02, 0.04])
    np.testing.assert_array_equal(rec.camera, [0, 1, 1, 0])
    np.testing.assert_array_equal(rec.led, [1, 1, 2, 3])
    np.testing.assert_array_equal(rec.R, [100, 101.5, 120, 130])
    times, leds, pix = rec.fields()
    np.testing.assert_array_equal(times, [0.0, 0.02, 0.04])
    np.testing.assert_array_equal(leds, [1, 2, 3])
    assert np.all(np.isnan(pix[0, 1])) and np.all(np.isnan(pix[1, 2]))
    np.testing.assert_array_equal(pix[1, 0], [101.5, 199])


@pytest.mark.parametrize(
    "row, line, value, message",
    [
        ("0.06,0,4,nan,5", 8, "nan", "R is not a finite number"),
        ("0.06,0,4,5,inf", 8, "inf", "T is not a finite number"),
        ("0.06,2,4,5,5", 8, "2", "unknown camera"),
        ("0.06,-1,4,5,5", 8, "-1", "unknown camera"),
        ("0.06,0,5,5,5", 8, "5", "bad led number"),
        ("0.06,0,0,5,5", 8, "0", "bad led number"),
        ("0.06,0,1.5,5,5", 8, "1.5", "led is not an integer"),
        ("0.06,0,4,abc,5", 8, "abc", "R is not a number"),
        ("nan,0,4,5,5", 8, "nan", "time_s is not a finite number"),
        ("0.03,0,4,5,5", 8, "0.03", "time_s goes backwards"),
        ("0.06,0,4,5", 8, "0.06,0,4,5", "expected 5 fields"),
        ("0.06,0,4,5,5,6", 8, "0.06,0,4,5,5,6", "expected 5 fields"),
        ("0.04,1,2,5,5", 8, "2", "led differs from led 3 on line 7"),
        ("0.04,0,3,5,5", 8, "0", "camera appears twice"),
    ],
)
def test_malformed_rows_name_file_line_and_value(tmp_path, row, line, value, message):
    p = tmp_path / "bad.csv"
    p.write_text(GOOD + row + "\n")
    with pytest.raises(RecordingError, match=message) as info:
        read_recording(p)
    err = info.value
    assert err.line == line and err.value == value and err.path == str(p)
    assert f"{p}, line {line}:" in str(err) and repr(value) in str(err)


def test_bad_header_and_empty(tmp_path):
    with pytest.raises(RecordingError, match="line 1: expected header"):
        parse_recording(["time,camera,led,R,T", "0,0,1,1,1"], path="x.csv")
    with pytest.raises(RecordingError, match="empty recording"):
        parse_recording(["# nothing"], path="x.csv")
    with pytest.raises(RecordingError, match="unknown camera"):
        parse_recording(["time_s,camera,led,R,T", "0,2,1,1,1"], n_cameras=2)
    assert len(parse_recording(["time_s,camera,led,R,T", "0,2,1,1,1"], n_cameras=3)) == 1


def test_synthetic_recording_round_trip(tmp_path):
    syn = synthetic_recording(11, 4.0)
    p = tmp_path / "syn.csv"
    write_recording(p, syn.recording)
    back = read_recording(p)
    for name in ("time_s", "camera", "led", "R", "T"):
        np.testing.assert_array_equal(getattr(back, name), getattr(syn.recording, name))
    first = p.read_text().splitlines()[1]
    assert first.count(",") == 4 and "." not in first.split(",")[3]   # integer pixels


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.integers(0, 1), st.floats(-1e4, 1e4), st.floats(-1e4, 1e4)),
                min_size=1, max_size=30))
def test_any_valid_recording_round_trips(rows):
    """Unrounded floats survive the writer/reader exactly (one field per row)."""
    n = len(rows)
    rec = Recording(np.round(0.02 * np.arange(n), 9), [r[0] for r in rows], np.arange(n) % 4 + 1,
                    [r[1] for r in rows], [r[2] for r in rows])
    back = parse_recording(format_recording(rec).splitlines())
    for name in ("time_s", "camera", "led", "R", "T"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name))


def test_writer_refuses_bad_data(tmp_path):
    rec = Recording([0.0, 0.02], [0, 0], [1, 2], [1.0, np.nan], [1.0, 2.0])
    with pytest.raises(ValueError, match=r"detection 1: R=nan"):
        write_recording(tmp_path / "x.csv", rec)
    rec = Recording([0.02, 0.0], [0, 0], [1, 2], [1.0, 1.0], [1.0, 2.0])
    with pytest.raises(RecordingError, match="time_s goes backwards"):
        write_recording(tmp_path / "y.csv", rec)
    assert not (tmp_path / "y.csv").exists()
