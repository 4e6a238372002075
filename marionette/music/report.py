"""What ``marionette play`` tells the operator about the live music: when it
is not followed (lines on stderr, in real time or after a step-mode run),
how much of the show ran that way (the summary), warnings about a live
recording that cannot be the show's music, and which input latency the
follower uses.

The music is *not followed* on a tick whose follower state is searching
after some earlier tick had a place: the engine marks those ticks with
FLAG_UNFOLLOWED (docs/music.md, ``on_lost``); from a lost live source on
(``Engine.source_lost``, FLAG_SOURCE_LOST) every tick is. Nothing here touches the
tick: the real-time lines come from a thread that reads the engine's
snapshot.
"""
from __future__ import annotations

import sys
import threading
from dataclasses import dataclass

import numpy as np

from marionette._core import FLAG_SOURCE_LOST, FLAG_UNFOLLOWED
from marionette.music.follower import OPTIONS, STATES

SEARCHING, LOCKED, WAITING = (STATES.index(s) for s in ("searching", "locked", "waiting"))
POLL_INTERVAL = 0.1             # how often the watcher reads the snapshot [s]
UNFOLLOWED_LIMIT = 0.5          # play exits 1 when more of the show than this searched [1]
SILENT_RMS = 1e-4               # a recording whose every frame is below this is silent [full scale]
FLAT_RANGE_DB = 3.0             # ... or whose frames (10th to 90th percentile) span less [dB]
SHORT_SHARE = 0.5               # a recording shorter than this share of the show's music is truncated [1]
TAUGHT_SHORT_SHARE = 0.95       # ... taught music (teach): the show's end would follow silence [1]


def lost_line(time_s: float, position_s: float, on_lost: str) -> str:
    """The stderr line when the music becomes unfollowed at show time time_s [s]."""
    doing = "the figure holds there" if on_lost == "hold" else "the show plays on at the last rate"
    return (f"music not followed from show time {time_s:.2f} s (last place {position_s:.2f} s "
            f"of the music; on_lost {on_lost}: {doing})")


def found_line(time_s: float, lost_for_s: float) -> str:
    """The stderr line when the music is followed again at show time time_s [s]."""
    return f"music followed again at show time {time_s:.2f} s, after {lost_for_s:.2f} s"


def lost_events(flags: np.ndarray, positions: np.ndarray, period: float,
                on_lost: str) -> list[str]:
    """The lines a real-time run prints, from a run's records (tick k at
    show time k * period [s])."""
    lost = (np.asarray(flags) & FLAG_UNFOLLOWED) != 0
    edges = np.flatnonzero(np.diff(np.concatenate([[False], lost]).astype(np.int8)))
    lines = []
    for k in edges:
        if lost[k]:
            since = k
            before = positions[k - 1] if k > 0 else positions[k]
            lines.append(lost_line(k * period, before * period, on_lost))
        else:
            lines.append(found_line(k * period, (k - since) * period))
    return lines


class LostWatcher:
    """A thread that reads engine.snapshot() about 10 times a second and
    prints a line on stderr when the music becomes unfollowed and when it is
    followed again. It only reads; a loss shorter than the poll may pass unseen
    (the summary, from the records, counts every tick)."""

    def __init__(self, engine, period: float, on_lost: str, out=None):
        self.engine = engine
        self.period = float(period)             # [s]
        self.on_lost = on_lost
        self.out = out
        self.lines: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="marionette-lost-watch", daemon=True)
        self._lost_at: int | None = None        # tick the loss was seen
        self._last: tuple[int, float] | None = None   # last followed (tick, position [show ticks])

    def start(self) -> "LostWatcher":
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop polling (again: nothing more) after one last look at the final tick."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join()
        self.look()

    def _say(self, line: str) -> None:
        self.lines.append(line)
        print(line, file=self.out or sys.stderr, flush=True)

    def look(self) -> None:
        snap = self.engine.snapshot()
        if snap is None:
            return
        lost = bool(snap.flags & FLAG_UNFOLLOWED)
        if lost and self._lost_at is None:
            self._lost_at = snap.tick
            position = self._last[1] if self._last is not None else snap.position
            self._say(lost_line(snap.tick * self.period, position * self.period, self.on_lost))
        elif not lost:
            if self._lost_at is not None:
                self._say(found_line(snap.tick * self.period, (snap.tick - self._lost_at) * self.period))
                self._lost_at = None
            self._last = (snap.tick, snap.position)

    def _run(self) -> None:
        while not self._stop.wait(POLL_INTERVAL):
            self.look()


@dataclass(frozen=True)
class FollowShare:
    """How much of a run the music was not followed, from its records.

    Ticks before the first live frame came do not count as unfollowed: there
    was no music to follow yet (a sound card delivers its first block up to
    2 s after it is opened). A silent recording still brings frames."""

    ticks: int                  # ticks run
    before_music: int           # ticks before the first live frame
    searching: int              # ticks searching, or waiting at the cue, from the first live frame on,
                                # and every tick from a lost source on
    unfollowed: int             # ... of them after the first place (FLAG_UNFOLLOWED)
    losses: int                 # times the music became unfollowed
    locked: bool                # the follower was LOCKED on some tick
    source_lost: int | None = None      # tick from which the live source was lost (FLAG_SOURCE_LOST)
    source_lost_position: float = float("nan")  # the show's position there [show ticks]
    source_lost_rate: float = float("nan")      # ... and the rate it played on at [show ticks per tick]

    @property
    def share(self) -> float:
        """Share of the show that ran unfollowed: ticks searching or waiting at the
        cue while frames came (silence is heard too) / ticks [1]."""
        return self.searching / self.ticks if self.ticks else 0.0

    @property
    def too_much(self) -> bool:
        return self.share > UNFOLLOWED_LIMIT


