"""``marionette sync-sim``: music following offline, tick by tick, as at the show.

    marionette sync-sim --taught TAUGHT.wav --live LIVE.wav --out TRACK.csv
                        [--mode smooth|paper] [--truth TRUTH.csv] [--config FIGURE.toml]
                        [--loudness-only]

The taught recording (or a show file, whose stored loudness, onsets and
band levels the engine follows) gives the stored loudness, onset strength
and band levels (one frame each per tick, marionette/music/feature.py and
bands.py; a show without bands: none), the live recording the live frames
(--loudness-only: the live loudness alone, as one-band servo nodes measure
it; the tracker then works without onsets and bands, as the engine does
on such nodes' LOUDNESS frames); the C follower runs its tick (mar_follow_tick, the same
code the engine runs in its tick) once per tick: tick k has heard the live
audio up to k * T, so it gets live frame k - 1 (tick 0 gets none), and
`marionette play --music` feeds the engine the same way, so the two give
the same track bit for bit. TRACK.csv has one row per tick:

    tick,time_s,position_s,rate,confidence,state

time_s = k * T [s] (live time), position_s = where in the taught music the
live music is at that moment [s], rate [1], confidence [0..1], state
(searching, locked, holding, paused). With --truth (a CSV with the columns
tick,position_s) it prints the accuracy: the share of ticks within 20, 50
and 200 ms of the truth, the median and the 95th percentile of the error [ms].
"""
from __future__ import annotations

import argparse
import csv
import io
import math
from pathlib import Path

import numpy as np

from marionette.cli.options import input_file, output_file
from marionette.config import FOLLOW_MODES, load_config
from marionette.errors import MarionetteError
from marionette.music.bands import wav_music_frames
from marionette.music.feature import wav_frames, wav_loudness
from marionette.music.follower import DEFAULT_START, STATES, Follower, cue_ticks, sync_ticks
from marionette.show import load_show
from marionette.textfile import read_text


class SyncSimError(MarionetteError, ValueError):
    """A sync-sim input (truth file, output path) is unusable."""


def read_truth(path) -> dict[int, float]:
    """tick -> position_s [s] from a CSV with the header tick,position_s."""
    path = Path(path)
    try:
        text = read_text(path, SyncSimError)
    except FileNotFoundError:
        raise SyncSimError(f"{path}: no such truth file") from None
    truth: dict[int, float] = {}
    rows = csv.reader(io.StringIO(text, newline=""))
    header = next(rows, None)
    if header is None or [h.strip() for h in header[:2]] != ["tick", "position_s"]:
        raise SyncSimError(f"{path}:1: expected the header 'tick,position_s', found {header!r}")
    for line, row in enumerate(rows, start=2):
        if not row or not "".join(row).strip():
            continue
        if len(row) < 2:
            raise SyncSimError(f"{path}:{line}: expected 'tick,position_s', found {','.join(row)!r}")
        try:
            tick = int(row[0])
        except ValueError:
            raise SyncSimError(f"{path}:{line}: tick {row[0]!r} is not an integer") from None
        try:
            pos = float(row[1])
        except ValueError:
            raise SyncSimError(f"{path}:{line}: position_s {row[1]!r} is not a number") from None
        if tick < 0 or not math.isfinite(pos):
            raise SyncSimError(f"{path}:{line}: tick {tick} / position_s {pos!r}: the tick must "
                               "be >= 0 and the position finite")
        truth[tick] = pos
    if not truth:
        raise SyncSimError(f"{path}: no rows")
    return truth


def accuracy(errors_s: np.ndarray) -> dict:
    """Share within 20/50/200 ms [1], median and p95 of |error| [ms]."""
    e = np.abs(np.asarray(errors_s, dtype=float))
    if len(e) == 0:
        return {"ticks": 0, "within20": float("nan"), "within50": float("nan"),
                "within200": float("nan"), "median_ms": float("nan"), "p95_ms": float("nan")}
    return {"ticks": int(len(e)), "within20": float(np.mean(e <= 0.020)),
            "within50": float(np.mean(e <= 0.050)), "within200": float(np.mean(e <= 0.200)),
            "median_ms": float(np.median(e) * 1e3), "p95_ms": float(np.quantile(e, 0.95) * 1e3)}


def taught_frames(taught, period: float):
    """The stored loudness, onsets [dB] and band levels (each None when not
    stored) the follower compares with: from a show file (.npz, .csv: what
    the engine follows at the show) or from the taught recording (WAV)."""
    if Path(taught).suffix in (".npz", ".csv"):
        show = load_show(taught)
        if abs(show.tick_period - period) > 1e-12:
            raise SyncSimError(f"{taught}: tick period {show.tick_period} s, the figure's is {period} s")
        return show.loudness, show.onsets, show.bands
    return wav_music_frames(taught, period)


