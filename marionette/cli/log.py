"""``marionette log FLIGHT.bin``: what a flight record says.

    marionette log FLIGHT.bin [--csv OUT.csv] [--plot [OUT.png]] [--axes a,b]

Prints a summary: the show, figure and settings from the header; the ticks
and the time span; the follower's states and the share of each; the share
of the show not followed; the limited axis-ticks; bad inputs; node alarms;
every flag counted by name (the names are the binding's FLAG_* constants,
marionette._core). ``--csv`` writes one row per tick with every field of the
record (docs/formats.md), the commands as ``command_<axis name>``.
``--plot`` draws position and rate, the follower's state and confidence,
the limited axes, the node alarms and the commands of the axes chosen with
``--axes`` (default: the first two), one panel above the other; it needs
matplotlib (the ``plot`` extra), imported only then, and draws with Agg.

A file that is not a flight record, or one cut short, is an error that names
the file (exit status 2).
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from marionette import _core
from marionette.cli.options import image_file, input_file, output_file
from marionette.errors import MarionetteError
from marionette.limiter_report import limited_axes
from marionette.music.follower import STATES
from marionette.recorder import MAGIC, read_flight_record

# flag bit -> name, from the binding (FLAG_SOURCE_LOST -> "source_lost")
FLAGS = dict(sorted((int(value), name[len("FLAG_"):].lower())
                    for name, value in vars(_core).items() if name.startswith("FLAG_")))
NO_FOLLOWER = -1                               # follow_state without a follower
BIT = {name: bit for bit, name in FLAGS.items()}


class LogError(MarionetteError, ValueError):
    """A flight record that cannot be read, or an option that does not fit it."""


def read_record(path) -> tuple[dict, np.ndarray]:
    """(header, records) of a flight record; LogError naming the file otherwise."""
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: no such flight record")
    try:
        with open(path, "rb") as f:
            first = f.readline(1 << 20)
    except OSError as exc:
        raise LogError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if not first:
        raise LogError(f"{path}: empty file, not a marionette flight record")
    if not first.startswith(MAGIC):
        raise LogError(f"{path}: not a marionette flight record (it does not begin "
                       f"with {MAGIC.decode().strip()!r})")
    if not first.endswith(b"\n"):
        raise LogError(f"{path}: the header line is cut short (file truncated?)")
    try:
        header = json.loads(first[len(MAGIC):])
    except (ValueError, UnicodeDecodeError) as exc:
        raise LogError(f"{path}: the header is not valid JSON ({exc})") from None
    names = header.get("axis_names") if isinstance(header, dict) else None
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise LogError(f"{path}: the header has no list of axis_names")
    size = _core.record_dtype(len(names)).itemsize
    if header.get("record_bytes", size) != size:
        raise LogError(f"{path}: records of {header['record_bytes']} bytes, but {len(names)} axes "
                       f"make {size}-byte records (written by another version?)")
    try:
        return read_flight_record(path)
    except ValueError as exc:                  # records cut short
        message = str(exc)
        if not message.startswith(str(path)):
            message = f"{path}: {message}"
        raise LogError(message) from None


def _figure(header: dict):
    """The figure named in the header (FigureConfig), when it can still be read
    and has the record's axes; else None."""
    source = header.get("config")
    if not source or not Path(str(source)).is_file():
        return None
    try:
        from marionette.config import load_config
        config = load_config(source)
    except (MarionetteError, OSError, ValueError):
        return None
    return config if config.axis_names == list(header["axis_names"]) else None


def _node_addresses(header: dict) -> list[int] | None:
    """The figure's node addresses, ascending (bit i of node_alarms is the i-th)."""
    config = _figure(header)
    return None if config is None else sorted({a.node for a in config.axes})


def _runs(mask: np.ndarray) -> int:
    """How many runs of True."""
    m = np.asarray(mask, dtype=np.int8)
    return int(np.sum(np.diff(np.concatenate([[0], m])) == 1))


