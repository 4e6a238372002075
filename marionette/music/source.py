"""What a live source of music is: something that, once started, hands one
frame per tick of the live music to a sink, and says how it is doing.

    source = SoundCard(engine.push_loudness, device="USB Audio", onsets=True)
    with source:                    # start() ... stop()
        ...
    print(source.name, source.frames, source.overflows, source.lost_reason)

A frame is the music's loudness (linear [full scale], >= 0) and its onset
strength [dB] (NaN: the source has none, as the servo nodes' LOUDNESS);
``sink(loudness, onset)`` gets them, in order, on the source's own thread
(or, for a recording in step mode, on the caller's). The sound card made
without onsets calls ``sink(loudness)`` alone; the servo nodes' source
calls ``sink(loudness, onset, bands)`` for a node that measures band
levels (linear [full scale], marionette.music.bands' unit).

The implementations: ``sound_card.SoundCard``, ``wav_source.WavSource`` (a
recording played as if live) and ``node_source.NodeLoudness`` (the servo
nodes' LOUDNESS messages).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Callable

Sink = Callable[..., object]            # sink(loudness, onset), see the module docstring


class LiveSource(ABC):
    """The live music, one frame per tick.

    sink: where the frames go (None: dropped until one is set); on_lost:
    called once with the reason when the source is lost, from whichever
    thread notices. ``frames``: frames delivered to the sink;
    ``overflows``: times the source dropped audio before it was measured;
    ``lost_reason``: why the source was lost, or None.
    """

    def __init__(self, sink: Sink | None = None, on_lost: Callable[[str], object] | None = None):
        self.sink = sink
        self.on_lost = on_lost
        self.frames = 0                     # frames delivered
        self.overflows = 0                  # audio dropped before it was measured
        self.lost_reason: str | None = None

    @property
    @abstractmethod
    def name(self) -> str:
        """What the operator calls the source."""

    @property
    def latency(self) -> float | None:
        """How old a frame's audio end is when the sink gets it [s]; None: not known."""
        return None

    @abstractmethod
    def start(self) -> "LiveSource":
        """Begin delivering frames; returns the source."""

    @abstractmethod
    def stop(self) -> None:
        """No more frames after this returns; again: nothing more."""

    def __enter__(self) -> "LiveSource":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
