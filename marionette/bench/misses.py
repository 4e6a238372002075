"""``marionette bench misses``: where the cued top decks of ``bench sync`` lose their ticks.

    marionette bench misses [--seeds N] [--seed S] [--quick] [--model] [--json]

The same decks as ``bench sync``'s "cue at top" rows (the target decks of
the synthesized pieces, started at the top, cued there), the same frames
and follower, and the same measured ticks (from CUE_FROM_S after the
onset, without the AFTER_PAUSE_S after a resume and the AFTER_JUMP_S
after a jump). Each tick more than 50 ms off is put down to one cause:

- masked stop: the tape stands, and the live level over the MASK_BEFORE_S
  before the stop was within MASK_DB of the level during it: the music
  stood at the hiss (the volume knob turns both), so no frame shows the stop;
- seen stop: the tape stands, and the stop changed the level;
- relock after a resume / after a jump: from the event until the first
  tick within 50 ms again;
- elsewhere: the rest.

within50 is printed over the measured ticks and again without the masked
stops' ticks, the share that a follower could reach (docs/music.md,
"Stops that no frame shows").
"""
from __future__ import annotations

import json
import sys

import numpy as np

from marionette.bench import sync as bs
from marionette.cli.options import Number
from marionette.music.bands import bands, fit_frames
from marionette.music.feature import loudness, onsets
from marionette.music.follower import Follower
from marionette.sim.music import synthesize

T = bs.T                         # tick period [s]
MISS_S = 0.050                   # a tick further off than this is a miss [s]
MASK_BEFORE_S = 0.5              # the level before a stop is taken over this long [s]
MASK_DB = 3.0                    # a stop this little under the level before it is masked [dB]
CAUSES = ("masked stop", "seen stop", "relock after a resume", "relock after a jump", "elsewhere")


def masked_stops(level_db: np.ndarray, paused: np.ndarray) -> np.ndarray:
    """Per tick: the tape stands in a stop whose level is within MASK_DB of the level before it."""
    n = len(paused)
    out = np.zeros(n, bool)
    before = int(round(MASK_BEFORE_S / T))
    edges = np.diff(np.concatenate([[0], paused.astype(np.int8), [0]]))
    for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if s > 0 and np.median(level_db[max(0, s - before):s]) - np.median(level_db[s:e]) < MASK_DB:
            out[s:e] = True
    return out


def until_back(err: np.ndarray, t: np.ndarray, events) -> np.ndarray:
    """Per tick: after one of the events [s] and before the first tick within MISS_S since."""
    out = np.zeros(len(err), bool)
    for ev in events:
        after = np.flatnonzero((t >= ev) & (err <= MISS_S))
        out[(t >= ev) & (t < (t[after[0]] if len(after) else np.inf))] = True
    return out


def causes(err, t, played, level_db, measured) -> dict:
    """Missed measured ticks per cause (CAUSES), and the measured and masked-stop tick counts."""
    n = len(err)
    paused = played.paused[:n]
    masked = masked_stops(level_db, paused)
    left = measured & (err > MISS_S)
    out = {"ticks": int(measured.sum()), "masked_ticks": int((measured & masked).sum())}
    for cause, where in (("masked stop", masked), ("seen stop", paused),
                         ("relock after a resume", until_back(err, t, played.resumes)),
                         ("relock after a jump", until_back(err, t, played.jumps)),
                         ("elsewhere", np.ones(n, bool))):
        out[cause] = int((left & where).sum())
        left &= ~where
    return out


def cued_top_decks(durations: dict, style: str, seed: int, quick: bool = False) -> list:
    """bench sync's cued top target decks of one piece; durations: every
    piece's [s] (scenarios() draws for each piece in turn, so the decks of
    one piece come only from the draw over all of them)."""
    runs = bs.scenarios(durations, 20.0 if quick else None, quick, seed)
    return bs.top_variants([sc for sc in runs if sc.target and sc.piece == style])