def summary(header: dict, rec: np.ndarray, path) -> list[str]:
    """The lines `marionette log` prints."""
    period = float(header.get("tick_period", float("nan")))              # [s]
    n = len(rec)
    out = [f"{path}: flight record of {header.get('show', '?')} on {header.get('figure', '?')} "
           f"({header.get('config', '?')})",
           f"  tick {period * 1e3:g} ms, lead {header.get('lead', '?')}, "
           f"{header.get('interpolation', '?')} interpolation, {len(header['axis_names'])} axes"]
    if n == 0:
        out.append("  no ticks recorded")
        return out
    t = (rec["time_ns"] - rec["time_ns"][0]) * 1e-9                       # [s]
    gaps = int(np.sum(np.diff(rec["tick"]) != 1))
    out.append(f"  ticks: {n} (tick {rec['tick'][0]} .. {rec['tick'][-1]}"
               + (f", {gaps} gaps" if gaps else "") + f"), time span {t[-1]:.3f} s "
               f"({n * period:.2f} s of ticks)")
    pos = rec["position"] * period
    out.append(f"  show position {pos[0]:.2f} .. {pos[-1]:.2f} s (min {np.min(pos):.2f}, "
               f"max {np.max(pos):.2f}); rate {np.min(rec['rate']):.3f} .. {np.max(rec['rate']):.3f}, "
               f"mean {np.mean(rec['rate']):.3f}")
    states = rec["follow_state"]
    if np.all(states == NO_FOLLOWER):
        out.append("  music follower: none (the show played by the clock)")
    else:
        parts = [f"{name} {np.mean(states == code):.1%}" for code, name in enumerate(STATES)
                 if np.any(states == code)]
        if np.any(states == NO_FOLLOWER):
            parts.append(f"none {np.mean(states == NO_FOLLOWER):.1%}")
        conf = rec["follow_confidence"][np.isfinite(rec["follow_confidence"])]
        out.append("  music follower: " + ", ".join(parts)
                   + (f"; confidence mean {np.mean(conf):.2f}" if conf.size else ""))
        from marionette.music.report import follow_share
        share = follow_share(rec)
        out.append(f"  music not followed: {share.share:.1%} of the ticks searching or waiting "
                   f"({share.searching * period:.2f} s), flag unfollowed on {share.unfollowed} "
                   f"ticks, lost {share.losses} time(s)"
                   + ("" if share.source_lost is None else
                      f"; live source lost at tick {share.source_lost}"))
    limited = rec["limited_axes"].astype(np.int64)
    hit = limited > 0
    out.append(f"  limits acted on {int(limited.sum())} axis-ticks in {int(hit.sum())} ticks "
               f"({np.mean(hit):.1%}), at most {int(limited.max())} axes in one tick"
               + (f", first at {t[np.argmax(hit)]:.2f} s" if hit.any() else ""))
    if hit.any():
        out.extend(_limited_lines(header, rec))
    bad = (rec["flags"] & BIT["bad_input"]) != 0
    out.append(f"  bad inputs refused: on {int(bad.sum())} ticks")
    alarms = rec["node_alarms"]
    if np.any(alarms):
        nodes = _node_addresses(header)
        words = []
        for i in range(32):
            on = (alarms >> np.uint32(i)) & 1 == 1
            if on.any():
                who = f"node {nodes[i]}" if nodes and i < len(nodes) else f"node #{i}"
                words.append(f"{who} {int(on.sum())} ticks (from {t[np.argmax(on)]:.2f} s, "
                             f"{_runs(on)} time(s))")
        out.append("  node alarms: " + "; ".join(words))
    else:
        out.append("  node alarms: none")
    flags = rec["flags"]
    counts = [f"{name} {int(np.sum((flags & bit) != 0))}" for bit, name in FLAGS.items()]
    other = int(np.bitwise_or.reduce(flags) & ~np.uint32(sum(FLAGS)))
    out.append("  flags [ticks]: " + ", ".join(counts)
               + (f", unknown bits 0x{other:x} {int(np.sum((flags & np.uint32(other)) != 0))}"
                  if other else ""))
    cmd = rec["command"]
    names = header["axis_names"]
    if len(names) and n:
        span = cmd.max(axis=0) - cmd.min(axis=0)
        j = int(np.argmax(span))
        out.append(f"  commands: {len(names)} axes, most travel {names[j]} "
                   f"{cmd[:, j].min():.4g} .. {cmd[:, j].max():.4g}")
    return out


