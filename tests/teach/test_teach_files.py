"""Teach-in input files: markers CSV, cameras.toml, teach settings TOML."""
import math

import numpy as np
import pytest

from marionette.config import load_config
from marionette.teach.camera import look_at
from marionette.teach.camera_file import CameraFileError, read_cameras, write_cameras
from marionette.teach.markers import MarkerError, parse_markers
from marionette.teach.settings import SettingsError, load_settings, settings_from_dict

HEADER = "camera,marker,x,y,z,R,T"


def test_markers_parse_and_errors():
    cams = parse_markers([HEADER, "# c", "", "0,A,0,0,0,1,2", "1,A,0,0,0,3,4", "0,B,1,0,0,5,6"], "m.csv")
    assert [c.names for c in cams] == [["A", "B"], ["A"]]
    assert cams[0].lines == [4, 6] and cams[1].pixels.tolist() == [[3.0, 4.0]]
    cases = [
        ([HEADER, "0,A,0,0,0,1"], "m.csv, line 2: expected 7 fields"),
        ([HEADER, "x,A,0,0,0,1,2"], "m.csv, line 2: camera is not an integer (value 'x')"),
        ([HEADER, "0,A,0,0,inf,1,2"], "m.csv, line 2: z is not a finite number (value 'inf')"),
        ([HEADER, "0,A,0,0,0,1,2", "0,A,0,0,0,1,2"], "line 3: camera 0 lists marker 'A' twice (first on line 2)"),
        (["camera,marker,x,y,z,R"], "m.csv, line 1: expected header"),
        ([HEADER], "no markers after the header"),
    ]
    for lines, message in cases:
        with pytest.raises(MarkerError, match=message.replace("(", r"\(").replace(")", r"\)")):
            parse_markers(lines, "m.csv")
    with pytest.raises(ValueError, match="m.csv: camera 0 has no markers"):
        parse_markers([HEADER, "1,A,0,0,0,1,2"], "m.csv")


def test_cameras_round_trip_and_target(tmp_path):
    cams = [look_at((-5, -4, 3), (0, 0, 1.2), roll=0.01, L=420.0), look_at((5, -4, 3), (0, 0, 1.2), L=430.0)]
    path = tmp_path / "c.toml"
    write_cameras(path, cams, info=[{"method": "x", "n": 3}, {}], uncertainty=[{"a": 0.1}, {}])
    assert read_cameras(path) == cams
    path.write_text("[[camera]]\na = -5\nb = -4\nc = 3\ntarget = [0, 0, 1.2]\nbeta = 0.01\nL = 420\n")
    (cam,) = read_cameras(path)
    assert cam.gamma == pytest.approx(cams[0].gamma) and cam.alpha == pytest.approx(cams[0].alpha)
    for text, message in [
        ("[[camera]]\na = 1\nb = 2\nc = 3\nfocus = 2\n", "camera 0: unknown key 'focus'"),
        ("[[camera]]\na = 1\nb = 2\n", "camera 0: camera parameter 'c'"),
        ("[[camera]]\na = 1\nb = 2\nc = 3\n[[camera]]\na = 1\nb = 2\nc = 'x'\n", "camera 1: c = 'x' is not a finite number"),
        ("[[camera]]\na = 1\nb = 2\nc = 3\ntarget = [0, 0]\n", "camera 0: target = \\[0, 0\\] must be three numbers"),
        ("camera = 3\n", "no \\[\\[camera\\]\\] tables"),
        ("[[camera]\n", "not valid TOML"),
    ]:
        path.write_text(text)
        with pytest.raises(CameraFileError, match=f"{path}: {message}"):
            read_cameras(path)


def test_bundled_settings_fit_the_bundled_figure():
    s = load_settings()
    figure = load_config()
    assert sorted(s.axis_map.axis_names()) == sorted(figure.axis_names)
    assert s.half_side == 0.2 and s.max_gap_s == 2.0 and s.fit == "linear"
    # the dancer's edge lands at 95 % of the marionette's half range, inside the x limits
    edge = s.compress(0)(np.array([-2.0, 2.0]))
    np.testing.assert_allclose(edge, [-0.7125, 0.7125])
    winch = {w.name: w for w in s.axis_map.winches}
    assert winch["winch_head"].offset == figure.axis("winch_head").home
    light = s.axis_map.lights[0]
    assert light.pan_offset == pytest.approx(math.atan2(-light.position[1], -light.position[0]))


def test_settings_errors_name_file_and_key():
    for data, message in [
        ({"rucksak": {}}, r"x.toml: unknown table\(s\) \['rucksak'\]"),
        ({"rucksack": {"half": 0.2}}, "x.toml: rucksack.half is not a known key"),
        ({"rucksack": {"fit": "cubic"}}, "x.toml: rucksack.fit = 'cubic' must be one of"),
        ({"filter": {"cutoff_hz": -1}}, "x.toml: filter.cutoff_hz = -1 must be > 0"),
        ({"area": {"dancer_center": [0]}}, r"x.toml: area.dancer_center = \[0\] must be \[x, y\]"),
        ({"area": {"knee_fraction": 0.99}}, "x.toml: need 0 <= knee_fraction < edge_fraction < 1"),
        ({"map": {"winches": [{"name": "w", "attach": [0, 0]}]}}, "x.toml: Winch attach must have 3 entries"),
        ({"map": {"x_nam": "x"}}, "x.toml: unknown axis map key"),
    ]:
        with pytest.raises(SettingsError, match=message):
            settings_from_dict(data, "x.toml")
    assert settings_from_dict({"filter": {"max_gap_s": 0}}).max_gap_s is None
