"""The loudness feature (marionette.music.feature) and the live sound-card source
(marionette.music.sound_card).

The feature is the same at teach and show time: linear in the volume, the
same at any sample rate from 8 kHz up, framed on the 20 ms tick grid. The
onset strength beside it ignores the volume, marks a note's start and not
its end, and reads tape hiss as small. There
is no sound card on the test machines, so the live source is exercised with
a fake ``sounddevice`` module (its block stream, its device list) and with
no module at all.
"""
from __future__ import annotations

import struct
import sys
import types

import numpy as np
import pytest

from marionette.music import sound_card
from marionette.music.feature import (BAND, FRAME_PERIOD, AudioError, LoudnessMeter, OnsetMeter,
                                      loudness, onsets, read_wav, wav_frames, wav_loudness, write_wav)
from marionette.music.follower import Follower, sync_ticks

T = FRAME_PERIOD


def music(fs: float, seconds: float, seed: int) -> np.ndarray:
    """Tones in the band with stepped envelopes, evaluated at sample rate fs [Hz]."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * fs)) / fs
    x = np.zeros_like(t)
    for _ in range(12):
        f0 = rng.uniform(100.0, 3500.0)                                   # [Hz]
        on = rng.uniform(0.0, seconds, 2)
        env = ((t >= on.min()) & (t < on.max())) * np.exp(-(t - on.min()) / rng.uniform(0.05, 0.5))
        x += rng.uniform(0.02, 0.1) * env * np.sin(2 * np.pi * f0 * t + rng.uniform(0, 6.3))
    return x


def test_full_scale_sine_reads_one():
    for fs in (8000, 16000, 44100):
        t = np.arange(fs) / fs
        frames = loudness(np.sin(2 * np.pi * 1000.0 * t), fs)
        assert np.allclose(frames, 1.0, atol=0.02), fs
        if fs >= 16000:                      # above the band (4 kHz): nothing
            assert np.all(loudness(np.sin(2 * np.pi * 6000.0 * t), fs) < 0.02)


@pytest.mark.parametrize("seed", range(5))
def test_linear_in_the_volume(seed):
    x = music(16000, 3.0, seed)
    base = loudness(x, 16000)
    for gain_db in (-20.0, -6.0, 6.0, 20.0):
        g = 10 ** (gain_db / 20)
        assert np.allclose(loudness(g * x, 16000), g * base, rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("seed", range(8))
def test_the_same_at_any_sample_rate(seed):
    """The same music sampled at 8 to 48 kHz gives frames within 1 dB (where
    the music is not near silence)."""
    ref = loudness(music(16000, 4.0, seed), 16000)
    loud = ref > 0.05 * ref.max()
    for fs in (8000, 11025, 22050, 44100, 48000):
        frames = loudness(music(fs, 4.0, seed), fs)
        n = min(len(ref), len(frames))
        db = 20 * np.log10(frames[:n][loud[:n]] / ref[:n][loud[:n]])
        assert np.median(np.abs(db)) < 0.3 and np.max(np.abs(db)) < 2.0, (fs, np.max(np.abs(db)))


def test_frames_lie_on_the_tick_grid():
    """Frame k covers the samples [floor(k fs T), floor((k + 1) fs T)): a click
    at sample i lands in the frame that holds it, at any sample rate."""
    rng = np.random.default_rng(3)
    for fs in (8000, 11025, 22050, 44100):
        for i in rng.integers(0, int(1.9 * fs), 20):
            x = np.zeros(2 * fs)
            x[i] = 1.0
            frames = loudness(x, fs)
            starts = np.floor(np.arange(len(frames) + 1) * fs * T).astype(int)
            k = int(np.searchsorted(starts, i, side="right") - 1)
            assert int(np.argmax(frames)) == k and frames[k] > 0, (fs, i)
            assert np.count_nonzero(frames) == 1


def feed_in_blocks(meter, x, rng, longest: int) -> np.ndarray:
    """The meter's frames of x fed in random blocks of 1 to longest - 1 samples."""
    parts, i = [], 0
    while i < len(x):
        n = int(rng.integers(1, longest))
        parts.append(meter.feed(x[i:i + n]))
        i += n
    return np.concatenate(parts)