def _limited_lines(header: dict, rec: np.ndarray) -> list[str]:
    """Per limited axis (the records' excess): ticks, runs in show time, largest excess."""
    names = header["axis_names"]
    config = _figure(header)
    units = [a.unit for a in config.axes] if config is not None else [""] * len(names)
    found = limited_axes(rec, names, units, float(header["tick_period"]))
    return [f"    by axis [axis-ticks]: " + ", ".join(f"{a.axis} {a.ticks}" for a in found)] + \
        [f"    {a.describe()}" for a in found]


def csv_columns(header: dict, rec: np.ndarray) -> list[str]:
    """Every field of the record; arrays one column per axis, named by the axis."""
    cols = []
    for field in rec.dtype.names:
        shape = rec.dtype[field].shape
        if shape:
            cols += [f"{field}_{name}" for name in header["axis_names"]]
        else:
            cols.append(field)
    return cols


def write_csv(path, header: dict, rec: np.ndarray) -> None:
    """One row per tick. Floats are written with repr, so they read back bit for bit."""
    fields = [(f, bool(rec.dtype[f].shape)) for f in rec.dtype.names]
    columns = [rec[f].tolist() for f, _ in fields]
    try:
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(csv_columns(header, rec))
            for k in range(len(rec)):
                row = []
                for (_, is_array), col in zip(fields, columns):
                    if is_array:
                        row.extend(col[k])
                    else:
                        row.append(col[k])
                w.writerow(row)
    except OSError as exc:
        raise LogError(f"{path}: cannot write the CSV: {exc.strerror or exc}") from None


