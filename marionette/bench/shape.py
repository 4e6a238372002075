"""``marionette bench shape``: does the engine's limiter stay idle on shaped shows?

Limited axis-ticks (axis-ticks on which the engine's hard limits cut a
command), each show played through the engine in step mode with the default
settings (lead dead_time_lag, cubic interpolation, rate 1), on:

- ``demo``: the bundled demo show as it is, and ``demo_shaped`` after
  ``marionette shape`` with its defaults;
- ``sample``: the ``teach --sample`` show (calibrate --sample, teach --sample:
  shaped by teach's last stage);
- ``taught``: COUNT random taught shows from the teach simulator
  (marionette.teach.make_sample.write_sample, seeds SEED.., SECONDS long each,
  calibrated and taught as the CLI does), before shaping (``teach
  --no-shape``) and after (shaped as teach shapes);
- ``rates``: the shaped demo played at rates 0.94 and 1.06, and the
  ``teach --sample`` show following its music played back from a tape deck
  (marionette.sim.tape) running 3 % slow and 3 % fast with wow (a wobbling
  rate that the follower corrects): shows are shaped for every rate up to the
  figure's follow.rate_max, and the engine follows the music's corrections
  at a smooth clock (ext/mar_clock.h);
- the climax timing at the simulated servos (marionette.bench.climax).

Goal: 0 limited axis-ticks on every shaped show, climaxes within 1 tick.
A teach-in takes about a second, so the default COUNT is 10; the figure in
the closing note of issue 18 used --count 100.
"""
from __future__ import annotations

import contextlib
import io
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from marionette.bench import STRICT_HELP, exit_status, verdict
from marionette.bench.climax import TARGET_TICKS, climax_timing
from marionette.cli.options import Number
from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.engine import Engine
from marionette.errors import MarionetteError
from marionette.shape import shape_show
from marionette.show import load_show

COUNT = 10            # random taught shows [1]
SEED = 18             # first seed of the random taught shows
SECONDS = 20.0        # length of each random taught show [s]


RATES = (0.94, 1.06)   # constant playback rates the shaped demo is played at [1]
TAPE_SPEEDS = (0.97, 1.03)  # the sample's music played back this fast, with wow [1]
TAPE_WOW = 0.003      # the tape's wow depth [1] (at 0.7 Hz)


def limited_axis_ticks(show, config, rate: float = 1.0) -> int:
    """Axis-ticks the engine's limits act on when show is played (step mode,
    defaults) at rate, to its end."""
    with Engine(config, show, record=True) as engine:
        engine.set_rate(rate)
        engine.step(math.ceil(show.n_ticks / rate))
        return int(np.count_nonzero(engine.records()["excess"]))


def followed_limited_axis_ticks(show, config, music: Path, speed: float) -> int:
    """Axis-ticks the engine's limits act on when show follows its music played
    back from a tape at speed with wow (step mode, follow smooth, cued at the top)."""
    from marionette.music.feature import loudness, mono, onsets, read_wav
    from marionette.music.follower import sync_ticks
    from marionette.sim.tape import Deck, play
    samples, rate = read_wav(music)
    played = play(mono(samples), rate, Deck(speed=speed, wow=TAPE_WOW, sample_rate=16000.0, seed=18))
    live = sync_ticks(loudness(played.samples, played.sample_rate))
    onset = sync_ticks(onsets(played.samples, played.sample_rate))
    with Engine(config, show, follow="smooth", record=True) as engine:
        for value, strength in zip(live, onset):
            if np.isfinite(value):
                engine.push_loudness(float(value), float(strength))
            engine.step(1)
        return int(np.count_nonzero(engine.records()["excess"]))


def _cli(argv: list[str]) -> None:
    """One `marionette` command in this process, its report kept quiet."""
    from marionette.cli import build_parser
    args = build_parser().parse_args(argv)
    with contextlib.redirect_stdout(io.StringIO()):
        status = args.run(args)
    if status:
        raise MarionetteError(f"bench shape: `marionette {' '.join(argv)}` failed ({status})")


def taught_show(directory: Path, seed: int | None, seconds: float):
    """A show taught without shaping from the teach simulator's recording
    (seed None: the bundled sample), and the figure."""
    from marionette.teach.make_sample import write_sample
    cameras, show = directory / "cameras.toml", directory / "taught.npz"
    if seed is None:
        _cli(["calibrate", "--sample", "-o", str(cameras)])
        _cli(["teach", "--sample", "--cameras", str(cameras), "-o", str(show), "--quiet"])
    else:
        write_sample(directory, seed=seed, duration=seconds)
        _cli(["calibrate", str(directory / "markers.csv"), "-o", str(cameras)])
        _cli(["teach", str(directory / "recording.csv"), "--cameras", str(cameras), "--music",
              str(directory / "music.wav"), "-o", str(show), "--quiet", "--no-shape"])
    config = load_config()
    return load_show(show, config), config


