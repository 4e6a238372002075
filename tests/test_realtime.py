"""The real-time loop: runs on its own, without the GIL, and stops cleanly.
Checks count ticks and records, never wall-clock durations."""
import threading
import time

import numpy as np

from marionette import Engine

from conftest import make_figure, make_show, smooth_dance


def _busy(stop: threading.Event, counter: list):
    """Hold the GIL as much as Python lets a thread: allocate and churn."""
    while not stop.is_set():
        junk = [{"k": i, "v": [i] * 8} for i in range(200)]
        counter[0] += len(junk)


def test_runs_for_seconds_and_stops_cleanly(rng):
    config = make_figure(4)
    show = make_show(config, smooth_dance(config, 2000, rng))
    with Engine(config, show, record=True) as engine:
        engine.start(priority=0)
        time.sleep(3.0)
        assert engine.running
        engine.stop()
        assert not engine.running
        stats = engine.stats()
        records = engine.records()
        ticks_after_stop = stats["ticks"]
        time.sleep(0.1)
        assert engine.stats()["ticks"] == ticks_after_stop     # nothing ticks after stop()
    assert stats["ticks"] >= 100                                # ~150 expected in 3 s at 20 ms
    assert len(records) == stats["ticks"] and stats["records_dropped"] == 0
    np.testing.assert_array_equal(records["tick"], np.arange(len(records)))
    steps = np.diff(records["time_ns"])
    assert np.all(steps % 20_000_000 == 0) and np.all(steps > 0)   # on the 20 ms grid
    # the show clock keeps real time: missed periods still advance the position
    np.testing.assert_allclose(np.diff(records["position"]), steps / 20_000_000)
    assert stats["wake"]["count"] == stats["ticks"]
    assert stats["overruns"] == int(np.sum(steps // 20_000_000 - 1))


def test_ticks_keep_coming_while_python_threads_hold_the_gil(rng):
    config = make_figure(4)
    show = make_show(config, smooth_dance(config, 2000, rng))
    stop, counter = threading.Event(), [0]
    churners = [threading.Thread(target=_busy, args=(stop, counter)) for _ in range(2)]
    with Engine(config, show, record=True) as engine:
        for t in churners:
            t.start()
        try:
            engine.start(priority=0, max_ticks=100)
            assert engine.wait(timeout=30)                      # 2 s of ticks expected
        finally:
            stop.set()
            for t in churners:
                t.join()
        stats = engine.stats()
        records = engine.records()
    assert counter[0] > 0
    assert stats["ticks"] == 100 and len(records) == 100
    # ticks were not bunched up behind the GIL: the loop missed (almost) no deadlines
    assert stats["overruns"] <= 2, stats


def test_snapshots_are_consistent_while_the_loop_runs(rng):
    config = make_figure(8)
    show = make_show(config, smooth_dance(config, 3000, rng))
    seen = {}
    with Engine(config, show, record=True) as engine:
        engine.start(priority=0, max_ticks=60)
        while engine.running:
            snap = engine.snapshot()
            if snap is not None:
                seen[snap.tick] = list(snap.commands.values())
        engine.stop()
        records = engine.records()
    assert len(seen) >= 30
    for tick, commands in seen.items():
        assert commands == list(records["command"][tick]), f"torn snapshot at tick {tick}"


def test_a_run_until_the_show_end_stops_there(rng):
    """until_show_end: the loop stops at the show's end (FLAG_END), here
    reached at rate 1.25 after about 4/5 of the show's ticks, not at
    max_ticks; without it the loop runs to max_ticks."""
    config = make_figure(4)
    show = make_show(config, smooth_dance(config, 100, rng))
    for until_end, ticks in ((True, range(78, 86)), (False, range(200, 201))):
        with Engine(config, show, record=True, rate=1.25) as engine:
            engine.start(priority=0, max_ticks=200, until_show_end=until_end)
            assert engine.wait(timeout=30.0)
            engine.stop()
            assert engine.stats()["ticks"] in ticks, (until_end, engine.stats()["ticks"])
