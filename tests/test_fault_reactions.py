"""The [faults] table: its validation, and the reactions as the Engine and
`play`'s summary see them (the tick's own checks are in ext/tests/test_engine.c)."""
from dataclasses import replace

import numpy as np
import pytest

from conftest import figure_dict, make_figure, make_show
from test_engine import check_limits
from marionette import _core, faults
from marionette.config import FaultConfig, config_from_dict
from marionette.engine import Engine
from marionette.errors import ConfigError


def test_defaults_are_stop_and_no_overrun_threshold():
    config = make_figure()
    assert config.faults == FaultConfig(silent_node="stop", overruns=0)
    doc = figure_dict()
    doc["faults"] = {"silent_node": "hold", "overruns": 50}
    assert config_from_dict(doc, "f.toml").faults == FaultConfig("hold", 50)


@pytest.mark.parametrize("table, expected", [
    ({"silent_node": "panic"}, "f.toml: faults.silent_node = 'panic' is not known (use one of "
                               "('stop', 'hold', 'estop', 'continue'))"),
    ({"silent_node": 1}, "f.toml: faults.silent_node = 1 is not known"),
    ({"overruns": -1}, "f.toml: faults.overruns = -1 must be an integer in 0..1000000"),
    ({"overruns": 2.5}, "f.toml: faults.overruns = 2.5 must be an integer"),
    ({"overruns": True}, "f.toml: faults.overruns = True must be an integer"),
    ({"on_fire": "run"}, "f.toml: faults.on_fire = 'run' is not a known key (known: overruns, silent_node)"),
    ("stop", "f.toml: [faults] must be a table"),
])
def test_bad_faults_table_is_refused_with_file_key_and_value(table, expected):
    doc = figure_dict()
    doc["faults"] = table
    with pytest.raises(ConfigError) as info:
        config_from_dict(doc, "f.toml")
    assert expected in str(info.value)


def moving_engine(reaction):
    config = replace(make_figure(), faults=FaultConfig(silent_node=reaction))
    t = np.arange(300) * config.tick_period
    show = make_show(config, [0.5 * np.sin(2 * np.pi * 0.6 * t + j) for j in range(3)])
    return config, Engine(config, show, record=True)


@pytest.mark.parametrize("reaction", ["stop", "hold", "estop", "continue"])
def test_a_silent_node_in_step_mode_and_the_summary(reaction):
    config, engine = moving_engine(reaction)
    with engine:
        engine.step(100)
        engine._core.set_node_alarms(0b1, 0b1)     # what the supervisor does on a silent node
        engine.step(100)
        records = engine.records()
    flags = records["flags"]
    assert np.all((flags[100:] & _core.FLAG_NODE_SILENT) != 0) and not np.any(flags[:100] & _core.FLAG_NODE_SILENT)
    lines, status = faults.summary(records, config, 0)
    assert status == 1                              # it ended with a silent node, whatever the reaction
    assert f"silent_node = {reaction}" in lines[0] and lines[-1] == "  the show ended on a fault"
    if reaction == "continue":
        assert np.all(np.diff(records["position"]) == 1)
        return
    stop = _core.FLAG_FAULT_HOLD if reaction == "hold" else _core.FLAG_FAULT_STOP
    assert np.all((flags[100:] & stop) != 0) and not np.any(flags[:100] & stop)
    rest, allowed = faults.rest_after(records, config, 100)
    assert rest is not None and rest * config.tick_period <= allowed + 2 * config.tick_period
    assert f"every axis at rest {rest * config.tick_period:.2f} s later" in lines[1]
    stopping = (flags & _core.FLAG_STOPPING) != 0
    assert stopping[100] and not np.any(stopping[:100])           # the stop ramp, planned at once
    check_limits(config, records["command"], engine.show.positions[:, 0], stopping=stopping)


def test_hold_blends_back_in_when_the_node_answers_and_ends_clean():
    config, engine = moving_engine("hold")
    with engine:
        engine.step(100)
        engine._core.set_node_alarms(0b1, 0b1)
        engine.step(50)
        engine._core.set_node_alarms(0, 0)
        engine.step(100)
        records = engine.records()
    assert records["position"][149] == records["position"][100]     # the clock waited
    assert not records["flags"][-1] & (_core.FLAG_FAULT_HOLD | _core.FLAG_MOVING | _core.FLAG_HOLDING)
    assert records["position"][-1] > records["position"][149]        # playing on
    lines, status = faults.summary(records, config, 0)
    assert status == 0 and "the show ended on a fault" not in lines


def test_no_fault_says_nothing():
    config, engine = moving_engine("stop")
    with engine:
        engine.step(50)
        records = engine.records()
    assert faults.summary(records, config, 0) == ([], 0)


def test_the_overrun_threshold_stops_a_real_time_show():
    """A real `play --realtime` process stopped (SIGSTOP) for 0.5 s mid-show
    misses 25 ticks; with `[faults] overruns = 10` the show stops at its
    limits, says so on stderr and in the summary, and exits 1."""
    import os
    import signal
    import subprocess
    import sys
    import tempfile
    import time
    from pathlib import Path
    from conftest import smooth_dance
    from marionette.config import load_config
    from marionette.recorder import read_flight_record
    tmp = Path(tempfile.mkdtemp())
    bundled = Path(load_config(None).source).read_text()
    assert "[faults]" not in bundled
    (tmp / "figure.toml").write_text(bundled + "\n[faults]\noverruns = 10\n")
    config = load_config(tmp / "figure.toml")
    make_show(config, smooth_dance(config, 200, np.random.default_rng(9))).save(tmp / "show.csv")
    play = subprocess.Popen([sys.executable, "-m", "marionette.cli", "play", str(tmp / "show.csv"),
                             "--config", str(tmp / "figure.toml"), "--realtime", "--priority", "0",
                             "--headless", "--record", str(tmp / "flight.bin")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp)
    time.sleep(1.5)
    os.kill(play.pid, signal.SIGSTOP)
    time.sleep(0.5)
    os.kill(play.pid, signal.SIGCONT)
    out, err = play.communicate(timeout=60)
    assert play.returncode == 1, (out, err)
    assert "real-time overruns" in err and "threshold 10" in err, err
    assert "the show ended on a fault" in out, out
    _, r = read_flight_record(tmp / "flight.bin")
    stopped = (r["flags"] & _core.FLAG_FAULT_STOP) != 0
    assert stopped.any() and stopped[-1] and not stopped[:50].any()
    assert np.all(r["flags"][stopped] & _core.FLAG_OVERRUNS)