def collect(seeds: int = bs.SEEDS, seed: int = bs.SEED, quick: bool = False, tracker: str = "smooth") -> dict:
    """Per deck kind (fast, slow-room, pauses, jump): the causes' tick counts, summed over the runs."""
    by_kind: dict[str, dict] = {}
    pieces = {style: synthesize(style, seed=piece_seed) for style, piece_seed in bs.PIECES}
    durations = {style: piece.duration for style, piece in pieces.items()}   # [s]
    for style, piece in (list(pieces.items())[:1] if quick else pieces.items()):
        stored = loudness(piece.samples, piece.sample_rate)
        stored_onsets = onsets(piece.samples, piece.sample_rate)
        stored_bands = fit_frames(bands(piece.samples, piece.sample_rate), len(stored))
        audible = bs.audible_from(stored)
        for s in range(seed, seed + seeds):
            for sc in cued_top_decks(durations, style, s, quick):
                played, (live, live_onsets, live_bands) = bs.live_frames(piece, sc.deck)
                follower = Follower(stored, mode=tracker, onset=stored_onsets, bands=stored_bands)
                follower.cue(0.0)
                track = follower.run(live, live_onsets, bands=live_bands)
                n = min(len(played.truth), len(track.position))
                t = np.arange(n) * T
                err = np.abs(track.position[:n] * T - played.truth[:n])
                measured = t >= bs.onset_of(played, audible) + bs.CUE_FROM_S
                for r in played.resumes:
                    measured &= ~((t >= r) & (t < r + bs.AFTER_PAUSE_S))
                for j in played.jumps:
                    measured &= ~((t >= j) & (t < j + bs.AFTER_JUMP_S))
                level_db = 20 * np.log10(np.maximum(live[1:n + 1], 1e-9))   # tick k's frame is k - 1
                got = causes(err, t, played, np.pad(level_db, (0, n - len(level_db)), mode="edge"), measured)
                kind = by_kind.setdefault(sc.name.split("/")[1], {})
                for key, v in got.items():
                    kind[key] = kind.get(key, 0) + v
    total = {key: sum(k[key] for k in by_kind.values()) for key in next(iter(by_kind.values()))}
    missed = sum(total[c] for c in CAUSES)
    return {"tracker": tracker, "seeds": seeds, "seed": seed, "kinds": by_kind, "total": total,
            "within50": 1 - missed / total["ticks"],
            "within50_without_masked": 1 - (missed - total["masked stop"]) / (total["ticks"] - total["masked_ticks"])}


def format_table(result: dict) -> str:
    lines = [f"bench misses: ticks > {MISS_S * 1e3:g} ms off on the cued top decks, {result['tracker']} mode, "
             f"{result['seeds']} seed set(s) from {result['seed']}",
             f"{'decks':<10} {'ticks':>7} " + " ".join(f"{c:>22}" for c in CAUSES)]
    for name, k in [*result["kinds"].items(), ("all", result["total"])]:
        lines.append(f"{name:<10} {k['ticks']:>7} " + " ".join(f"{k[c]:>22}" for c in CAUSES))
    lines.append(f"within 50 ms {100 * result['within50']:.2f} %; without the masked stops' "
                 f"{result['total']['masked_ticks']} ticks {100 * result['within50_without_masked']:.2f} %")
    return "\n".join(lines)


def register(sub) -> None:
    p = sub.add_parser("misses", help="where the cued top decks of bench sync lose their ticks",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=Number(int, 1), default=bs.SEEDS, metavar="N", help="sets of decks")
    p.add_argument("--seed", type=bs.SEED_OPTION, default=bs.SEED, help="the first set's seed")
    p.add_argument("--quick", action="store_true", help="one piece, its first 20 s")
    p.add_argument("--model", action="store_true", help="the tape deck model in the smooth mode's place")
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")


def run(args) -> int:
    result = collect(args.seeds, args.seed, args.quick, "model" if args.model else "smooth")
    print(json.dumps(result, indent=2) if args.json else format_table(result))
    return 0


if __name__ == "__main__":
    from marionette.cli import main as cli_main
    sys.exit(cli_main(["bench", "misses", *sys.argv[1:]]))
