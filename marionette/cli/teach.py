"""``marionette teach RECORDING.csv --cameras cameras.toml --music MUSIC.wav -o SHOW.npz``:
turn a recording of the dancer into a show for the figure.

detections -> triangulation -> rucksack pose -> complement one missing LED ->
bridge gaps -> 21-tap FIR -> compress the working area -> resample to the tick ->
axis map -> rotation folded by whole turns -> fit to the figure's limits ->
pragmatic filter (timed parabolic moves) -> show with the music's stored loudness.

The .npz holds the show (marionette.show) and, as extra arrays that the show loader
ignores, every filter stage for ``marionette plot``. Formats: docs/teach.md.
"""
from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path

import numpy as np

from marionette.cli.options import ACCEL_FRACTION, CONFIG_HELP, Number, input_file, output_file
from marionette.config import load_config
from marionette.engine import DEFAULT_LEAD, LEAD_MODES
from marionette.errors import ArgumentError, TeachError
from marionette.music.bands import wav_music_frames
from marionette.music.report import TAUGHT_SHORT_SHARE, recording_warnings
from marionette.progress import Progress
from marionette.shape import POLICIES, last_departure, move_reach, shape_show
from marionette.show import LIMIT_POLICIES, Show, fit_to_figure
from marionette.teach.axis_map import TURN, fold_turns, map_axes, unwind
from marionette.teach.camera_file import CameraFileError, read_cameras
from marionette.teach.filters import DEFAULT_NUMTAPS
from marionette.teach.make_sample import sample_path
from marionette.teach.pipeline import teach_poses
from marionette.teach.recording import read_recording
from marionette.teach.settings import SettingsError, load_settings

# Stages stored in the .npz, in pipeline order: (key, time base, label for plots)
STAGES = (
    ("raw", "set", "raw: LED sets as recorded (gaps where an LED is missing)"),
    ("complemented", "set", "complemented: one missing LED rebuilt (syntactic filter)"),
    ("bridged", "set", "bridged: remaining gaps bridged linearly"),
    ("lowpass", "set", "low-pass: 21-tap FIR"),
    ("compressed", "set", "compressed: dancer's area into the marionette's (x, y only)"),
    ("mapped", "tick", "resampled to the tick and mapped to the axis"),
    ("shaped", "tick", "shaped: parabolic moves between points of rest (pragmatic filter)"),
)
STEPS = ("settings", "cameras", "recording", "poses", "axes", "shaping", "music", "writing")


def _map_stage(pose: np.ndarray, axis_map, names: list[str], home: dict) -> np.ndarray:
    """Axis values (axes, K) of poses (K, 6) that may contain NaN rows [unit]."""
    out = np.full((len(names), pose.shape[0]), np.nan)
    ok = np.all(np.isfinite(pose), axis=1)
    if not ok.any():
        return out
    values = map_axes(pose[ok], axis_map)
    for j, name in enumerate(names):
        out[j, ok] = values[name] if name in values else home[name]
    return out


def _check_inputs(args) -> None:
    if args.sample:
        if args.recording or args.music:
            raise TeachError("give either RECORDING.csv and --music, or --sample, not both")
        args.recording = str(sample_path("recording.csv"))
        args.music = str(sample_path("music.wav"))
    if not args.recording:
        raise TeachError("no recording: give RECORDING.csv (or --sample for the bundled one)")
    if not args.music:
        raise TeachError("no music: give --music MUSIC.wav (its loudness is stored in the show)")
    if Path(args.output).suffix != ".npz":
        raise TeachError(f"{args.output}: teach writes an .npz show (the filter stages for "
                         "`marionette plot` need it); `marionette shape` or Show.save convert")


def run(args) -> int:
    _check_inputs(args)
    progress = Progress(STEPS, enabled=not args.quiet)
    try:
        return _teach(args, progress)
    finally:
        progress.done()


