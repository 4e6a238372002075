"""NodeMonitor.check: a silent node is found from the other nodes' answers,
and the evidence is the poll that gave it away, however the answers bunch
up on their way back (a loaded receive path delivers several ticks at once)."""
import numpy as np
import pytest

from marionette.transport.node_monitor import SILENT_AFTER_TICKS, NodeMonitor

NODES = (1, 2, 3, 4, 5)


def run(rng, poll_interval):
    """A random silent node and random delivery bunching; returns (silent
    node, its last answered tick, reports as (engine tick, node, evidence),
    first engine tick whose check had the proof)."""
    monitor = NodeMonitor(NODES, keep_history=False, poll_interval=poll_interval)
    silent = int(rng.choice(NODES))
    stop = int(rng.integers(10, 40))                    # first tick the node does not answer
    polled = lambda node, k: poll_interval == 1 or k % poll_interval == NODES.index(node)  # noqa: E731
    last = max(k for k in range(stop) if polled(silent, k))
    proof = last + SILENT_AFTER_TICKS * poll_interval    # the poll that gives it away
    # ... proven sent by the first answer of another node to it or a later SYNC
    shown = next(k for k in range(proof, proof + poll_interval + 1)
                 if any(polled(n, k) for n in NODES if n != silent))
    delivered, reports, proven_at = 0, [], None         # answers delivered up to this tick
    for tick in range(80):
        # the answers to ticks [delivered, up to tick) arrive now, 0 to 3 ticks' worth
        upto = min(tick, delivered + int(rng.integers(0, 4)))
        for k in range(delivered, upto):
            for node in NODES:
                if polled(node, k) and not (node == silent and k >= stop):
                    monitor.on_status(node, k, 0, (0,), now=float(k))
        delivered = upto
        if proven_at is None and delivered > shown:
            proven_at = tick
        reports += [(tick, n, e) for n, e in monitor.check(tick, now=float(tick))]
    return silent, last, reports, proven_at


@pytest.mark.parametrize("poll_interval", [1, len(NODES)])
def test_evidence_is_the_poll_that_gave_the_node_away(poll_interval):
    rng = np.random.default_rng(31)
    for _ in range(300):
        silent, last, reports, proven_at = run(rng, poll_interval)
        # one report, for that node only: bunched answers make no other node look silent
        assert [n for _, n, _ in reports] == [silent]
        tick, _, evidence = reports[0]
        assert evidence == last + SILENT_AFTER_TICKS * poll_interval
        # not before the others' answers proved it, and at the first check after
        assert tick == proven_at