def collect(count: int = COUNT, seed: int = SEED, seconds: float = SECONDS) -> dict:
    t0 = time.perf_counter()
    config = load_config()
    demo = load_show(DEMO_SHOW, config)
    shaped, report = shape_show(demo, config)
    result: dict = {"demo": limited_axis_ticks(demo, config),
                    "demo_shaped": limited_axis_ticks(shaped, config),
                    "demo_shaped_reduced_moves": len(report.infeasible),
                    "demo_moves": report.segments}
    for rate in RATES:
        result[f"demo_shaped_rate_{rate:g}"] = limited_axis_ticks(shaped, config, rate)
    with tempfile.TemporaryDirectory() as tmp:
        sample, _ = taught_show(Path(tmp), None, seconds)          # teach --sample, shaped
        result["sample"] = limited_axis_ticks(sample, config)
    from marionette.teach.make_sample import sample_path
    for speed in TAPE_SPEEDS:
        result[f"sample_followed_tape_{speed:g}"] = followed_limited_axis_ticks(
            sample, config, sample_path("music.wav"), speed)
    before, after, reduced, moves = [], [], 0, 0
    for s in range(seed, seed + count):
        with tempfile.TemporaryDirectory() as tmp:
            taught, _ = taught_show(Path(tmp), s, seconds)
        shaped, report = shape_show(taught, config)                 # as teach shapes it
        before.append(limited_axis_ticks(taught, config))
        after.append(limited_axis_ticks(shaped, config))
        reduced += len(report.infeasible)
        moves += report.segments
    result.update(
        taught_count=count, taught_seed=seed, taught_seconds=seconds,
        taught_unshaped_total=int(sum(before)), taught_unshaped_max=int(max(before, default=0)),
        taught_shaped_total=int(sum(after)), taught_shaped_max=int(max(after, default=0)),
        taught_shaped_nonzero=int(sum(a > 0 for a in after)),
        taught_reduced_moves=reduced, taught_moves=moves)
    climax = climax_timing(config)
    result.update({k: climax[k] for k in ("climax_error_ticks_max_compensated",
                                          "climax_error_ticks_median_compensated",
                                          "alignment_error_ticks_max_compensated",
                                          "limited_axis_ticks_compensated")})
    result["targets"] = {
        "limited == 0 on every shaped show": result["demo_shaped"] == 0 and result["sample"] == 0
        and result["taught_shaped_max"] == 0,
        "limited == 0 at other rates and following": all(
            result[k] == 0 for k in result if k.startswith(("demo_shaped_rate_", "sample_followed_"))),
        f"climax_error_ticks_max_compensated <= {TARGET_TICKS:g}":
            result["climax_error_ticks_max_compensated"] <= TARGET_TICKS}
    result["seconds_taken"] = time.perf_counter() - t0
    return result


def format_table(r: dict) -> str:
    return "\n".join([
        "limited axis-ticks (engine, step mode, default settings; goal 0 when shaped)",
        f"  bundled demo:            {r['demo']:>6d}",
        f"  demo after shape:        {r['demo_shaped']:>6d}   ({r['demo_shaped_reduced_moves']} of "
        f"{r['demo_moves']} moves reduced)",
        f"  teach --sample show:     {r['sample']:>6d}",
        "  demo after shape at rate " + ", ".join(
            f"{rate:g}: {r[f'demo_shaped_rate_{rate:g}']}" for rate in RATES),
        "  teach --sample show following its music from a tape with wow at speed " + ", ".join(
            f"{speed:g}: {r[f'sample_followed_tape_{speed:g}']}" for speed in TAPE_SPEEDS),
        f"  {r['taught_count']} random taught shows ({r['taught_seconds']:g} s, seeds "
        f"{r['taught_seed']}..): unshaped {r['taught_unshaped_total']} in all (max "
        f"{r['taught_unshaped_max']}), shaped {r['taught_shaped_total']} in all (max "
        f"{r['taught_shaped_max']}; {r['taught_reduced_moves']} of {r['taught_moves']} moves reduced)",
        f"climax timing at the simulated servos [ticks]: max {r['climax_error_ticks_max_compensated']:.3f}"
        f", median {r['climax_error_ticks_median_compensated']:.3f} (the servo's extremum; aligned: "
        f"max {r['alignment_error_ticks_max_compensated']:.3f})",
        *(f"  target {label:<45} {verdict(ok)}" for label, ok in r["targets"].items()),
        f"  ({r['seconds_taken']:.0f} s)"])


def register(sub) -> None:
    parser = sub.add_parser("shape", help="limited axis-ticks on shaped shows, climax timing",
                            description=__doc__.split("\n\n")[0].strip("`"))
    parser.add_argument("--count", type=Number(int, 0), default=COUNT,
                        help="random taught shows (about a second each; default %(default)s)")
    parser.add_argument("--seed", type=Number(int, 0), default=SEED, help="first seed of the random shows")
    parser.add_argument("--seconds", type=Number(float, 0.0, 45.0, above=True), default=SECONDS,
                        help="length of each random taught show [s]")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--strict", action="store_true", help=STRICT_HELP)


def run(args) -> int:
    r = collect(args.count, args.seed, args.seconds)
    if args.json:
        json.dump(r, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(format_table(r))
    return exit_status(r["targets"].values(), args.strict)


def main(argv=None) -> int:
    """``python -m marionette.bench.shape``: as ``marionette bench shape``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "shape", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
