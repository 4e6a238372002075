"""``marionette bench bands``: does a short stretch of live music tell its
own place in the piece from every other place? Broadband loudness against
band loudness (marionette/music/bands.py), on the decks of ``bench sync``.

This measures the feature alone, before any tracker: what the cue needs
(0.5 s of music that tells a bar from its repeat) and what a search needs.
For each synthesized piece of ``bench sync`` and each of its scenarios
without a pause or a jump (fast, slow-room: a room and drift; noisy: 10 dB
SNR; four seed sets), WINDOWS live windows of 0.5, 1 and 2 s at random
live times (fixed seed). A window's live frames are put on the stored
grid by the deck's true warp (so rate errors play no part), each band's
level in dB is floored RANGE_DB under that band's 99th percentile over the
recording, and the joint correlation (`bands.window_correlation`: each
band's mean over the window out, one correlation over all bands) is taken
at every offset of the stored piece. Figures per feature and window:

- identified: the share of windows whose best offset within TRUE_REACH
  frames of the truth beats every offset more than AWAY_S away;
- lead_z: the median lead of that best true offset over the best other
  place, in Fisher z (the margin a lock rule can ask for);
- true_corr: the median correlation at the true place;
- identified_clean: the share identified when the piece is heard exactly
  as stored (no deck): where it falls short, the music repeats itself
  exactly (the synthesizer loops bars), and no feature can do better.

Features: "loudness" (the broadband feature the follower uses today),
and band loudness with 1, 4, 6 (the default), 8 and 12 bands.

Then the cue's decision on each feature (marionette/bench/bands_cue.py):
how soon a rule that fits lines through the cue locks on the top decks,
and whether it locks on the wrong-cue decks.
"""
from __future__ import annotations

import json
import sys
import zlib

import numpy as np

from marionette.bench import bands_cue
from marionette.bench._machine import describe, machine_info
from marionette.bench.sync import PIECES, SEED, SEEDS, scenarios
from marionette.cli.options import Number
from marionette.music.bands import bands, correlations, fisher
from marionette.music.feature import FRAME_PERIOD, loudness
from marionette.sim.music import synthesize
from marionette.sim.tape import play

T = FRAME_PERIOD            # [s]
WINDOWS = 40                # live windows per deck and length [1]
WINDOW_S = (0.5, 1.0, 2.0)  # window lengths [s]
RANGE_DB = 30.0             # band levels floored this far under the band's 99th percentile [dB]
TRUE_REACH = 2              # the true place: within this many frames of the truth [frames]
AWAY_S = 0.5                # another place: further than this from the truth [s]
BAND_COUNTS = (1, 4, 6, 8, 12)  # band loudness variants measured [1]
TIE = 1e-9                  # a place beats another by more than rounding [1]


def level_db(feature: np.ndarray) -> np.ndarray:
    """Frames (n,) or (n, bands) of linear level as dB, each band floored
    RANGE_DB under its own 99th percentile; shape (n, bands)."""
    x = np.asarray(feature, dtype=np.float64)
    x = x[:, None] if x.ndim == 1 else x
    top = np.percentile(x, 99, axis=0)
    return 20.0 * np.log10(np.maximum(x, top * 10.0 ** (-RANGE_DB / 20.0)) + 1e-12)


def on_stored_grid(live_db: np.ndarray, positions: np.ndarray) -> tuple[int, np.ndarray]:
    """The live frames (m, bands) heard at stored positions [frames],
    increasing, interpolated onto the whole stored frames between the first
    and last: (first stored frame, rows)."""
    first, last = int(np.ceil(positions[0])), int(np.floor(positions[-1]))
    grid = np.arange(first, last + 1)
    rows = np.stack([np.interp(grid, positions, live_db[:, b]) for b in range(live_db.shape[1])], axis=1)
    return first, rows


def measure_deck(stored_db: np.ndarray, live_db: np.ndarray, truth: np.ndarray, rng) -> dict:
    """Per window length: (identified, lead_z, true_corr) lists over WINDOWS windows."""
    out = {}
    n_live = min(len(live_db), len(truth))
    away = int(round(AWAY_S / T))
    for seconds in WINDOW_S:
        m = int(round(seconds / T))
        rows = []
        for k in rng.integers(0, max(1, n_live - m), WINDOWS):
            pos = truth[k:k + m] / T                                # the stored frame each live frame heard
            if np.any(np.diff(pos) <= 0):
                continue
            first, window = on_stored_grid(live_db[k:k + m], pos)
            if len(window) < m // 2 or first < 0:
                continue
            c = correlations(window, stored_db)
            if not np.isfinite(c).any():
                continue
            off = np.arange(len(c)) - first
            near = np.abs(off) <= TRUE_REACH
            far = np.abs(off) > away
            true = np.nanmax(c[near]) if np.isfinite(c[near]).any() else np.nan
            other = np.nanmax(c[far]) if np.isfinite(c[far]).any() else -1.0
            if np.isnan(true):
                continue
            rows.append((true > other + TIE, float(fisher(true) - fisher(other)), float(true)))
        out[seconds] = rows
    return out


