"""The cue's decision on a feature, offline: part of ``marionette bench bands``.

A cue says the music starts at the top. After a little music (CHECKS_S
after its onset), the rule under test fits lines through the cue (rates
RATES, offsets within LAGS frames of the cue) to the live frames heard
since the onset, and locks when the best line's joint correlation
(`bands.window_correlation`, per band demeaned) beats the best place
anywhere else in the piece (more than AWAY_S from the line) by at least
`lead_z` in Fisher z. Measured on ``bench sync``'s decks: the target decks
played from the top (their onset from the deck's truth, where the first
audible stored frame is heard) and the wrong-cue decks (the tape starts
10-60 s in; the music from the first frame). Figures per feature and
lead_z:

- locked_by_0_5s: the share of top decks locked by 0.5 s of music, the
  line within CUE_TOL_S of the truth at that moment;
- lock_s_median: the median music heard before the lock [s] (inf: never
  within CHECKS_S);
- bad_locks: top decks locked with the line further than CUE_TOL_S off;
- wrong_false_locks: wrong-cue decks locked at the cue at any check.

The follower's own cue (ext/mar_follow.c) adds more to this (two fits in a
row, a lead scaled by the window, onset detection); this isolates what the
feature gives a rule of this shape.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from marionette.bench.sync import (PIECES, audible_from, onset_of, scenarios, top_variants,
                                   wrong_cue_decks)
from marionette.music.bands import correlations
from marionette.music.feature import FRAME_PERIOD, loudness
from marionette.sim.tape import play

T = FRAME_PERIOD                                        # [s]
CHECKS_S = (0.3, 0.4, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)    # music heard at each decision [s]
RATES = np.arange(0.93, 1.0701, 0.005)                  # lines through the cue [1]
LAGS = 5                                                # offsets from the cue [frames]
AWAY_S = 0.5                                            # another place: this far from the line [s]
CUE_TOL_S = 0.05                                        # a lock within this of the truth is right [s]
LEAD_Z = (0.0, 0.1, 0.2, 0.3)                           # rules measured [Fisher z]
DECK_S = 3.0                                            # live music kept after the onset [s]


def along_rate(live: np.ndarray, rate: float, ages: int) -> np.ndarray:
    """The first `ages` live frames (rows) on the stored grid for a tape at
    `rate`: stored frame j of the line was heard at live frame j / rate."""
    m = int(np.floor((ages - 1) * rate)) + 1
    src = np.arange(m) / rate
    return np.stack([np.interp(src, np.arange(ages), live[:ages, b]) for b in range(live.shape[1])], axis=1)


def cue_decision(stored: np.ndarray, live: np.ndarray, cue: int, ages: int) -> tuple[float, float, float, int]:
    """(best line's correlation, best elsewhere, its rate, its offset [frames])
    for the live frames (rows from the onset) and the cue at stored frame `cue`."""
    best = (-2.0, -2.0, 1.0, 0)
    for rate in RATES:
        window = along_rate(live, rate, ages)
        lo = max(0, cue - LAGS)
        segment = stored[lo:cue + LAGS + len(window)]
        if len(segment) < len(window):
            continue
        c = correlations(window, segment)
        if not np.isfinite(c).any():
            continue
        i = int(np.nanargmax(c))
        if abs(lo + i - cue) < LAGS and c[i] > best[0]:
            best = (float(c[i]), 0.0, float(rate), lo + i - cue)
    corr, _, rate, d = best
    if corr <= -2.0:
        return corr, 1.0, rate, d
    c = correlations(along_rate(live, rate, ages), stored)
    far = np.abs(np.arange(len(c)) - (cue + d)) > int(round(AWAY_S / T))
    elsewhere = float(np.nanmax(c[far])) if np.isfinite(c[far]).any() else -1.0
    return corr, elsewhere, rate, d


def deck_checks(stored: np.ndarray, live: np.ndarray, truth: np.ndarray, onset: int, cue: int) -> list:
    """[(music heard [s], correlation, elsewhere, line minus truth [s])] at CHECKS_S."""
    out = []
    for secs in CHECKS_S:
        ages = int(round(secs / T))
        if onset + ages > min(len(live), len(truth)):
            break
        corr, elsewhere, rate, d = cue_decision(stored, live[onset:], cue, ages)
        now = onset + ages - 1
        out.append((secs, corr, elsewhere, (cue + d + rate * (ages - 1)) * T - truth[now]))
    return out


def collect(pieces: dict, stored: dict, features: dict, seeds: range, level_db, progress=None) -> dict:
    """{(feature, kind): [(target, checks)]} over the top and wrong-cue decks of seeds."""
    # scenarios() draws for every piece of the bench; decks of others are skipped
    durations = {k: pieces[k].duration if k in pieces else 60.0 for k, _ in PIECES}
    cue = {k: int(round(audible_from(loudness(p.samples, p.sample_rate)) / T)) for k, p in pieces.items()}
    out = {(f, kind): [] for f in features for kind in ("top", "wrong")}
    for s in seeds:
        decks = [("top", sc) for sc in top_variants(scenarios(durations, None, False, s))]
        decks += [("wrong", sc) for sc in wrong_cue_decks(durations, None, False, s)]
        for kind, sc in decks:
            if sc.piece not in pieces:
                continue
            # only the first seconds matter: the deck cut after the cue's last check
            start = cue[sc.piece] * T / sc.deck.speed if kind == "top" else 0.0
            deck = replace(sc.deck, seconds=start + DECK_S + 2.0)
            played = play(pieces[sc.piece].samples, pieces[sc.piece].sample_rate, deck)
            onset = int(round(onset_of(played, cue[sc.piece] * T) / T)) if kind == "top" else 0
            for f, fn in features.items():
                live = level_db(fn(played.samples, played.sample_rate))
                out[f, kind].append((sc.target, deck_checks(stored[sc.piece, f], live, played.truth,
                                                            onset, cue[sc.piece])))
            if progress:
                progress(f"cue: {sc.name}@{s} ({kind})")
    return out


def summarize(per_deck: dict, features, fisher) -> list[dict]:
    rows = []
    for f in features:
        for lead in LEAD_Z:
            lock_s, bad = [], 0
            for target, checks in per_deck[f, "top"]:
                if not target:
                    continue
                fired = [(s, err) for s, c, e, err in checks if fisher(c) - fisher(e) >= lead and c > -2]
                right = bool(fired) and abs(fired[0][1]) <= CUE_TOL_S
                lock_s.append(fired[0][0] if right else np.inf)       # a bad lock is no lock at the cue
                bad += int(bool(fired) and not right)
            false = sum(any(fisher(c) - fisher(e) >= lead and c > -2 for _, c, e, _ in checks)
                        for _, checks in per_deck[f, "wrong"])
            lock = np.array(lock_s)
            rows.append({"section": "cue", "feature": f, "lead_z": lead, "decks_top": len(lock),
                         "decks_wrong": len(per_deck[f, "wrong"]),
                         "locked_by_0_5s": float(np.mean(lock <= 0.5)) if len(lock) else float("nan"),
                         "lock_s_median": float(np.median(lock)) if len(lock) else float("nan"),
                         "bad_locks": bad, "wrong_false_locks": int(false)})
    return rows