def simulate(taught, live, mode: str = "smooth", config=None, live_onsets: bool = True,
             start: float | None = DEFAULT_START):
    """Runs the follower over two recordings; returns (track, period [s], follower).
    live_onsets False: the live frames carry no onset (a node's LOUDNESS);
    start: where the live music starts in the taught music [s] (the cue, as
    Engine(follow_start=...)), None: unknown."""
    period = config.tick_period if config is not None else 0.020
    settings = config.follow if config is not None else None
    stored, stored_onsets, stored_bands = taught_frames(taught, period)
    live_bands = None
    if live_onsets and stored_bands is not None:
        frames, onsets, rows = wav_music_frames(live, period)
        live_bands = sync_ticks(rows)
    elif live_onsets:
        frames, onsets = wav_frames(live, period)
    else:                       # as a one-band node measures it: no onset, no bands
        frames = wav_loudness(live, period)
        onsets = np.full(len(frames), np.nan)
    if len(stored) < 2:
        raise SyncSimError(f"{taught}: shorter than two ticks ({len(stored)} frames)")
    follower = Follower(stored, settings, period, onset=stored_onsets, bands=stored_bands, mode=mode)
    if start is not None:
        follower.cue(cue_ticks(start, len(stored), period, "--start"))
    track = follower.run(sync_ticks(frames), sync_ticks(onsets), bands=live_bands)
    return track, period, follower


def write_track(path, track, period: float) -> None:
    ticks = np.arange(len(track.position))
    try:
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["tick", "time_s", "position_s", "rate", "confidence", "state"])
            for k in ticks:
                w.writerow([int(k), f"{k * period:.3f}", f"{track.position[k] * period:.6f}",
                            f"{track.rate[k]:.6f}", f"{track.confidence[k]:.4f}",
                            STATES[track.state[k]]])
    except OSError as exc:
        raise SyncSimError(f"{path}: cannot write the track: {exc.strerror}") from None


def run(args) -> int:
    config = load_config(args.config) if args.config else None
    track, period, follower = simulate(args.taught, args.live, args.mode, config,
                                       live_onsets=not args.loudness_only, start=args.start)
    write_track(args.out, track, period)
    n = len(track.position)
    locked = np.flatnonzero(track.state == STATES.index("locked"))
    first = f"{locked[0] * period:.2f} s" if len(locked) else "never"
    shares = ", ".join(f"{name} {np.mean(track.state == i):.0%}" for i, name in enumerate(STATES))
    c = follower.counters()
    print(f"sync-sim ({args.mode}): {n} ticks ({n * period:.2f} s of live audio) -> {args.out}")
    print(f"  first lock {first}; states: {shares}")
    print(f"  locks {c['locks']}, pauses {c['pauses']}, resumes {c['resumes']}, "
          f"measurements {c['measurements']}, missing frames {c['missing']}")
    if args.truth:
        truth = read_truth(args.truth)
        ticks = np.array(sorted(k for k in truth if k < n), dtype=int)
        if len(ticks) == 0:
            raise SyncSimError(f"{args.truth}: no tick below {n}, the length of the track")
        err = track.position[ticks] * period - np.array([truth[k] for k in ticks])
        for label, sel in (("all truth ticks", np.ones(len(ticks), bool)),
                           ("after the first lock", ticks >= (locked[0] if len(locked) else n))):
            a = accuracy(err[sel])
            if a["ticks"] == 0:
                print(f"  accuracy, {label}: no ticks")
                continue
            print(f"  accuracy, {label} ({a['ticks']} ticks): within 20 ms {a['within20']:.1%}, "
                  f"50 ms {a['within50']:.1%}, 200 ms {a['within200']:.1%}; "
                  f"median {a['median_ms']:.1f} ms, p95 {a['p95_ms']:.1f} ms")
    return 0


def start_time(text: str) -> float | None:
    """--start: SECONDS into the taught music, or 'unknown' (None)."""
    if text.strip().lower() == "unknown":
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither seconds nor 'unknown'") from None
    if not (math.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0 seconds, or 'unknown'")
    return value


def add_start_argument(p) -> None:
    p.add_argument("--start", type=start_time, default=DEFAULT_START, metavar="SECONDS|unknown",
                   help=f"where in the taught music the live music starts (a cue; default "
                        f"{DEFAULT_START:g}, the top): wait there through the silence, play from "
                        f"the music's onset; 'unknown': search the whole piece")


def register(sub) -> None:
    p = sub.add_parser("sync-sim", help="follow a live recording against a taught one, offline",
                       description="Run the music follower offline, tick by tick as at the show, "
                       "over a taught recording (or a show's stored loudness) and a live one; "
                       "write the track (where in the taught music the live music is, per tick) "
                       "and, with --truth, print its accuracy (docs/music.md).")
    p.add_argument("--taught", required=True, type=input_file,
                   help="the music as taught (WAV), or a show (.npz, .csv) whose stored loudness "
                        "the engine would follow")
    p.add_argument("--live", required=True, type=input_file,
                   help="the music as played at the show (WAV)")
    p.add_argument("--out", required=True, type=output_file,
                   help="track to write (CSV, one row per tick)")
    p.add_argument("--mode", choices=FOLLOW_MODES, default="smooth",
                   help="smooth (fractional rate, default) or paper (double or skip a sample)")
    p.add_argument("--truth", type=input_file,
                   help="CSV tick,position_s: print the accuracy against it")
    p.add_argument("--config", type=input_file,
                   help="figure TOML for the tick period and [follow] settings")
    add_start_argument(p)
    p.add_argument("--loudness-only", action="store_true",
                   help="live frames without onsets and bands, as one-band servo nodes send them "
                        "(LOUDNESS)")
    p.set_defaults(run=run)
