"""Music following: everything between the live music and the engine's follower.

- ``feature``: the loudness feature and the onset strength, one frame per
  20 ms tick, computed the same way at teach and at show time;
- ``follower``: the C music follower (ext/mar_follow.c) from Python;
- ``source``: what a live source of music is (start, stop, a sink for its
  frames, what it reports), and its three kinds: ``sound_card`` (with
  ``stderr_catch``, which keeps PortAudio's lines off the terminal),
  ``wav_source`` (a recording played as if live) and ``node_source`` (the
  servo nodes' LOUDNESS messages, which arrive on the link's receive path
  in marionette.transport; the engine makes that source itself);
- ``report``: what ``marionette play`` tells the operator about the music.

The simulators of music (a synthesizer and a tape deck) are in
``marionette.sim``.
"""
