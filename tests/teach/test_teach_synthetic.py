"""Synthetic ground-truth generator."""

import numpy as np

from marionette.teach.camera import project
from marionette.teach.rucksack import led_positions
from marionette.teach.synthetic import make_dance, synthetic_markers, synthetic_recording


def test_deterministic_given_seed():
    a = synthetic_recording(5, 6.0)
    b = synthetic_recording(5, 6.0)
    c = synthetic_recording(6, 6.0)
    for name in ("time_s", "camera", "led", "R", "T"):
        np.testing.assert_array_equal(getattr(a.recording, name), getattr(b.recording, name))
    assert len(a.recording) != len(c.recording) or not np.array_equal(a.recording.R, c.recording.R)


def test_strobe_sequence_quantisation_and_dropouts():
    syn = synthetic_recording(7, 30.0, dropout=0.05, shade_rate=0.0)
    rec = syn.recording
    np.testing.assert_allclose(syn.field_times, 0.02 * np.arange(1500), atol=1e-9)
    np.testing.assert_array_equal(syn.field_leds, np.arange(1500) % 4 + 1)
    field = np.round(rec.time_s / 0.02).astype(int)
    np.testing.assert_array_equal(rec.led, field % 4 + 1)          # 1, 2, 3, 4 per 20 ms
    np.testing.assert_array_equal(rec.R, np.round(rec.R))           # integer pixels
    assert np.all(np.diff(rec.time_s) >= 0)
    lost = 1 - len(rec) / (2 * 1500)
    assert 0.035 < lost < 0.065                                     # ~5 % requested


def test_noise_free_pixels_are_exact_projections():
    syn = synthetic_recording(8, 5.0, noise_px=0.0, quantize=False, dropout=0.0, shade_rate=0.0)
    rec = syn.recording
    field = np.round(rec.time_s / 0.02).astype(int)
    for cam_index, cam in enumerate(syn.cameras):
        sel = rec.camera == cam_index
        expect = project(cam, syn.field_points[field[sel]])
        np.testing.assert_allclose(np.c_[rec.R[sel], rec.T[sel]], expect, atol=1e-9)
    # the flashing LED is the dance's LED at that instant
    leds = led_positions(syn.dance.pose(syn.field_times), syn.b)
    np.testing.assert_allclose(syn.field_points, leds[np.arange(leds.shape[0]), syn.field_leds - 1])


def test_dance_stays_in_area_and_turns():
    for seed in range(10):
        dance = make_dance(np.random.default_rng(seed))
        t = np.arange(0, 60, 0.02)
        q = dance.pose(t)
        assert np.all(np.abs(q[:, :2]) <= 0.85 * 2.0 + 1e-12)
        assert np.all(np.abs(q[:, 3:5]) <= np.radians(6) + 1e-12)
        assert abs(q[-1, 5] - q[0, 5]) > 6 * 2 * np.pi                 # > 6 full turns in 60 s
        # velocity is the derivative of the pose
        h = 1e-6
        np.testing.assert_allclose(dance.velocity(t[:50]), (dance.pose(t[:50] + h) - dance.pose(t[:50] - h)) / (2 * h),
                                   atol=1e-6)


def test_markers_visible_and_noisy():
    from marionette.teach.synthetic import default_cameras

    cam = default_cameras()[0]
    X, pix = synthetic_markers(3, cam, n=50, noise_px=0.5)
    d = pix - project(cam, X)
    assert X.shape == (50, 3) and 0.35 < d.std() < 0.65
    assert np.all((pix > -2) & (pix < 514))
