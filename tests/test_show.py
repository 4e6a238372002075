"""Show files: CSV and NPZ round trips, fitting to a figure, clear errors."""
import numpy as np
import pytest

from marionette.demo import DEMO_SHOW, make_demo_show
from marionette.config import load_config
from marionette.errors import ShowError
from marionette.show import load_show

from conftest import make_figure, make_show, smooth_dance


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_round_trip_many_random_shows(tmp_path, rng, suffix):
    for case in range(20):
        config = make_figure(int(rng.integers(1, 6)))
        ticks = int(rng.integers(1, 300))
        show = make_show(config, rng.uniform(-1, 1, (len(config.axes), ticks)),
                         rng.uniform(0, 2, ticks))
        show.source, show.music = f"case {case}", "song, live.wav"
        if case % 2:                                  # taught from a recording: onsets stored too
            show.onsets = rng.uniform(0, 30, ticks)
        if case % 3 == 0:                             # ... and band loudness (NPZ only)
            show.bands = rng.uniform(0, 1, (ticks, int(rng.integers(1, 9))))
        path = tmp_path / f"s{case}{suffix}"
        show.save(path)
        back = load_show(path, config)
        np.testing.assert_array_equal(back.positions, show.positions)
        np.testing.assert_array_equal(back.loudness, show.loudness)
        if case % 2:
            np.testing.assert_array_equal(back.onsets, show.onsets)
        else:
            assert back.onsets is None
        if case % 3 == 0 and suffix == ".npz":
            np.testing.assert_array_equal(back.bands, show.bands)
        else:
            assert back.bands is None                 # a CSV show carries no bands
        assert back.axis_names == show.axis_names and back.units == show.units
        assert (back.tick_period, back.source, back.music) == (0.02, show.source, show.music)


def test_bundled_demo_show_is_what_the_generator_makes():
    config = load_config()
    shipped = load_show(DEMO_SHOW, config)
    made = make_demo_show(config)
    np.testing.assert_array_equal(shipped.positions, made.positions)
    np.testing.assert_array_equal(shipped.loudness, made.loudness)


def _csv(tmp_path, body, header="tick,loudness,a0,a1", meta="# tick_period: 0.02\n"):
    path = tmp_path / "show.csv"
    path.write_text(f"# marionette show 1\n{meta}{header}\n{body}")
    return path


@pytest.mark.parametrize("body,expected", [
    ("0,0.1,0.0,0.0\n1,0.1,nan,0.0\n", ["line 5", "'a0'", "nan"]),
    ("0,0.1,0.0,inf\n", ["line 4", "'a1'", "inf"]),
    ("0,0.1,0.0,0.0\n1,0.1,0.0\n", ["line 5", "3 values", "4 columns"]),
    ("0,0.1,0.0,0.0\n2,0.1,0.0,0.0\n", ["line 5", "tick '2'", "expected 1"]),
    ("0,0.1,0.0,zero\n", ["line 4", "'a1'", "'zero'"]),
    ("0,-0.5,0.0,0.0\n", ["line 4", "loudness", "-0.5"]),
    ("", ["no data rows"]),
])
def test_bad_csv_names_line_axis_and_value(tmp_path, body, expected):
    with pytest.raises(ShowError) as info:
        load_show(_csv(tmp_path, body), make_figure(2))
    for part in expected:
        assert part in str(info.value), f"{part!r} not in {info.value}"
    assert "show.csv" in str(info.value)


@pytest.mark.parametrize("header,body,expected", [
    ("tick,loudness,onset_db,a0,a1", "0,0.1,2.0,0.0,0.0\n1,0.1,-3.0,0.0,0.0\n", ["line 5", "onset_db", "-3.0"]),
    ("tick,loudness,onset_db,a0,a1", "0,0.1,nan,0.0,0.0\n", ["line 4", "'onset_db'", "nan"]),
    ("tick,loudness,onset_db", "0,0.1,0.5\n", ["line 3", "header must be"]),     # no axis
])
def test_bad_onset_column_names_line_and_value(tmp_path, header, body, expected):
    with pytest.raises(ShowError) as info:
        load_show(_csv(tmp_path, body, header), make_figure(2))
    for part in expected:
        assert part in str(info.value), f"{part!r} not in {info.value}"


def test_unknown_missing_axis_and_wrong_period(tmp_path):
    with pytest.raises(ShowError, match="unknown axis 'elbow'"):
        load_show(_csv(tmp_path, "0,0,0,0\n", header="tick,loudness,a0,elbow"), make_figure(2))
    with pytest.raises(ShowError, match=r"no trajectory \(column\) for axis 'a1'"):
        load_show(_csv(tmp_path, "0,0,0\n", header="tick,loudness,a0"), make_figure(2))
    with pytest.raises(ShowError, match=r"tick_period 0.04 s does not match test.toml: 0.02 s"):
        load_show(_csv(tmp_path, "0,0,0,0\n", meta="# tick_period: 0.04\n"), make_figure(2))
    with pytest.raises(ShowError, match="line 1"):
        p = tmp_path / "x.csv"
        p.write_text("tick,loudness,a0\n0,0,0\n")
        load_show(p)


def test_axes_are_put_in_the_figures_order(tmp_path):
    path = _csv(tmp_path, "0,0,0.1,0.2\n", header="tick,loudness,a1,a0")
    show = load_show(path, make_figure(2))
    assert show.axis_names == ["a0", "a1"]
    np.testing.assert_array_equal(show.positions[:, 0], [0.2, 0.1])