def follow_share(records: np.ndarray) -> FollowShare:
    states = records["follow_state"]
    lost = (records["flags"] & FLAG_UNFOLLOWED) != 0
    heard = np.flatnonzero(np.isfinite(records["live_loudness"]))
    first = int(heard[0]) if len(heard) else len(states)                # [tick]
    searching = np.isin(states, (SEARCHING, WAITING)) & (np.arange(len(states)) >= first)
    gone = np.flatnonzero(records["flags"] & FLAG_SOURCE_LOST)          # latched: to the end
    at, where, rate = None, float("nan"), float("nan")
    if len(gone):
        at = int(gone[0])
        searching[at:] = True
        where, rate = float(records["position"][at]), float(records["rate"][at])
    return FollowShare(ticks=len(states), before_music=first, searching=int(np.sum(searching)),
                       unfollowed=int(np.sum(lost)),
                       losses=int(np.sum(np.diff(np.concatenate([[False], lost]).astype(np.int8)) == 1)),
                       locked=bool(np.any(states == LOCKED)), source_lost=at,
                       source_lost_position=where, source_lost_rate=rate)


def share_line(s: FollowShare, period: float, on_lost: str) -> str:
    """The summary line: the share of the show that ran unfollowed."""
    return (f"  music not followed: {s.share:.0%} of the show searching or waiting for it "
            f"({s.searching * period:.2f} s "
            f"from the first live frame at {s.before_music * period:.2f} s), {s.unfollowed * period:.2f} s "
            f"of it after the first place, lost {s.losses} time(s); on_lost {on_lost}"
            + ("" if s.source_lost is None else "\n" + source_lost_line(s, period, on_lost)))


def source_lost_line(s: FollowShare, period: float, on_lost: str) -> str:
    """The summary line when the live source was lost (s.source_lost is a tick)."""
    at = f"{s.source_lost_position * period:.2f} s"
    doing = (f"the figure held the show at {at}" if on_lost == "hold"
             else f"the show stood at {at}, rate 0" if s.source_lost_rate == 0.0   # WAITING, PAUSED
             else f"the show played on at rate {s.source_lost_rate:.3f}")
    return (f"  live source lost at show time {s.source_lost * period:.2f} s: not followed from "
            f"then to the end ({(s.ticks - s.source_lost) * period:.2f} s; on_lost {on_lost}: {doing})")


def verdict_line(s: FollowShare) -> str | None:
    """The last line when more than half of the show ran unfollowed, else None."""
    if not s.too_much:
        return None
    return (f"NOT FOLLOWED: the music was not followed for {s.share:.0%} of the show "
            f"(more than {UNFOLLOWED_LIMIT:.0%}); exit status 1")


def recording_warnings(path, loud: np.ndarray, period: float, show_seconds: float,
                       cue_s: float | None, kind: str = "live recording",
                       short_share: float = SHORT_SHARE) -> list[str]:
    """Warnings about a live recording before the show (or, kind "taught
    music", the music that teach stores in the show): silent (every frame
    under SILENT_RMS [full scale], or the frames' levels span less than
    FLAT_RANGE_DB: a steady tone or hiss, not music) or truncated (shorter
    than short_share of the show's music from the cue; cue_s None: unknown,
    the whole music counts). loud: its loudness frames, one per period [s]."""
    loud = np.asarray(loud, dtype=np.float64)
    out = []
    seconds = len(loud) * period                                        # [s]
    if len(loud) == 0 or np.max(loud) < SILENT_RMS:
        out.append(f"warning: {kind} {path} is silent (every frame under "
                   f"{SILENT_RMS:g} full scale RMS); the music cannot be followed")
    else:
        db = 20 * np.log10(np.maximum(loud, 1e-12))
        spread = float(np.percentile(db, 90) - np.percentile(db, 10))
        if spread < FLAT_RANGE_DB:
            out.append(f"warning: {kind} {path} has no level range ({spread:.1f} dB "
                       f"between its 10th and 90th percentile frames): a steady sound, not music")
    start = 0.0 if cue_s is None else float(cue_s)
    music = max(0.0, show_seconds - start)                              # [s]
    if seconds < short_share * music:
        where = "the top" if cue_s is None else f"the cue at {start:g} s"
        out.append(f"warning: {kind} {path} is {seconds:.2f} s long, less than "
                   f"{short_share:.0%} of the show's music from {where} ({music:.2f} s): truncated?")
    return out


def never_locked_warning(source: str, s: FollowShare) -> str | None:
    """After the run: the follower never locked on the live recording
    source (another piece, or no music at all)."""
    if s.locked or s.ticks == 0:
        return None
    return (f"warning: the music follower never locked on {source} in {s.ticks} ticks: "
            f"another piece than the show's, or no music?")


def choose_latency(figure_latency: float | None, source_latency: float | None) -> tuple[float, str]:
    """The follower's input latency [s] and where it came from: the figure's
    [follow] latency when set, else the sound card's reported input latency,
    else the follower's default."""
    if figure_latency is not None:
        return float(figure_latency), "the figure's [follow] latency"
    if source_latency is not None:
        return float(source_latency), "the sound card's input latency"
    return OPTIONS["latency"]["default"], "default"
