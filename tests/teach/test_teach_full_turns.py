"""A dancer who turns freely: the rotation folded into the axis's limits by whole turns."""
import dataclasses
import re

import numpy as np
import pytest

from marionette.config import load_config
from marionette.show import load_show
from marionette.teach.axis_map import TURN, fold_turns, map_axes, unwind
from marionette.teach.camera_file import write_cameras
from marionette.teach.make_sample import sample_dance, write_sample
from marionette.teach.recording import write_recording
from marionette.teach.settings import load_settings
from marionette.teach.synthetic import synthetic_recording

from conftest import run_cli

SEED = 7070


def fewest_wraps(angle, lo, hi):
    """The least number of changes of whole turns keeping every sample in [lo, hi],
    by dynamic programming over every number of turns that can occur."""
    fewest = np.ceil((lo - angle) / TURN).astype(int)
    most = np.floor((hi - angle) / TURN).astype(int)
    turns = np.arange(fewest.min(), most.max() + 1)
    cost = np.where((turns >= fewest[0]) & (turns <= most[0]), 0, 10**9)
    for k in range(1, angle.size):
        cost = np.minimum(cost, cost.min() + 1)
        cost = np.where((turns >= fewest[k]) & (turns <= most[k]), cost, 10**9)
    return int(cost.min())


def test_fold_takes_the_fewest_wraps_and_stays_in_range():
    """300 random rotations on the 20 ms tick (random walks in speed, up to 6 turns),
    ranges of one to two turns: the fold is the rotation plus whole turns, inside the
    range, changing at as few samples as the dynamic programme finds."""
    rng = np.random.default_rng(SEED)
    for _ in range(300):
        n = int(rng.integers(2, 1500))
        speed = np.cumsum(rng.normal(0.0, 0.05, n)) + rng.uniform(-2.0, 2.0)   # [rad/s]
        angle = rng.uniform(-10, 10) + np.cumsum(speed) * 0.02                  # [rad]
        lo = rng.uniform(-4.0, 0.0)
        hi = lo + TURN * rng.uniform(1.0001, 2.0)
        fold = fold_turns(angle, lo, hi)
        assert np.all((fold.values >= lo) & (fold.values <= hi))
        np.testing.assert_allclose(fold.values, angle + TURN * fold.turns, atol=1e-9)
        assert fold.wraps.size == fewest_wraps(angle, lo, hi)
        assert set(np.flatnonzero(np.diff(fold.turns)) + 1) == set(fold.wraps)
        if hi - lo < 1.5 * TURN:                 # one turn back per wrap
            assert np.all(np.abs(np.diff(fold.turns)) <= 1)


def test_fold_leaves_a_rotation_that_fits_alone():
    angle = 3.0 * np.sin(np.linspace(0.0, 20.0, 500))
    fold = fold_turns(angle, -np.pi, np.pi)
    assert fold.wraps.size == 0 and np.all(fold.turns == 0)
    np.testing.assert_array_equal(fold.values, angle)
    shifted = fold_turns(angle + 2 * TURN, -np.pi, np.pi)        # two turns ahead: back by two
    assert shifted.wraps.size == 0 and np.all(shifted.turns == -2)
    with pytest.raises(ValueError, match="less than a full turn"):
        fold_turns(angle, -3.0, 3.0)


def test_unwind_turns_back_in_a_straight_run_within_the_speed():
    """A rotation turning at 1 rad/s folded into one turn: each jump becomes a straight
    run back at the speed given, ending on the folded rotation, inside the range."""
    dt, speed = 0.02, 1.2                               # [s], [rad/s]
    angle = 1.0 * np.arange(1500) * dt                  # 30 s at 1 rad/s [rad]
    fold = fold_turns(angle, -np.pi, np.pi)
    out = unwind(fold.values, fold.wraps, lambda d: speed * d, dt)
    assert fold.wraps.size == 5                         # at pi, 3 pi, ..., 9 pi
    assert np.all((out >= -np.pi) & (out <= np.pi))
    step = np.diff(out)
    assert np.all(step <= 1.0 * dt + 1e-12) and np.all(step >= -speed * dt - 1e-12)
    back = np.r_[step < 0, False]                       # sample k moves back to k + 1
    starts = np.flatnonzero(np.diff(back.astype(int)) == 1) + 1
    ends = np.flatnonzero(np.diff(back.astype(int)) == -1) + 1
    assert np.array_equal(starts, fold.wraps - 1)
    # back at speed + 1 rad/s against the turning: 2 pi / 2.2 s, 143 ticks; the last
    # one is cut by the end, at full speed
    np.testing.assert_allclose(ends[:-1] - starts[:-1], TURN / (speed + 1.0) / dt, atol=1.0)
    assert out.size - fold.wraps[-1] < 143 and np.all(np.isclose(step[fold.wraps[-1] - 1:], -speed * dt))
    away = ~back[:fold.wraps[-1]]                       # before the cut run back
    np.testing.assert_allclose(out[:fold.wraps[-1]][away], fold.values[:fold.wraps[-1]][away])


