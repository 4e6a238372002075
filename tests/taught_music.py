"""Taught music for the follower's scenario tests: a synthesized piece
with its stored features, made once per process."""
from __future__ import annotations

import functools

from marionette.music.bands import bands, fit_frames
from marionette.music.feature import loudness, onsets
from marionette.sim.music import synthesize


@functools.cache
def taught(style, seed):
    """A synthesized piece, its stored loudness, onsets and band levels."""
    piece = synthesize(style, seed=seed)
    loud = loudness(piece.samples, piece.sample_rate)
    return (piece, loud, onsets(piece.samples, piece.sample_rate),
            fit_frames(bands(piece.samples, piece.sample_rate), len(loud)))
