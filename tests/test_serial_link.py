"""SerialLink on a pyserial URL, socket://: pyserial gives the socket's
descriptor, so the tick writes the frames to it itself; statuses come back
from simulated nodes in this process behind the TCP port."""
import socket
import threading
import time

import numpy as np

from marionette import protocol
from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.engine import Engine
from marionette.show import load_show
from marionette.sim.figure import SimFigure
from marionette.transport import open_link


class SocketNodes(threading.Thread):
    """Simulated nodes behind a TCP port; model time = SYNC tick * period."""

    def __init__(self, config):
        super().__init__(daemon=True)
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.sim = SimFigure(config, trace=True)
        self.deframer = protocol.Deframer()
        self.period = config.tick_period

    def run(self):
        conn, _ = self.server.accept()
        with conn:
            tick = 0
            while data := conn.recv(65536):
                for m in self.deframer.feed(data):
                    if isinstance(m, protocol.Sync):
                        tick = m.tick
                    answers = self.sim.handle(m, tick * self.period)
                    if answers:
                        conn.sendall(b"".join(protocol.encode_serial(a) for a in answers))
        self.server.close()


def test_engine_over_a_socket_url():
    config = load_config(None)
    show = load_show(DEMO_SHOW, config)
    nodes = SocketNodes(config)
    nodes.start()
    link = open_link(f"serial:socket://127.0.0.1:{nodes.port}")
    assert isinstance(link.fileno(), int)           # the fast path: the tick writes
    try:
        with Engine(config, show, output=link, record=True) as engine:
            for _ in range(30):
                engine.step(1)
                time.sleep(0.005)
            time.sleep(0.2)
            records = engine.records()
            monitor = engine.nodes
            stats = engine.stats()
    finally:
        link.close()
        nodes.join(5)
    assert stats["sink_frames"] == 30 and stats["sink_errors"] == 0
    assert nodes.deframer.rejected == 0 and nodes.deframer.frames_ok == 60    # SYNC + SETPOINT each
    np.testing.assert_array_equal(nodes.sim.trace_arrays()["tick"], np.arange(30))
    for n, state in monitor.nodes.items():
        assert state.statuses == 30 and state.last_tick == 29 and state.heartbeats >= 1, (n, state)
    # the setpoints the nodes took are the engine's commands, in counts
    a = config.axes[0]
    taken = nodes.sim.nodes[a.node].model.command[nodes.sim.nodes[a.node].channels.index(a.channel)]
    counts = np.round(a.offset + a.scale * records["command"][-1, 0])
    assert taken == (counts - a.offset) / a.scale
