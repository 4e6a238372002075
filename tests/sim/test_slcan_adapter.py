"""The emulated slcan adapter on a real pty, driven by python-can's own
slcan interface."""
import os
import select

import can
import numpy as np

from marionette.sim.slcan import BELL, CR, Pty, SlcanAdapter


def _read_available(fd, wait=0.5):
    out = b""
    while select.select([fd], [], [], wait)[0]:
        out += os.read(fd, 4096)
        wait = 0.05
    return out


def test_python_can_slcan_talks_to_the_adapter_both_ways():
    rng = np.random.default_rng(7)
    pty, adapter = Pty(), SlcanAdapter()
    bus = can.Bus(interface="slcan", channel=pty.path, bitrate=500000, sleep_after_open=0)
    try:
        sent = [(int(rng.integers(0, 0x800)), bytes(rng.integers(0, 256, int(rng.integers(0, 9)),
                                                                  dtype=np.uint8)))
                for _ in range(50)]
        for can_id, data in sent:
            bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        frames, answer = adapter.feed(_read_available(pty.master))
        assert adapter.is_open and adapter.bitrate_code == "6"        # 500 kbit/s
        assert frames == sent
        assert set(answer) == {CR[0]} and adapter.bad_lines == 0
        back = sent[:20] + [(0x1ABCDEF0, b"\x01")]                     # and one 29-bit id
        os.write(pty.master, b"".join(SlcanAdapter.encode(i, d) for i, d in back))
        got = [bus.recv(1.0) for _ in back]
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == back
        assert got[-1].is_extended_id and not got[0].is_extended_id
    finally:
        bus.shutdown()
        pty.close()


def test_garbage_lines_are_answered_with_bell_and_counted():
    adapter = SlcanAdapter()
    adapter.feed(b"O\r")
    frames, answer = adapter.feed(b"t12\rq\rt2013AABB\r" + b"x" * 100 + b"\rt1000\r")
    assert frames == [(0x100, b"")]
    assert answer.count(BELL) == 3 and adapter.bad_lines == 4      # 3 bad lines + 1 runaway


def test_frames_before_open_are_not_delivered():
    adapter = SlcanAdapter()
    frames, _ = adapter.feed(b"t1001AA\r")
    assert frames == [] and adapter.bad_lines == 0
