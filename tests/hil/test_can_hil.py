"""The engine, python-can's slcan interface on a pty, and `marionette sim
--can slcan` in its own process: the CAN mapping end to end."""
import time

import numpy as np

from hil_support import dance_from_home
from marionette import protocol
from marionette.transport.can_link import CanLink
from test_serial_hil import SIM_PRIORITY, TICKS, expected_positions, play


def test_tracking_over_slcan_matches_the_servo_model(sim, figure, tmp_path):
    trace = tmp_path / "trace.npz"
    s = sim("--can", "slcan", "--priority", SIM_PRIORITY, "--trace", trace)
    link = CanLink(interface="slcan", channel=s.ready["channel"], bitrate=500000)
    assert link.protocol == "can"
    show = dance_from_home(figure, TICKS * figure.tick_period, seed=8)
    records, nodes, reports, stats = play(figure, show, link)
    # the statuses are counted by the tick each answers, not by what arrived
    # before the link closed: on a loaded machine the last ones come late
    deadline = time.monotonic() + 10.0                                   # [s]
    while time.monotonic() < deadline and any(
            s.last_tick is None or s.last_tick < TICKS - 1 for s in nodes.nodes.values()):
        time.sleep(0.01)
    link.close()
    summary = s.quit()
    assert stats["sink_frames"] == TICKS and stats["sink_errors"] == 0 and link.send_errors == 0
    # 1 SYNC + the setpoint PDOs (node 1: 3 PDOs for 9 channels, the others 1 each) per tick
    assert summary["link"]["frames"] == TICKS * (1 + 3 + 1 + 1 + 1 + 2)
    assert summary["link"]["rejected"] == 0
    t = np.load(trace)
    np.testing.assert_array_equal(t["tick"], np.arange(TICKS))
    # the model agrees as over serial, but for the time between a SYNC and
    # its setpoint PDOs: python-can sends frame by frame, so the setpoints
    # reach the node a few ms after the SYNC the model applies them at
    expected = expected_positions(figure, records["command"], t["time"])
    speed = np.array([a.max_speed for a in figure.axes])
    assert np.max(np.abs(t["positions"] - expected) / speed) <= 0.005     # [s] at top speed
    # statuses come back as STATUS header + position PDOs, joined by the decoder
    for n, state in nodes.nodes.items():
        answered = {tick for _, tick, _, _ in state.history if 0 <= tick < TICKS}
        assert len(answered) >= TICKS - 3, (n, sorted(set(range(TICKS)) - answered))
        count = sum(1 for a in figure.axes if a.node == n)
        assert len(state.positions) == count
    assert nodes.frames_bad == 0 and reports == []


def test_silent_node_and_estop_over_slcan(sim, figure):
    s = sim("--can", "slcan", "--priority", SIM_PRIORITY)
    link = CanLink(interface="slcan", channel=s.ready["channel"], bitrate=500000)
    show = dance_from_home(figure, 8.0, seed=9)
    marks = {}

    def faults(engine):
        time.sleep(1.5)
        s.control("silence 4")
        time.sleep(1.0)
        marks["estop"] = engine.snapshot().tick
        engine.estop()
        time.sleep(1.0)

    records, nodes, reports, _ = play(figure, show, link, ticks=200, during=faults)
    link.close()
    s.quit()
    assert [n for _, n, _ in reports] == [4]
    missed = nodes.nodes[4].last_tick + 1
    assert reports[0][2] - missed == 2 and reports[0][0] - missed <= 4, (reports, missed)
    for n in (1, 2, 3, 5):
        flags = np.array([h[2] for h in nodes.nodes[n].history if h[1] > marks["estop"] + 3])
        assert len(flags) > 20 and np.all(flags & protocol.FLAG_ESTOP), n
        assert nodes.nodes[n].errors == 1           # NACK (EMCY on CAN): setpoints ignored