def test_out_of_limits_error_clamp_and_compress(tmp_path):
    config = make_figure(2)                       # limits [-1, 1]
    body = "".join(f"{k},0,{v},0.5\n" for k, v in enumerate([0.0, 0.5, 1.5, 0.5, -2.0]))
    path = _csv(tmp_path, body)
    with pytest.raises(ShowError) as info:
        load_show(path, config)
    for part in ["line 6", "'a0'", "1.5", "[-1.0, 1.0]", "2 ticks outside"]:
        assert part in str(info.value)

    clamped = load_show(path, config, on_limits="clamp")
    np.testing.assert_array_equal(clamped.positions[0], [0.0, 0.5, 1.0, 0.5, -1.0])
    np.testing.assert_array_equal(clamped.positions[1], 0.5)        # untouched
    assert len(clamped.changes) == 1 and "'a0'" in clamped.changes[0] and "2 ticks" in clamped.changes[0]

    compressed = load_show(path, config, on_limits="compress")
    x = compressed.positions[0]
    assert x.min() == -1.0 and x.max() == 1.0
    assert np.all(np.diff(np.argsort(x, kind="stable")) == np.diff(np.argsort([0, .5, 1.5, .5, -2], kind="stable")))
    assert "compressed" in compressed.changes[0]


def test_npz_errors(tmp_path):
    path = tmp_path / "bad.npz"
    np.savez(path, positions=np.zeros((2, 3)))
    with pytest.raises(ShowError, match="bad.npz: missing array"):
        load_show(path)
    path.write_bytes(b"not a zip")
    with pytest.raises(ShowError, match="bad.npz: not an .npz file"):
        load_show(path)
    config = make_figure(2)
    show = make_show(config, smooth_dance(config, 10, np.random.default_rng(1)))
    show.positions[1, 7] = np.nan
    show.save(tmp_path / "nan.npz")
    with pytest.raises(ShowError, match=r"nan.npz, tick 7: axis 'a1' has value nan"):
        load_show(tmp_path / "nan.npz")
    show.positions[1, 7] = 0.0
    show.bands = np.ones((10, 6))
    show.bands[4, 2] = -1.0
    show.save(tmp_path / "band.npz")
    with pytest.raises(ShowError, match=r"band.npz, tick 4: band 2 loudness -1.0 must be finite and >= 0"):
        load_show(tmp_path / "band.npz")
    show.bands = np.ones((9, 6))
    show.save(tmp_path / "short.npz")
    with pytest.raises(ShowError, match=r"short.npz: bands have shape \(9, 6\), expected \(10 ticks"):
        load_show(tmp_path / "short.npz")


def test_a_damaged_npz_is_one_error_naming_the_file_and_no_pickle_advice(tmp_path):
    """Empty, truncated at random points, bytes overwritten at random (fixed
    seed): always a ShowError that names the file; never numpy's advice to
    allow pickles."""
    config = make_figure(2)
    good = tmp_path / "good.npz"
    make_show(config, smooth_dance(config, 200, np.random.default_rng(2))).save(good)
    data = good.read_bytes()
    rng = np.random.default_rng(20261202)
    path = tmp_path / "damaged.npz"
    cases = [b""] + [data[:rng.integers(0, len(data))] for _ in range(40)]
    for _ in range(40):
        d = bytearray(data)
        for k in rng.integers(0, len(d), size=rng.integers(1, 30)):
            d[k] = rng.integers(0, 256)
        cases.append(bytes(d))
    refused = 0
    for case in cases:
        path.write_bytes(case)
        try:
            load_show(path, config)
        except ShowError as exc:
            refused += 1
            assert str(exc).startswith(str(path)) and "pickle" not in str(exc)
    assert refused >= 75                # a few overwritten bytes may fall in padding


def test_compress_refuses_to_flatten_an_axis_for_one_outlier(tmp_path):
    """One 1e300 among a good dance: not a gain of 1e-300 for the whole axis,
    but an error naming the tick and the value."""
    config = make_figure(2)
    positions = smooth_dance(config, 50, np.random.default_rng(3))
    positions[1, 17] = 1e300
    path = tmp_path / "outlier.npz"
    make_show(config, positions).save(path)
    with pytest.raises(ShowError) as info:
        load_show(path, config, on_limits="compress")
    for part in ["tick 17", "'a1'", "1e+300", "gain of 2e-300", "under 0.5", "clamp"]:
        assert part in str(info.value), part
    positions[1, 17] = 1.2                          # a little outside: compressed as before
    make_show(config, positions).save(path)
    assert "gain" in load_show(path, config, on_limits="compress").changes[0]


def test_a_csv_missing_a_column_names_the_axis(tmp_path):
    config = make_figure(3)
    path = tmp_path / "cut.csv"
    make_show(config, smooth_dance(config, 5, np.random.default_rng(4))).save(path)
    lines = path.read_text().splitlines()
    cut = [",".join(line.split(",")[:-1]) if not line.startswith("#") else line for line in lines]
    path.write_text("\n".join(cut) + "\n")           # the last column gone, its unit left
    with pytest.raises(ShowError, match=r"cut.csv: no trajectory \(column\) for axis 'a2'"):
        load_show(path, config)
    with pytest.raises(ShowError, match=r"3 units \(m, m, m\) for 2 axes \(a0, a1\)"):
        load_show(path)