def test_unwind_reaches_a_top_late_that_the_rise_cannot_reach_in_time():
    """A rotation turning at 2 rad/s from rest, folded into one turn, with runs of at
    most 1.5 rad/s: the rise to the first wrap's top leaves at the sample departs names
    and reaches the top later, in a straight run within that speed; the turn back starts
    there; every sample stays inside the range."""
    dt, speed = 0.02, 1.5                               # [s], [rad/s]
    angle = -3.0 + 2.0 * np.arange(1000) * dt           # [rad]
    fold = fold_turns(angle, -np.pi, np.pi)
    departs = []
    out = unwind(fold.values, fold.wraps, lambda d: speed * d, dt,
                 lambda x: departs.append(len(x)) or 0)
    assert np.all((out >= -np.pi) & (out <= np.pi))
    k = fold.wraps[0]
    top = int(np.argmax(out[:fold.wraps[1]]))
    assert departs[0] == k and out[top] == fold.values[k - 1]
    # 6.14 rad from the first sample at 1.5 rad/s: 205 samples, not the dancer's 154
    assert top == int(np.ceil((fold.values[k - 1] - out[0]) / (speed * dt))) > k - 1
    assert np.all(np.abs(np.diff(out[:top + 1])) <= speed * dt + 1e-12)
    assert np.all(np.diff(out[top:top + 10]) < 0)       # then back


def test_a_dance_that_turns_twice_goes_through_teach(tmp_path):
    """The teach simulator's dance turning twice in 10 s (plus the sample dance's yaw
    swing), true cameras, the bundled figure and settings: teach folds rotate_z by
    whole turns, warns on stderr with the number of wraps (the fewest), and away from
    the turns back the unshaped show is the true yaw modulo full turns within 0.05 rad;
    the default (shaped) run stays inside the limits and cuts no turn back short."""
    duration = 10.0                                     # [s]
    write_sample(tmp_path, seed=SEED, duration=duration)   # music.wav, markers unused
    dance = sample_dance(np.random.default_rng(SEED), duration)
    dance.rate[5] = 2 * TURN / duration                 # two turns [rad/s]
    dance.amplitude[5] *= 0.3                           # and a yaw swing up to 0.47 rad
    syn = synthetic_recording(SEED, duration, dance=dance)
    write_recording(tmp_path / "recording.csv", syn.recording, n_cameras=len(syn.cameras))
    write_cameras(tmp_path / "cameras.toml", syn.cameras)
    args = ["teach", tmp_path / "recording.csv", "--cameras", tmp_path / "cameras.toml",
            "--music", tmp_path / "music.wav"]

    result = run_cli(*args, "-o", tmp_path / "unshaped.npz", "--no-shape")
    assert result.returncode == 0, result.stderr
    config = load_config()
    j = config.axis_names.index("rotate_z")
    axis = config.axes[j]
    rot = load_show(tmp_path / "unshaped.npz", config).positions[j]
    assert rot.min() >= axis.min and rot.max() <= axis.max
    t = np.arange(rot.size) * config.tick_period
    settings = load_settings(None)
    truth = map_axes(dance.pose(t), dataclasses.replace(settings.axis_map, z_ref=1.3))["rotate_z"]
    wraps = fewest_wraps(truth, axis.min, axis.max)
    assert wraps == 2 and "2 wrap(s)" in result.stderr and "'rotate_z'" in result.stderr
    # away from the turns back, the show is the true yaw modulo full turns
    off = np.abs((rot - truth + np.pi) % TURN - np.pi)          # [rad]
    away = off < 0.05
    inside = (t > 1.0) & (t < t[-1] - 1.0)              # the FIR pads the ends
    # one run off the dancer's yaw per wrap (a rise to a late top and the turn back;
    # the first rise from the show's start), each but the last (still turning back at
    # 9 s) ending where the figure meets the dancer's yaw again
    edges = np.diff(np.r_[1, away[inside].astype(int)])
    assert np.count_nonzero(edges == -1) == wraps and np.count_nonzero(edges == 1) == wraps - 1

    result = run_cli(*args, "-o", tmp_path / "shaped.npz", "--list-infeasible", "1000")
    assert result.returncode == 0, result.stderr
    rot = load_show(tmp_path / "shaped.npz", config).positions[j]
    assert rot.min() >= axis.min and rot.max() <= axis.max
    # each turn back's top is reached late rather than cut (the dancer turns faster
    # than the figure may): it lies within 1.5 s after its wrap, and the shaper cuts
    # it by less than 0.05 rad (by 1.2 rad when the turn back started at the wrap
    # itself). A climax of the dance after a turn back may still be cut: this one's
    # last, 0.37 rad (0.12 rad before), where the figure follows a dancer still
    # turning faster than it can
    wrap_s = [float(x) for x in re.search(r"\(at ([0-9., s]+)\)", result.stderr).group(1)
              .replace(" s", "").split(",")]
    short = {float(t): float(x) for t, x in
             re.findall(r"'rotate_z' at ([0-9.]+) s: short by ([0-9.e-]+) rad", result.stdout)}
    tops = [t for t in short if any(w <= t <= w + 1.5 for w in wrap_s)]
    assert len(wrap_s) == wraps and all(short[t] < 0.05 for t in tops), result.stdout
