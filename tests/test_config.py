"""Figure configuration: the bundled figure, and clear errors for bad files."""
import copy
from pathlib import Path

import pytest

from marionette.config import config_from_dict, load_config
from marionette.errors import ConfigError

from conftest import figure_dict


def test_bundled_hoffmann_figure_has_the_papers_16_axes():
    config = load_config()
    assert len(config.axes) == 16
    assert sum(a.name.startswith("winch_") for a in config.axes) == 9
    assert {"rotate_z", "x", "y", "light1_pan", "light1_tilt", "light2_pan", "light2_tilt"} <= set(
        config.axis_names)
    assert config.tick_period == 0.020
    assert config.axis("x").max - config.axis("x").min == pytest.approx(1.5)
    assert config.axis("y").max - config.axis("y").min == pytest.approx(1.5)
    assert "ILLUSTRATIVE" in Path(config.source).read_text()
    for a in config.axes:
        assert a.min <= a.home <= a.max and a.max_speed > 0 and a.max_accel > 0
        assert a.mean_delay == pytest.approx(a.dead_time + a.time_constant)


def test_round_trip_of_a_written_file(tmp_path):
    path = tmp_path / "fig.toml"
    path.write_text('[figure]\nname = "one"\ntick_period = 0.01\n\n[[axis]]\nname = "w"\n'
                    'node = 3\nchannel = 1\nunit = "rad"\nmin = -1\nmax = 1\nhome = 0\n'
                    'max_speed = 2\nmax_accel = 5\ndead_time = 0.01\ntime_constant = 0.02\n'
                    'scale = 100\nbandwidth = 3.5\n')
    config = load_config(path)
    assert config.tick_period == 0.01 and config.source == str(path)
    a = config.axis("w")
    assert (a.node, a.channel, a.unit, a.bandwidth, a.offset) == (3, 1, "rad", 3.5, 0.0)


def _broken(change):
    doc = figure_dict(3)
    change(doc)
    return doc


CASES = [
    ("missing key", lambda d: d["axis"][1].pop("max_speed"), ["axis[1]", "'a1'", "max_speed"]),
    ("negative speed", lambda d: d["axis"][0].update(max_speed=-2.0), ["axis[0]", "max_speed", "-2.0"]),
    ("zero accel", lambda d: d["axis"][2].update(max_accel=0), ["axis[2]", "max_accel", "0"]),
    ("limits reversed", lambda d: d["axis"][0].update(min=1.0, max=-1.0), ["axis[0]", "min = 1.0", "max = -1.0"]),
    ("unknown unit", lambda d: d["axis"][2].update(unit="furlong"), ["axis[2]", "unit", "'furlong'"]),
    ("duplicate axis", lambda d: d["axis"][2].update(name="a0"), ["duplicate", "'a0'", "axis[0]", "axis[2]"]),
    ("home outside", lambda d: d["axis"][1].update(home=5.0), ["axis[1]", "home", "5.0"]),
    ("node out of range", lambda d: d["axis"][1].update(node=300), ["axis[1]", "node", "300"]),
    ("unknown key", lambda d: d["axis"][0].update(max_sped=1.0), ["axis[0]", "max_sped", "not a known key"]),
    ("negative dead time", lambda d: d["axis"][0].update(dead_time=-0.1), ["dead_time", "-0.1"]),
    ("not a number", lambda d: d["axis"][0].update(time_constant="fast"), ["time_constant", "'fast'"]),
    ("nan", lambda d: d["axis"][0].update(max=float("nan")), ["axis[0]", ".max = nan", "not finite"]),
    ("shared address", lambda d: d["axis"][1].update(channel=0), ["'a0'", "'a1'", "channel 0"]),
    ("bad period", lambda d: d["figure"].update(tick_period=-0.02), ["tick_period", "-0.02"]),
    ("no axes", lambda d: d.pop("axis"), ["no [[axis]]"]),
    ("zero scale", lambda d: d["axis"][0].update(scale=0.0), ["scale"]),
    ("bad name", lambda d: d["axis"][0].update(name="left hand"), ["name", "'left hand'"]),
]


@pytest.mark.parametrize("what,change,expected", CASES, ids=[c[0] for c in CASES])
def test_bad_figure_is_refused_with_file_key_and_value(what, change, expected):
    with pytest.raises(ConfigError) as info:
        config_from_dict(_broken(change), "figures/bad.toml")
    message = str(info.value)
    assert message.startswith("figures/bad.toml: ")
    for part in expected:
        assert part in message, f"{what}: {part!r} not in {message!r}"


def test_bad_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[figure\nname = 1\n")
    with pytest.raises(ConfigError, match="bad.toml: not valid TOML"):
        load_config(bad)
    with pytest.raises(ConfigError, match="nope.toml: no such file"):
        load_config(tmp_path / "nope.toml")


def test_valid_document_is_not_changed_by_validation():
    doc = figure_dict(2)
    before = copy.deepcopy(doc)
    config_from_dict(doc)
    assert doc == before
