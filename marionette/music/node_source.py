"""The live music as the servo nodes measure it: the loudness a node sends in
LOUDNESS messages (firmware_protocol/SPEC.md), a live source as
marionette.music.source declares it.

The messages come in on the link's receive path, which the engine's
LinkSupervisor runs (marionette.transport); its NodeMonitor calls take()
with each value and its bands. A node measures no onsets, so the onset is
NaN; a band node's frames go to ``sink(loudness, onset, bands)`` with the
band levels [full scale] (the unit of marionette.music.bands), a one-band
node's to ``sink(loudness, onset)``. On CAN a band node's frame whose bands
frame was lost comes as a one-band frame.
start() and stop() open and close the gate to the sink; the engine opens it
when it is made and closes it when it is closed.
"""
from __future__ import annotations

from marionette.errors import EngineError
from marionette.music.source import LiveSource


class NodeLoudness(LiveSource):
    """LOUDNESS values from the servo nodes to the sink (the engine's push_loudness).

    A value the sink refuses (ValueError, or EngineError: a full ring) is
    counted in ``refused`` and dropped; the C engine counts it too."""

    def __init__(self, sink, on_lost=None):
        super().__init__(sink, on_lost)
        self.refused = 0                # values the sink refused
        self._open = False

    @property
    def name(self) -> str:
        return "the servo nodes' LOUDNESS"

    def start(self) -> "NodeLoudness":
        self._open = True
        return self

    def stop(self) -> None:
        self._open = False

    def take(self, value: float, bands=None) -> None:
        """One LOUDNESS value (linear, >= 0) and its band levels (linear
        [full scale], or None), on the link's receive thread."""
        if not self._open or self.sink is None:
            return
        try:
            if bands is None:
                self.sink(value, float("nan"))
            else:
                self.sink(value, float("nan"), bands)
        except (ValueError, EngineError):
            self.refused += 1
            return
        self.frames += 1
