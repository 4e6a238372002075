"""A lost live source (Engine.source_lost, as `play --audio-device` calls it
when the sound card's stream fails, ends or goes silent): from the next tick
to the end every record carries FLAG_SOURCE_LOST, the music is not followed
(FLAG_UNFOLLOWED) and [follow] on_lost applies at once; nothing changes
before. Step mode, the bundled figure and the show `marionette teach
--sample` makes, the bundled music played 3 % fast with noise as the live
source."""
import numpy as np
import pytest

from conftest import run_cli
from marionette import _core
from marionette._core import FLAG_SOURCE_LOST, FLAG_UNFOLLOWED
from marionette.config import load_config
from marionette.engine import Engine
from marionette.music.feature import loudness, onsets, read_wav
from marionette.music.follower import sync_ticks
from marionette.music.report import follow_share, share_line
from marionette.show import load_show
from marionette.sim.tape import Deck, play
from marionette.teach.make_sample import sample_path

LOST_AT = 1200          # the tick the source is reported lost before [tick] (24 s; locked by then)
LOCKED = 1              # follow_state code


@pytest.fixture(scope="module")
def sample_show(tmp_path_factory):
    d = tmp_path_factory.mktemp("sample")
    result = run_cli("calibrate", "--sample", "-o", d / "cameras.toml")
    assert result.returncode == 0, result.stderr
    result = run_cli("teach", "--sample", "--cameras", d / "cameras.toml", "-o", d / "show.npz")
    assert result.returncode == 0, result.stderr
    config = load_config(None)
    return config, load_show(d / "show.npz", config)


@pytest.fixture(scope="module")
def live():
    """(loudness, onset) per tick as the engine hears them: tick k gets frame k - 1."""
    x, rate = read_wav(sample_path("music.wav"))
    played = play(x, rate, Deck(speed=1.03, snr_db=20.0, sample_rate=rate, seed=11))
    return (sync_ticks(loudness(played.samples, played.sample_rate)),
            sync_ticks(onsets(played.samples, played.sample_rate)))


def run(sample_show, live, on_lost, lost_at=None):
    """The whole show; the source lost just before tick lost_at (None: never).
    The frames go on after it: a source that delivers again is not trusted."""
    config, show = sample_show
    loud, onset = live
    with Engine(config, show, follow=True, record=True, on_lost=on_lost) as e:
        for k in range(show.n_ticks):
            if k == lost_at:
                e.source_lost("the stream ended by itself")
                e.source_lost("a second report")
            if k < len(loud) and np.isfinite(loud[k]):
                e.push_loudness(float(loud[k]), float(onset[k]))
            e.step(1)
        assert e.source_lost_reason == (None if lost_at is None else "the stream ended by itself")
        return e.records()


@pytest.fixture(scope="module", params=["flywheel", "hold"])
def runs(request, sample_show, live):
    return request.param, run(sample_show, live, request.param), run(sample_show, live, request.param, LOST_AT)


def test_the_flag_is_a_bit_of_its_own():
    others = [getattr(_core, n) for n in dir(_core) if n.startswith("FLAG_") and n != "FLAG_SOURCE_LOST"]
    assert bin(FLAG_SOURCE_LOST).count("1") == 1 and all(f & FLAG_SOURCE_LOST == 0 for f in others)


def test_flagged_from_the_loss_to_the_end_and_not_before(runs):
    on_lost, kept, lost = runs
    assert not np.any(kept["flags"] & FLAG_SOURCE_LOST)
    flagged = (lost["flags"] & FLAG_SOURCE_LOST) != 0
    first = int(np.argmax(flagged))
    assert LOST_AT <= first <= LOST_AT + 1, first
    assert np.all(flagged[first:]) and not np.any(flagged[:first])
    assert np.all(lost["flags"][first:] & FLAG_UNFOLLOWED), on_lost
    # the follower was following; before the loss the show ran as without it
    assert lost["follow_state"][first - 1] == LOCKED
    for name in ("position", "rate", "follow_state", "flags", "command"):
        np.testing.assert_array_equal(lost[name][:first], kept[name][:first], err_msg=name)
    # the summary says when and what on_lost did
    s = follow_share(lost)
    assert s.source_lost == first and s.searching >= len(lost) - first
    line = share_line(s, 0.02, on_lost).splitlines()[-1]
    assert line.startswith(f"  live source lost at show time {first * 0.02:.2f} s: not followed"), line
    assert f"on_lost {on_lost}: " + ("the figure held the show at" if on_lost == "hold"
                                     else "the show played on at rate 1.0") in line, line


def test_on_lost_applies_at_once(runs):
    on_lost, _, r = runs
    first = int(np.argmax((r["flags"] & FLAG_SOURCE_LOST) != 0))
    before_p, before_r = r["position"][first - 1], r["rate"][first - 1]
    assert 1.0 < before_r < 1.06, before_r                  # the tape runs 3 % fast
    if on_lost == "hold":
        assert np.all(r["position"][first:] == before_p) and np.all(r["rate"][first:] == 0.0)
        # the figure comes to rest there: the target steps as the lead drops
        # with the rate, and the limits take a few seconds on this show
        commands = r["command"][first + 400:]
        assert np.ptp(commands, axis=0).max() < 1e-9, np.ptp(commands, axis=0)
    else:
        assert np.all(r["rate"][first:] == before_r)
        last = len(r) - 1
        running = r["position"][first - 1:] < last          # until the show's end holds it
        steps = np.diff(r["position"][first - 1:])[running[1:]]
        assert len(steps) > 500
        np.testing.assert_allclose(steps, before_r, rtol=0, atol=1e-9)
        assert r["position"][-1] == last