def test_streaming_in_any_blocks_equals_one_go():
    rng = np.random.default_rng(5)
    x = music(11025, 3.0, 1)
    whole = loudness(x, 11025)
    assert np.allclose(feed_in_blocks(LoudnessMeter(11025), x, rng, 700), whole, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("seed", range(5))
def test_onsets_ignore_the_volume_knob(seed):
    """The knob turns music and tape hiss alike (digital silence is another
    matter: a rise from it depends on the level, see OnsetMeter)."""
    x = music(16000, 3.0, seed) + 3e-3 * np.random.default_rng(seed).standard_normal(48000)
    base = onsets(x, 16000)
    assert base.max() > 3.0                                   # the notes start somewhere
    for gain_db in (-20.0, -6.0, 6.0, 20.0):
        assert np.allclose(onsets(10 ** (gain_db / 20) * x, 16000), base, rtol=0.0, atol=1e-6), gain_db


@pytest.mark.parametrize("seed", range(5))
def test_onsets_are_the_same_at_any_sample_rate(seed):
    ref = onsets(music(16000, 4.0, seed), 16000)
    for fs in (8000, 11025, 22050, 44100):
        frames = onsets(music(fs, 4.0, seed), fs)
        n = min(len(ref), len(frames))
        assert np.corrcoef(frames[:n], ref[:n])[0, 1] > 0.98, fs


def test_an_onset_marks_a_note_start_and_not_its_end():
    rng = np.random.default_rng(3)
    for case in range(8):
        fs = float(rng.choice([8000, 16000, 22050]))
        t = np.arange(int(2.0 * fs)) / fs
        on, off = rng.uniform(0.3, 0.8), rng.uniform(1.2, 1.6)                # [s]
        release = np.clip(1.0 - (t - off) / 0.1, 0.0, 1.0)                   # a 100 ms fade
        tone = 0.3 * np.sin(2 * np.pi * rng.uniform(200.0, 3000.0) * t) * release
        x = np.where(t >= on, tone, 0.0) + 1e-3 * rng.standard_normal(len(t))
        o = onsets(x, fs)
        k_on = int(on / T)                                     # the frame the tone starts in
        assert o[k_on:k_on + 2].max() > 10.0, case           # [dB]
        assert np.delete(o, [k_on, k_on + 1]).max() < 2.0, case


def test_hiss_reads_as_small_onsets():
    rng = np.random.default_rng(4)
    for fs in (8000, 11025, 16000, 44100):
        hiss = onsets(rng.standard_normal(int(10 * fs)) * 10 ** rng.uniform(-4, -1), fs)
        assert np.quantile(hiss[50:], 0.99) < 1.0 and np.median(hiss[50:]) < 0.3, fs     # [dB]


def test_onsets_stream_in_any_blocks_as_in_one_go(tmp_path):
    rng = np.random.default_rng(6)
    x = music(22050, 3.0, 2)
    assert np.allclose(feed_in_blocks(OnsetMeter(22050), x, rng, 900), onsets(x, 22050),
                       rtol=1e-12, atol=1e-12)
    write_wav(tmp_path / "m.wav", x, 22050)
    level, onset = wav_frames(tmp_path / "m.wav")
    assert len(level) == len(onset) == len(loudness(x, 22050))


def test_sample_rate_too_low_is_refused():
    with pytest.raises(AudioError, match="below"):
        LoudnessMeter(2 * BAND[1] - 1)


def test_wav_round_trip_and_errors(tmp_path):
    x = 0.5 * np.sin(2 * np.pi * 440 * np.arange(8000) / 8000)
    write_wav(tmp_path / "a.wav", x, 8000)
    y, fs = read_wav(tmp_path / "a.wav")
    assert fs == 8000 and np.max(np.abs(y - x)) < 1e-4
    assert np.allclose(wav_loudness(tmp_path / "a.wav"), loudness(x, 8000), rtol=1e-3)
    with pytest.raises(AudioError, match="no such audio file"):
        read_wav(tmp_path / "missing.wav")
    (tmp_path / "junk.wav").write_bytes(b"not a wav file")
    with pytest.raises(AudioError, match="junk.wav"):
        read_wav(tmp_path / "junk.wav")


def _riff(fmt: bytes, data: bytes) -> bytes:
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(data)) + data
    return b"RIFF" + struct.pack("<I", len(body)) + body


def test_24_bit_wave_format_extensible_is_read(tmp_path):
    """What most 24-bit recorders write: tag 0xFFFE, sub-format PCM; stereo."""
    rate = 16000
    x = 0.5 * np.sin(2 * np.pi * 440 * np.arange(rate) / rate)
    pcm = np.round(np.stack([x, -0.25 * x], axis=1) * (2**23 - 1)).astype("<i4")
    data = pcm.view(np.uint8).reshape(-1, 4)[:, :3].tobytes()          # little-endian 24 bit
    pcm_guid = struct.pack("<HHI", 1, 0, 0x00100000) + bytes.fromhex("800000aa00389b71")
    fmt = struct.pack("<HHIIHHHHI", 0xFFFE, 2, rate, rate * 6, 6, 24, 22, 24, 3) + pcm_guid
    path = tmp_path / "24bit.wav"
    path.write_bytes(_riff(fmt, data))
    y, fs = read_wav(path)
    assert fs == rate and y.shape == (rate, 2)
    assert np.max(np.abs(y[:, 0] - x)) < 2.0 ** -22 and np.max(np.abs(y[:, 1] + 0.25 * x)) < 2.0 ** -22
    path.write_bytes(_riff(fmt, data)[:-1000])          # cut short: the whole frames it holds
    assert read_wav(path)[0].shape == (rate - 167, 2)
    float_fmt = struct.pack("<HHIIHH", 3, 1, rate, rate * 4, 4, 32)
    path.write_bytes(_riff(float_fmt, x.astype("<f4").tobytes()))
    assert np.max(np.abs(read_wav(path)[0] - x)) < 1e-7