def _teach(args, progress: Progress) -> int:
    progress.step("settings")
    config = load_config(args.config)
    try:
        settings = load_settings(args.settings)
    except SettingsError as exc:
        raise TeachError(str(exc)) from None
    names = config.axis_names
    mapped_names = settings.axis_map.axis_names()
    foreign = [n for n in mapped_names if n not in names]
    if foreign:
        raise TeachError(f"{settings.source}: the map makes axis {foreign[0]!r}, which "
                         f"{config.source} does not have (its axes: {', '.join(names)})")
    home = {a.name: a.home for a in config.axes}
    untaught = [n for n in names if n not in mapped_names]

    progress.step("cameras")
    try:
        cameras = read_cameras(args.cameras)
    except CameraFileError as exc:
        raise TeachError(str(exc)) from None

    progress.step("recording")
    try:
        rec = read_recording(args.recording, n_cameras=len(cameras))
    except ValueError as exc:
        raise TeachError(f"{exc} [{args.cameras} has {len(cameras)} camera(s)]"
                         if "unknown camera" in str(exc) else str(exc)) from None
    if len(rec) == 0:
        raise TeachError(f"{args.recording}: no detections after the header")

    progress.step("poses")
    try:
        stages = teach_poses(rec, cameras, settings.half_side, nonlinear=settings.fit == "nonlinear",
                             max_residual_px=settings.max_residual_px, cutoff_hz=settings.cutoff_hz,
                             compress_x=settings.compress(0), compress_y=settings.compress(1),
                             max_gap=settings.max_gap_s, dt=config.tick_period)
    except ValueError as exc:
        raise TeachError(f"{args.recording}: {exc}") from None

    progress.step("axes")
    z0 = stages.resampled[:, 2]
    amap = settings.axis_map
    if amap.z_ref is None:                    # one reference height for every stage [m]
        amap = dataclasses.replace(amap, z_ref=float(np.mean(z0)))
    stage_values = {key: _map_stage(getattr(stages, key), amap, names, home)
                    for key, base, _ in STAGES if base == "set"}
    stage_values["mapped"] = _map_stage(stages.resampled, amap, names, home)
    _fold_rotation(stage_values["mapped"], config, amap.rotation_name, stages.tick_times,
                   args.lead, args.accel_fraction)
    show = Show(axis_names=list(names), units=[a.unit for a in config.axes],
                positions=stage_values["mapped"].copy(), loudness=np.zeros(stages.tick_times.size),
                tick_period=config.tick_period,
                source=f"teach-in of {args.recording} with {args.cameras}",
                music=os.path.abspath(args.music), path=f"{args.recording} (taught)")
    show = fit_to_figure(show, config, on_limits=args.on_limits)

    progress.step("shaping")
    report = None
    if not args.no_shape:
        show, report = shape_show(show, config, policy=args.policy,
                                  accel_fraction=args.accel_fraction, lead=args.lead)
    stage_values["shaped"] = show.positions

    progress.step("music")
    loud, onset, band_rows = wav_music_frames(args.music, period=config.tick_period)
    n = show.n_ticks
    music_frames = loud.size
    show.loudness = np.concatenate([loud[:n], np.zeros(max(0, n - loud.size))])
    show.onsets = np.concatenate([onset[:n], np.zeros(max(0, n - onset.size))])
    show.bands = np.concatenate([band_rows[:n], np.zeros((max(0, n - len(band_rows)), band_rows.shape[1]))])

    warnings = recording_warnings(args.music, loud, config.tick_period, show.duration, 0.0,
                                  kind="taught music", short_share=TAUGHT_SHORT_SHARE)

    progress.step("writing")
    extra = {"stage_names": np.array([k for k, _, _ in STAGES]),
             "stage_bases": np.array([b for _, b, _ in STAGES]),
             "stage_labels": np.array([lab for _, _, lab in STAGES]),
             "stage_set_times": stages.set_times,
             "stage_tick_times": stages.tick_times}
    extra.update({f"stage_{k}": v for k, v in stage_values.items()})
    save_with_extras(show, args.output, extra)
    progress.done()

    _report(args, config, settings, stages, show, report, untaught, music_frames)
    for line in warnings:           # after the report, where they are seen
        print(line, file=sys.stderr)
    return 0


def _fold_rotation(mapped: np.ndarray, config, name: str, times: np.ndarray, lead: str,
                   accel_fraction: float) -> None:
    """Fold the rotation axis (a row of ``mapped``, changed in place) into its limits by
    whole turns when the dancer turned further than the axis reaches, turning back at
    each wrap, and say so on stderr. Each turn back is as long as the pragmatic filter
    needs to plan it as one move for lead (shape.move_reach), so shaping does not cut
    it. An axis with less than a full turn of range is left to the limits check."""
    if name not in config.axis_names:
        return
    j = config.axis_names.index(name)
    axis = config.axes[j]
    yaw = mapped[j].copy()
    if axis.max - axis.min < TURN or (yaw.min() >= axis.min and yaw.max() <= axis.max):
        return
    fold = fold_turns(yaw, axis.min, axis.max)
    T = config.tick_period
    rate = config.follow.rate_max
    mapped[j] = unwind(fold.values, fold.wraps,
                       lambda d: move_reach(axis, d, T, lead, accel_fraction, rate), T,
                       lambda x: last_departure(x, axis, T, lead, rate))
    at = ", ".join(f"{times[k]:.2f} s" for k in fold.wraps[:5]) + (", ..." if fold.wraps.size > 5 else "")
    print(f"warning: axis {name!r}: the dancer's yaw spans {(yaw.max() - yaw.min()) / TURN:.1f} turns "
          f"(from {yaw.min():.3g} to {yaw.max():.3g} {axis.unit}), beyond its limits "
          f"[{axis.min!r}, {axis.max!r}]; folded by whole turns with {fold.wraps.size} wrap(s)"
          + (f" (at {at}), where the figure turns back, as fast as a shaped move may, until "
             "it meets the dancer's orientation again" if fold.wraps.size else ""),
          file=sys.stderr, flush=True)


def save_with_extras(show: Show, path, extra: dict) -> None:
    """Show.save as .npz, then the same arrays again with the extra ones added."""
    show.save(path)
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    clash = set(arrays) & set(extra)
    if clash:
        raise ArgumentError(f"extra arrays {sorted(clash)} would replace show arrays")
    arrays.update(extra)
    np.savez_compressed(path, **arrays)


