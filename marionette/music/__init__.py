"""Music following: everything between the live music and the engine's follower.

- ``feature``: the loudness feature and the onset strength, one frame per
  20 ms tick, computed the same way at teach and at show time;
- ``follower``: the C music follower (ext/mar_follow.c) from Python;
- ``sound_card`` (with ``stderr_catch``): the live music from a sound card;
- ``report``: what ``marionette play`` tells the operator about the music.

The simulators of music (a synthesizer and a tape deck) are in
``marionette.sim``.
"""
