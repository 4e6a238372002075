"""One follower path: `marionette play --music` (the engine's tick) and
`marionette sync-sim` (mar_follow_tick offline) give the same track, bit for
bit, for the same show and the same live recording."""
import numpy as np
import pytest

from conftest import run_cli
from marionette._core import FLAG_END
from marionette.cli.sync_sim import simulate
from marionette.config import load_config
from marionette.music.bands import fit_frames, wav_bands
from marionette.music.feature import read_wav, wav_frames, write_wav
from marionette.recorder import read_flight_record
from marionette.show import Show, load_show
from marionette.sim.music import synthesize
from marionette.sim.tape import Deck, play
from marionette.teach.make_sample import sample_path

T = 0.020


def show_for(config, wav, tmp_path, bands=True):
    """A show for the bundled figure that stores the music's loudness,
    onsets and (bands: as teach makes it; else as an older show) band levels."""
    loud, onset = wav_frames(wav, T)
    home = np.array([[a.home for a in config.axes]]).T
    show = Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=np.repeat(home, len(loud), axis=1), loudness=loud, onsets=onset,
                bands=fit_frames(wav_bands(wav, T), len(loud)) if bands else None, tick_period=T)
    path = tmp_path / "show.npz"
    show.save(path)
    return path


def tape(samples, rate, deck, path):
    played = play(samples, rate, deck)
    write_wav(path, played.samples / max(1e-9, np.max(np.abs(played.samples))) * 0.5,
              int(played.sample_rate))
    return path


def assert_same_track(show, live, tmp_path):
    record = tmp_path / "flight.bin"
    result = run_cli("play", show, "--music", live, "--record", record)
    # a recording shorter than half the show leaves most of it unfollowed:
    # play then exits 1 and says so last (docs/music.md, on_lost)
    assert result.returncode == 0 or (result.returncode == 1 and result.stdout.splitlines()[-1]
                                      .startswith("NOT FOLLOWED")), result.stderr
    _, rec = read_flight_record(record)
    track, _, _ = simulate(show, live, config=load_config(None))
    n = len(rec)
    last = load_show(show).n_ticks - 1              # the engine holds at the show's last tick
    m = min(n, len(track.position))
    np.testing.assert_array_equal(rec["position"][:m], np.minimum(track.position[:m], last))
    np.testing.assert_array_equal(rec["rate"][:m], track.rate[:m])
    np.testing.assert_array_equal(rec["follow_state"][:m], track.state[:m])
    np.testing.assert_array_equal(rec["follow_confidence"][:m], track.confidence[:m])
    return track


@pytest.mark.parametrize("speed", [0.97, 0.99, 1.0, 1.01, 1.03])
def test_play_and_sync_sim_agree_on_the_bundled_sample(speed, tmp_path):
    config = load_config(None)
    music = sample_path("music.wav")
    show = show_for(config, music, tmp_path)
    samples, rate = read_wav(music)
    live = tape(samples, rate, Deck(speed=speed, snr_db=20.0, sample_rate=rate, seed=7),
                tmp_path / "live.wav")
    assert_same_track(show, live, tmp_path)


@pytest.mark.parametrize("bands", [True, False])
def test_play_and_sync_sim_agree_on_random_decks(bands, tmp_path):
    config = load_config(None)
    rng = np.random.default_rng(2026)
    for case in range(4):
        style = ["pop", "waltz", "techno", "ambient"][case]
        piece = synthesize(style, seed=int(rng.integers(1, 1000)))
        taught = tmp_path / f"taught{case}.wav"
        write_wav(taught, piece.samples, int(piece.sample_rate))
        show = show_for(config, taught, tmp_path, bands)
        deck = Deck(speed=rng.uniform(0.95, 1.05), wow=0.002, snr_db=rng.uniform(15, 30),
                    start=rng.uniform(0, 30), pauses=((rng.uniform(5, 10), rng.uniform(1, 3)),),
                    seconds=20.0, sample_rate=11025, seed=case)
        live = tape(piece.samples, piece.sample_rate, deck, tmp_path / f"live{case}.wav")
        assert_same_track(show, live, tmp_path)


def test_play_runs_to_the_end_of_the_show_at_any_speed(tmp_path):
    """Without --ticks, play --music runs until the show's end (FLAG_END):
    on a slow tape after more ticks than the show has (as long as the
    recording lasts), on a fast one after fewer."""
    config = load_config(None)
    samples, rate = read_wav(sample_path("music.wav"))
    show = show_for(config, sample_path("music.wav"), tmp_path)
    n = len(wav_frames(sample_path("music.wav"), T)[0])
    for speed in (0.94, 1.06):
        live = tape(samples, rate, Deck(speed=speed, snr_db=20, seed=3), tmp_path / f"live{speed}.wav")
        record = tmp_path / f"flight{speed}.bin"
        result = run_cli("play", show, "--music", live, "--record", record)
        assert result.returncode == 0, result.stderr
        _, rec = read_flight_record(record)
        if speed < 1:       # the recording ends a little before the show's end (within 0.2 s)
            assert len(rec) > n and rec["position"][-1] >= n - 1 - 10, (len(rec), rec["position"][-1])
        else:
            assert len(rec) < n and rec["flags"][-1] & FLAG_END, (len(rec), rec["flags"][-1])
