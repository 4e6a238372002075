"""CanLink on python-can's `virtual` bus, in one process, against the
in-process simulator answering on the same channel."""
import threading
import time
from contextlib import contextmanager

import can
import numpy as np

from marionette import _core, protocol
from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.engine import Engine
from marionette.show import load_show
from marionette.sim.figure import SimFigure
from marionette.transport import LinkError, open_link
from marionette.transport.can_link import FAILED_TICKS


class VirtualNodes(threading.Thread):
    """The simulated figure on a virtual CAN bus; model time = tick * period."""

    def __init__(self, config, channel):
        super().__init__(daemon=True)
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.sim = SimFigure(config, trace=True)
        self.decoder = protocol.CanDecoder()
        self.period = config.tick_period
        self.stop = threading.Event()

    def run(self):
        while not self.stop.is_set():
            msg = self.bus.recv(0.01)
            if msg is None:
                continue
            for m in self.decoder.feed(msg.arbitration_id, bytes(msg.data)):
                t = self.decoder.tick * self.period
                for answer in self.sim.handle(m, t):
                    for can_id, data in protocol.encode_can(answer):
                        self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        self.bus.shutdown()


@contextmanager
def nodes_and_link(config, channel):
    """The simulated figure answering on virtual CAN channel, and a CanLink
    on it; both closed after."""
    nodes = VirtualNodes(config, channel)
    nodes.start()
    link = open_link(f"can:virtual:{channel}")
    try:
        yield nodes, link
    finally:
        link.close()
        nodes.stop.set()
        nodes.join()


def test_engine_over_a_virtual_can_bus_in_one_process():
    config = load_config(None)
    show = load_show(DEMO_SHOW, config)
    with nodes_and_link(config, "marionette-test") as (nodes, link):
        with Engine(config, show, output=link, record=True) as engine:
            for _ in range(40):
                engine.step(1)
                time.sleep(0.005)           # the nodes answer on their thread
            time.sleep(0.2)
            records = engine.records()
            monitor = engine.nodes
    assert nodes.decoder.rejected == 0 and link.send_errors == 0
    trace = nodes.sim.trace_arrays()
    np.testing.assert_array_equal(trace["tick"], np.arange(40))
    for n, state in monitor.nodes.items():
        assert state.statuses == 40 and state.last_tick == 39, (n, state)
    # the positions the nodes report are the simulated ones, in counts
    node1 = sorted((a for a in config.axes if a.node == 1), key=lambda a: a.channel)
    last = nodes.sim.nodes[1].actual_counts()
    assert monitor.nodes[1].positions == tuple(int(c) for c in last)
    assert len(node1) == len(last)
    assert records["tick"][-1] == 39


def test_a_bus_whose_sends_all_fail_is_gone_after_three_ticks():
    """python-can's virtual bus, shut down under the link (every send then
    raises CanOperationError, without an errno): after FAILED_TICKS ticks
    whose every frame failed the link is gone, and the next tick counts
    every node silent and stops the figure (the default silent_node)."""
    config = load_config(None)
    show = load_show(DEMO_SHOW, config)
    with nodes_and_link(config, "marionette-gone") as (nodes, link):
        with Engine(config, show, output=link, record=True) as engine:
            for _ in range(20):
                engine.step(1)
                time.sleep(0.005)
            link.bus.shutdown()                     # the bus is gone
            for _ in range(10):
                engine.step(1)
            records = engine.records()
    flags = records["flags"]
    lost = (flags & _core.FLAG_LINK_LOST) != 0
    first = int(np.argmax(lost))
    print(f"gone: every send fails from tick 20, the tick reacts at tick {first}")
    assert first == 20 + FAILED_TICKS and np.all(lost[first:]), np.nonzero(lost)[0]
    assert np.all(flags[first:] & _core.FLAG_NODE_SILENT) and np.all(flags[first:] & _core.FLAG_FAULT_STOP)
    assert link.gone and link.send_errors > 0


def test_open_link_refuses_bad_descriptions():
    for spec in ("serial:", "can:virtual", "usb:/dev/x", "serial:/dev/null@fast"):
        try:
            open_link(spec)
        except LinkError as exc:
            assert spec in str(exc) or "serial" in str(exc)
        else:
            raise AssertionError(f"{spec} was accepted")


def test_a_can_link_that_cannot_open_is_told_in_plain_words(tmp_path):
    missing = tmp_path / "no-adapter"
    for spec, said in [(f"can:slcan:{missing}@500000", "No such file"),
                       ("can:no_such_interface:x", "no_such_interface")]:
        try:
            open_link(spec)
        except LinkError as exc:
            assert str(exc).startswith(f"CAN link {spec}: ") and said in str(exc)
            assert "{" not in str(exc)               # not a Python dict of bus arguments
        else:
            raise AssertionError(f"{spec} was accepted")