def plot(path, header: dict, rec: np.ndarray, axes: list[str], source) -> None:
    try:
        import matplotlib
    except ImportError:
        raise LogError("log --plot needs matplotlib: pip install 'marionette[plot]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    period = float(header.get("tick_period", 0.02))
    names = header["axis_names"]
    t = (rec["time_ns"] - rec["time_ns"][0]) * 1e-9 if len(rec) else np.zeros(0)
    fig, panels = plt.subplots(5, 1, figsize=(10, 11), sharex=True,
                               gridspec_kw=dict(height_ratios=(2, 1.2, 1, 1, 2)))
    ax = panels[0]
    ax.plot(t, rec["position"] * period, color="tab:blue", lw=1.2, label="position")
    ax.set_ylabel("show position [s]")
    ax.grid(True, lw=0.3, alpha=0.6)
    ax2 = ax.twinx()
    ax2.plot(t, rec["rate"], color="tab:orange", lw=0.9, label="rate")
    ax2.set_ylabel("rate [1]", color="tab:orange")
    ax.set_title("(A) playback position and rate", fontsize=9, loc="left")

    ax = panels[1]
    states = rec["follow_state"]
    ax.step(t, states, where="post", color="tab:green", lw=1.0)
    ax.set_yticks(range(-1, len(STATES)), ["none", *STATES], fontsize=7)
    ax.set_ylim(-1.5, len(STATES) - 0.5)
    conf = rec["follow_confidence"]
    if np.any(np.isfinite(conf)):
        ax2 = ax.twinx()
        ax2.plot(t, conf, color="0.5", lw=0.7)
        ax2.set_ylim(0, 1.05)
        ax2.set_ylabel("confidence", color="0.5")
    unf = (rec["flags"] & BIT["unfollowed"]) != 0
    if unf.any():
        ax.fill_between(t, -1.5, len(STATES) - 0.5, where=unf, color="tab:red", alpha=0.15,
                        step="post", label="not followed")
        ax.legend(fontsize=7, loc="upper right")
    ax.set_title("(B) music follower state (red: not followed)", fontsize=9, loc="left")

    ax = panels[2]
    hits = rec["excess"] != 0
    hit_axes = [j for j in range(len(names)) if hits[:, j].any()]
    if hit_axes:
        for row, j in enumerate(hit_axes):
            ticks = hits[:, j]
            ax.plot(t[ticks], np.full(int(ticks.sum()), row), "|", ms=7, color="tab:red")
        ax.set_yticks(range(len(hit_axes)), [names[j] for j in hit_axes], fontsize=6)
        ax.set_ylim(-0.7, len(hit_axes) - 0.3)
        ax.set_title("(C) axes a limit acted on (grey: how many, right scale)", fontsize=9,
                     loc="left")
        ax2 = ax.twinx()
        ax2.step(t, rec["limited_axes"], where="post", color="0.6", lw=0.8)
        ax2.set_ylabel("axes", color="0.5")
    else:
        ax.step(t, rec["limited_axes"], where="post", color="tab:red", lw=1.0)
        ax.set_ylabel("axes")
        ax.set_title("(C) how many axes a limit acted on", fontsize=9, loc="left")
    ax.grid(True, lw=0.3, alpha=0.6)

    ax = panels[3]
    alarms = rec["node_alarms"]
    nodes = _node_addresses(header)
    bits = [i for i in range(32) if np.any((alarms >> np.uint32(i)) & 1)]
    for i in bits:
        on = ((alarms >> np.uint32(i)) & 1).astype(float)
        who = f"node {nodes[i]}" if nodes and i < len(nodes) else f"node #{i}"
        ax.step(t, on * 0.8 + bits.index(i), where="post", lw=1.0, label=who)
    if bits:
        ax.legend(fontsize=7, loc="upper right", ncol=4)
        ax.set_yticks([])
    else:
        ax.text(0.5, 0.5, "no node alarms", transform=ax.transAxes, ha="center", va="center")
        ax.set_yticks([])
    ax.set_title("(D) node alarms (silent, fault or e-stop)", fontsize=9, loc="left")

    ax = panels[4]
    for name in axes:
        ax.plot(t, rec["command"][:, names.index(name)], lw=1.0, label=name)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_ylabel("command [axis unit]")
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.set_title("(E) commands", fontsize=9, loc="left")
    ax.set_xlabel("time [s] from the first tick")
    fig.suptitle(f"{Path(source).name}: {header.get('show', '?')}", fontsize=10)
    fig.tight_layout()
    try:
        fig.savefig(path)
    except OSError as exc:
        raise LogError(f"{path}: cannot write the plot: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)


def run(args) -> int:
    header, rec = read_record(args.record)
    names = header["axis_names"]
    if args.axes:
        chosen = [a.strip() for a in args.axes.split(",") if a.strip()]
        unknown = [a for a in chosen if a not in names]
        if unknown:
            raise LogError(f"{args.record}: no axis {unknown[0]!r} in this record "
                           f"(axes: {', '.join(names)})")
    else:
        chosen = names[:2]
    for line in summary(header, rec, args.record):
        print(line)
    if args.csv:
        write_csv(args.csv, header, rec)
        print(f"wrote {args.csv}: {len(rec)} rows, {len(csv_columns(header, rec))} columns")
    if args.plot is not None:
        out = args.plot or str(Path(args.record).with_suffix(".png"))
        plot(out, header, rec, chosen, args.record)
        print(f"wrote {out}: position and rate, follower state, limited axes, node alarms, "
              f"commands of {', '.join(chosen) or 'no axes'}")
    return 0


def _plot_file(text: str) -> str:
    """--plot's value: an image file, or none (argparse passes the empty const here too)."""
    return image_file(text) if text else text


def register(subparsers) -> None:
    p = subparsers.add_parser("log", help="summarize a flight record; export it as CSV, plot it",
                              description="Summarize a flight record written by `marionette play "
                              "--record` (docs/formats.md); --csv exports every tick, --plot draws it.")
    p.add_argument("record", type=input_file, help="flight record (.bin) written by play --record")
    p.add_argument("--csv", metavar="OUT.csv", type=output_file,
                   help="write one row per tick, every field")
    p.add_argument("--plot", nargs="?", const="", metavar="OUT.png", type=_plot_file,
                   help="draw the record (default file: the record's name with .png); needs matplotlib")
    p.add_argument("--axes", metavar="A,B", help="axes whose commands --plot draws "
                                                 "(default: the first two)")
    p.set_defaults(run=run)