@pytest.mark.parametrize("content, said", [
    (b"", "empty file, not a WAV file"),
    (b"RIFF\x04\x00\x00\x00WAVE", "without a whole fmt chunk"),
    (_riff(struct.pack("<HHIIHH", 1, 1, 8000, 16000, 2, 16), b"")[:-8], "without a data chunk"),
    (_riff(struct.pack("<HHIIHH", 1, 0, 8000, 16000, 2, 16), b"\0\0"), "0 channels")])
def test_a_bad_wav_is_an_error_naming_the_file(content, said, tmp_path):
    path = tmp_path / "bad.wav"
    path.write_bytes(content)
    with pytest.raises(AudioError) as info:
        read_wav(path)
    assert str(info.value).startswith(str(path)) and said in str(info.value)


def test_follower_ignores_the_volume_knob():
    """The follower on a live copy at -20 dB and +20 dB: the same positions."""
    x = music(16000, 30.0, 9) + music(16000, 30.0, 10)
    stored = loudness(x, 16000)
    live = sync_ticks(stored[300:])
    base = Follower(stored)
    base.reset(300.0)
    ref = base.run(live)
    for g in (0.1, 10.0):
        f = Follower(stored)
        f.reset(300.0)
        track = f.run(live * g)
        assert np.allclose(track.position, ref.position, atol=1e-6)


# --- the live source, with a fake sounddevice ------------------------------------------------

class FakeStream:
    def __init__(self, sd, callback, blocksize, channels, **kw):
        self.sd, self.callback, self.blocksize, self.channels = sd, callback, blocksize, channels
        self.started = self.closed = False

    def start(self):
        self.started = True
        x = self.sd.signal
        for i in range(0, len(x) - self.blocksize + 1, self.blocksize):
            block = np.repeat(x[i:i + self.blocksize, None], self.channels, axis=1).astype(np.float32)
            self.callback(block, self.blocksize, None, None)

    def stop(self):
        self.started = False

    def close(self):
        self.closed = True


def fake_sounddevice(devices, signal=None, refuse=None):
    sd = types.ModuleType("sounddevice")
    sd.signal = signal if signal is not None else np.zeros(0)
    sd.streams = []

    def query_devices():
        if isinstance(devices, Exception):
            raise devices
        return devices

    def check_input_settings(device, channels, samplerate):
        if refuse:
            raise ValueError(refuse)

    def InputStream(**kw):
        s = FakeStream(sd, **kw)
        sd.streams.append(s)
        return s

    sd.query_devices, sd.check_input_settings, sd.InputStream = query_devices, check_input_settings, InputStream
    return sd


MIC = {"name": "USB Microphone", "max_input_channels": 2, "default_samplerate": 22050.0}
SPEAKER = {"name": "HDMI out", "max_input_channels": 0, "default_samplerate": 48000.0}


def test_live_source_gives_the_same_frames_as_the_file_path():
    x = music(22050, 2.0, 4)
    sd = fake_sounddevice([SPEAKER, MIC], signal=x)
    got = []
    with sound_card.SoundCard(got.append, device="usb", channels=2, sd=sd) as src:
        assert src.device["index"] == 1 and src.sample_rate == 22050.0
        assert sd.streams[0].blocksize == round(22050 * sound_card.BLOCK_PERIOD)
    assert sd.streams[0].closed
    expected = loudness(x[:len(x) // sd.streams[0].blocksize * sd.streams[0].blocksize], 22050)
    assert np.allclose(got, expected, rtol=1e-5, atol=1e-7)         # float32 blocks
    assert src.frames == len(got)


def test_no_sounddevice_package_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "sounddevice", None)            # import fails
    with pytest.raises(AudioError, match=r"pip install 'marionette\[audio\]'"):
        sound_card.SoundCard(print)


def test_no_input_device_is_a_clear_error():
    with pytest.raises(AudioError, match="no audio input device found"):
        sound_card.SoundCard(print, sd=fake_sounddevice([SPEAKER]))
    with pytest.raises(AudioError, match="cannot list audio devices"):
        sound_card.SoundCard(print, sd=fake_sounddevice(OSError("no PortAudio host")))
    with pytest.raises(AudioError, match="no audio input device 'studio'.*1: USB Microphone"):
        sound_card.SoundCard(print, device="studio", sd=fake_sounddevice([SPEAKER, MIC]))
    with pytest.raises(AudioError, match="no audio input device 7"):
        sound_card.SoundCard(print, device=7, sd=fake_sounddevice([SPEAKER, MIC]))


def test_unusable_settings_are_clear_errors():
    sd = fake_sounddevice([MIC], refuse="Invalid sample rate")
    with pytest.raises(AudioError, match="cannot record 1 channel.*Invalid sample rate"):
        sound_card.SoundCard(print, sample_rate=12345, sd=sd)
    with pytest.raises(AudioError, match="has 2 channel"):
        sound_card.SoundCard(print, channels=3, sd=fake_sounddevice([MIC]))
    with pytest.raises(AudioError, match="below"):
        sound_card.SoundCard(print, sample_rate=4000, sd=fake_sounddevice([MIC]))