def collect(seeds: int = SEEDS, seed: int = SEED, quick: bool = False, progress=None) -> list[dict]:
    """One result per (feature, window length) with the documented keys."""
    features = {"loudness": lambda x, fs: loudness(x, fs)}
    for n in BAND_COUNTS:
        features[f"bands{n}"] = (lambda n: lambda x, fs: bands(x, fs, n_bands=n))(n)
    pieces = {style: synthesize(style, seed=s) for style, s in (PIECES[:1] if quick else PIECES)}
    # scenarios() draws for every piece; the quick run keeps the first piece's
    durations = {k: pieces[k].duration if k in pieces else 60.0 for k, _ in PIECES}
    stored = {(k, f): level_db(fn(p.samples, p.sample_rate)) for k, p in pieces.items()
              for f, fn in features.items()}
    acc = {(f, s): [] for f in features for s in WINDOW_S}
    ceiling = {(f, s): [] for f in features for s in WINDOW_S}
    for (k, f), db in stored.items():       # the piece heard as stored: only its own repeats confuse
        rng = np.random.default_rng((seed, zlib.crc32(k.encode()), 8))
        for secs, rows in measure_deck(db, db, np.arange(len(db)) * T, rng).items():
            ceiling[f, secs] += rows
    for s in range(seed, seed + (1 if quick else seeds)):
        for sc in scenarios(durations, 30.0 if quick else None, False, s):
            if sc.piece not in pieces or sc.deck.pauses or sc.deck.jump:
                continue
            played = play(pieces[sc.piece].samples, pieces[sc.piece].sample_rate, sc.deck)
            for f, fn in features.items():
                live_db = level_db(fn(played.samples, played.sample_rate))
                rng = np.random.default_rng((s, zlib.crc32(sc.name.encode()), 7))   # the same windows per feature
                for secs, rows in measure_deck(stored[sc.piece, f], live_db, played.truth, rng).items():
                    acc[f, secs] += rows
            if progress:
                progress(f"{sc.name}@{s}")
    per_deck = bands_cue.collect(pieces, stored, features, range(seed, seed + (1 if quick else seeds)),
                                 level_db, progress)
    machine = machine_info()
    results = []
    for (f, secs), rows in acc.items():
        ok = np.array([r[0] for r in rows], dtype=bool)
        lead = np.array([r[1] for r in rows])
        true = np.array([r[2] for r in rows])
        clean = np.array([r[0] for r in ceiling[f, secs]], dtype=bool)
        results.append({"section": "identify", "feature": f, "window_s": secs, "windows": len(rows),
                        "identified_clean": float(clean.mean()) if len(clean) else float("nan"),
                        "identified": float(ok.mean()) if len(ok) else float("nan"),
                        "lead_z_median": float(np.median(lead)) if len(lead) else float("nan"),
                        "lead_z_p10": float(np.percentile(lead, 10)) if len(lead) else float("nan"),
                        "true_corr_median": float(np.median(true)) if len(true) else float("nan"),
                        "machine": machine})
    results += [{**r, "machine": machine} for r in bands_cue.summarize(per_deck, features, fisher)]
    return results


def format_table(results: list[dict]) -> str:
    lines = ["what 0.5-2 s of live music tells apart (identified: its true place beats every other; "
             "clean: the same, heard as stored)",
             f"{'feature':<10} {'window_s':>8} {'windows':>7} {'identified':>10} {'clean':>6} "
             f"{'lead_z med':>10} {'lead_z p10':>10} {'true_corr':>9}"]
    for r in (r for r in results if r["section"] == "identify"):
        lines.append(f"{r['feature']:<10} {r['window_s']:>8g} {r['windows']:>7d} {r['identified']:>10.1%} {r['identified_clean']:>6.0%} "
                     f"{r['lead_z_median']:>10.2f} {r['lead_z_p10']:>10.2f} {r['true_corr_median']:>9.2f}")
    cue = [r for r in results if r["section"] == "cue"]
    if cue:
        lines += ["", f"the cue's decision (a line through the cue beats every other place by lead_z; "
                      f"top decks: {cue[0]['decks_top']}, wrong-cue decks: {cue[0]['decks_wrong']})",
                  f"{'feature':<10} {'lead_z':>6} {'locked by 0.5 s':>15} {'lock_s med':>10} "
                  f"{'bad locks':>9} {'false (wrong cue)':>17}"]
        for r in cue:
            lines.append(f"{r['feature']:<10} {r['lead_z']:>6.1f} {r['locked_by_0_5s']:>15.0%} "
                         f"{r['lock_s_median']:>10.2f} {r['bad_locks']:>9d} {r['wrong_false_locks']:>17d}")
    if results:
        lines.append(describe(results[0]["machine"]))
    return "\n".join(lines)


def register(sub) -> None:
    parser = sub.add_parser("bands", help="what 0.5-2 s of live music tells apart: loudness against bands",
                            description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true",
                        help="print a JSON list, one object per feature and window, then per feature and rule")
    parser.add_argument("--seeds", type=Number(int, 1), default=SEEDS, metavar="N",
                        help=f"sets of scenarios (default {SEEDS})")
    parser.add_argument("--quick", action="store_true", help="one piece, one seed, 30 s decks (smoke test)")


def run(args) -> int:
    progress = None if args.json else (lambda msg: print(f"  {msg}", file=sys.stderr, flush=True))
    results = collect(seeds=args.seeds, quick=args.quick, progress=progress)
    print(json.dumps(results, indent=1) if args.json else format_table(results))
    return 0           # no targets: a measurement for choosing the feature


def main(argv=None) -> int:
    """``python -m marionette.bench.bands``: as ``marionette bench bands``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "bands", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