def _report(args, config, settings, stages, show, report, untaught, music_frames) -> None:
    T = config.tick_period
    n_sets = stages.set_times.size
    dropped = stages.n_fields - stages.n_points
    print(f"taught {args.recording} -> {args.output}: {config.name}, {len(config.axes)} axes, "
          f"{show.n_ticks} ticks ({show.duration:.2f} s)")
    print(f"  fields: {stages.n_fields} with detections, {stages.n_points} LED points triangulated, "
          f"{dropped} dropped (one camera only, or residual > {settings.max_residual_px:g} px)")
    print(f"  LED sets: {n_sets} at 12.5 Hz; LEDs complemented: {stages.n_complemented}; "
          f"sets lost (>= 2 LEDs missing): {stages.n_lost}")
    if stages.gaps:
        lengths = [b - a for a, b in stages.gaps]
        k = int(np.argmax(lengths))
        a, b = stages.gaps[k]
        print(f"  gaps bridged: {len(stages.gaps)}, longest {lengths[k]:.2f} s "
              f"({a:.2f} s to {b:.2f} s)")
    else:
        print("  gaps bridged: 0")
    print(f"  filters: {DEFAULT_NUMTAPS}-tap FIR low-pass {settings.cutoff_hz:g} Hz; "
          f"x, y compressed from +-{settings.dancer_half:g} m to +-{settings.figure_half:g} m")
    print(f"  axes: {len(config.axes) - len(untaught)} taught"
          + (f", held at home (not in {settings.source}): {', '.join(untaught)}" if untaught else ""))
    changes = [c for c in show.changes if not c.startswith("shaped")]
    for change in changes:
        print(f"  limits: {change}")
    if report is None:
        print("  shaping: skipped (--no-shape)")
    else:
        bad = report.infeasible
        limited = report.limited
        print(f"  segments shaped: {report.segments} moves between points of rest "
              f"(policy {report.policy}, lead {report.lead}); infeasible: {len(bad)}; the engine's "
              f"limits act on {sum(a.ticks for a in limited)} axis-ticks of the show")
        for a in limited:
            print(f"    limited: {a.describe()}")
        for seg in bad[:args.list_infeasible]:
            print(f"    {seg.describe()}")
        if len(bad) > args.list_infeasible:
            print(f"    ... and {len(bad) - args.list_infeasible} more (--list-infeasible N)")
    n = show.n_ticks
    fit = (f"cut to {n}" if music_frames > n else
           f"padded with {n - music_frames} silent frames" if music_frames < n else "as long as the show")
    print(f"  loudness: {music_frames} frames of {T * 1e3:g} ms from {args.music} "
          f"({music_frames * T:.2f} s), {fit}; its onset strength beside it")
    print(f"  duration: {show.duration:.2f} s ({n} ticks of {T * 1e3:g} ms)")
    print(f"wrote {args.output} (show + filter stages for `marionette plot`)")


def register(subparsers) -> None:
    p = subparsers.add_parser("teach", help="recording of the dancer -> show for the figure (teach-in)",
                              description="Turn a recording of the dancer's LEDs into a show for the "
                              "figure, with the music's loudness (docs/teach.md).")
    p.add_argument("recording", nargs="?", type=input_file,
                   help="recording of LED detections (CSV: time_s,camera,led,R,T)")
    p.add_argument("--cameras", required=True, type=input_file,
                   help="cameras file written by `marionette calibrate`")
    music = p.add_mutually_exclusive_group(required=True)
    music.add_argument("--music", metavar="MUSIC.wav", type=input_file,
                       help="the music the dancer danced to (WAV); its loudness goes into the show")
    music.add_argument("--sample", action="store_true",
                       help="use the bundled sample's recording and music (instead of RECORDING "
                            "and --music)")
    p.add_argument("-o", "--output", required=True, type=output_file, help="show to write (.npz)")
    p.add_argument("--config", type=input_file, help=CONFIG_HELP)
    p.add_argument("--settings", type=input_file,
                   help="teach settings TOML (rucksack, filters, areas, axis map); "
                        "default: the bundled one for the bundled figure")
    p.add_argument("--policy", choices=POLICIES, default="reduce",
                   help="pragmatic filter, infeasible moves: reduce the excursion (default), "
                        "borrow time from the preceding rest, or reject (error)")
    p.add_argument("--accel-fraction", type=ACCEL_FRACTION, default=1.0,
                   help=f"plan the moves to this fraction of each top acceleration, {ACCEL_FRACTION.range}")
    p.add_argument("--lead", choices=sorted(LEAD_MODES), default=DEFAULT_LEAD,
                   help="pragmatic filter: the lead the show will be played with (as "
                        "`marionette shape`; default: %(default)s)")
    p.add_argument("--no-shape", action="store_true", help="skip the pragmatic filter")
    p.add_argument("--on-limits", choices=LIMIT_POLICIES, default="error",
                   help="taught positions outside an axis's limits: error (default), clamp, compress")
    p.add_argument("--list-infeasible", type=Number(int, 0), default=5, metavar="N",
                   help="list at most N infeasible moves (default 5)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=run)
