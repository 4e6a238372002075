"""``marionette calibrate MARKERS.csv -o cameras.toml``: identify the cameras from
known markers (Hoffmann 1996, eq. 4.8-4.9).

For every camera of the marker file: a starting guess (linear, from the markers, or
from ``--guess``), then Levenberg-Marquardt (default) or the paper's steepest descent
on the sum of squared marker errors; per camera the residual, the iterations and the
standard uncertainty of every parameter are printed, and cameras.toml is written for
``marionette teach``. Formats: docs/teach.md.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from marionette.cli.options import Number, input_file, output_file
from marionette.errors import TeachError
from marionette.teach.calibration import MIN_MARKERS, calibrate
from marionette.teach.camera import IDEAL_PARAMETER_NAMES, PARAMETER_NAMES, UNITS
from marionette.teach.camera_file import CameraFileError, read_cameras, write_cameras
from marionette.teach.guess import starting_guess
from marionette.teach.make_sample import sample_path
from marionette.teach.markers import read_markers

SOLVERS = {"lm": "lm", "steepest-descent": "steepest_descent"}
SOLVER_NAMES = {"lm": "Levenberg-Marquardt", "steepest_descent": "steepest descent (the paper's)"}
MODELS = {"ideal": IDEAL_PARAMETER_NAMES, "improved": PARAMETER_NAMES}


def image_size(text: str) -> tuple[int, int]:
    """'512x512' -> (columns, rows) [pixel]."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise TeachError(f"--image-size {text!r}: expected COLUMNSxROWS, e.g. 512x512") from None
    if w < 2 or h < 2:
        raise TeachError(f"--image-size {text!r}: both sizes must be >= 2 pixels")
    return w, h


def _guesses(args, markers, size):
    """Starting camera per camera: from --guess, else linear from the markers."""
    w, h = size
    R0, T0 = (w - 1) / 2.0, (h - 1) / 2.0          # optical axis at the image centre [pixel]
    half_diagonal = 0.5 * math.hypot(w, h)          # [pixel]
    if args.guess:
        try:
            given = read_cameras(args.guess)
        except CameraFileError as exc:
            raise TeachError(str(exc)) from None
        if len(given) != len(markers):
            raise TeachError(f"{args.guess}: {len(given)} camera(s), but {args.markers} has "
                             f"{len(markers)}")
        given = [dataclasses.replace(g, R0=R0, T0=T0, rho_max=half_diagonal / g.L) for g in given]
        return given, f"from {args.guess}"
    out = []
    for k, cm in enumerate(markers):
        try:
            out.append(starting_guess(cm.points, cm.pixels, R0, T0, image_diagonal_half=half_diagonal))
        except ValueError as exc:
            raise TeachError(f"{args.markers}: camera {k}: no starting guess: {exc}; "
                             "give one with --guess CAMERAS.toml") from None
    return out, "linear (from the markers)"


def run(args) -> int:
    if args.sample:
        if args.markers:
            raise TeachError("give either MARKERS.csv or --sample, not both")
        args.markers = str(sample_path("markers.csv"))
    if not args.markers:
        raise TeachError("no marker file: give MARKERS.csv (or --sample for the bundled one)")
    path = Path(args.markers)
    try:
        markers = read_markers(path)
    except ValueError as exc:
        raise TeachError(str(exc)) from None
    for k, cm in enumerate(markers):
        if len(cm.names) < MIN_MARKERS:
            raise TeachError(f"{path}: camera {k}: calibration needs at least {MIN_MARKERS} "
                             f"markers, the file has {len(cm.names)} ({', '.join(cm.names)})")
    size = image_size(args.image_size)
    guesses, guess_kind = _guesses(args, markers, size)
    method = SOLVERS[args.solver]
    free = MODELS[args.model]
    print(f"{path}: {len(markers)} camera(s); {SOLVER_NAMES[method]}, {args.model} model "
          f"({len(free)} parameters), {args.residual} residual; starting guess {guess_kind}")
    results = []
    for k, (cm, guess) in enumerate(zip(markers, guesses)):
        options = {"free": free, "residual": args.residual, "labels": cm.names}
        if args.max_iter is not None:
            options["max_iter"] = args.max_iter
        try:
            res = calibrate(cm.points, cm.pixels, guess, method=method, **options)
        except ValueError as exc:
            raise TeachError(f"{path}: camera {k}: {exc}") from None
        results.append(res)
        _print_camera(k, cm, res)
    info = [{"markers_file": str(path), "markers": len(cm.names), "method": r.method,
             "model": args.model, "residual": r.residual_kind, "F": r.F, "rms_px": r.rms_px,
             "max_px": float(np.max(np.hypot(*r.residuals_px.T))), "iterations": r.iterations,
             "converged": r.converged, "condition": r.condition}
            for cm, r in zip(markers, results)]
    write_cameras(args.output, [r.params for r in results], info, [r.uncertainty for r in results],
                  comment=f"cameras identified by `marionette calibrate` from {path}")
    print(f"wrote {args.output}")
    return 0


def _print_camera(k, cm, res) -> None:
    unit_F = "m^2" if res.residual_kind == "algebraic" else "pixel^2"
    err = np.hypot(*res.residuals_px.T)                     # per marker [pixel]
    worst = int(np.argmax(err))
    state = "converged" if res.converged else "NOT converged"
    print(f"camera {k}: {len(cm.names)} markers; {state} after {res.iterations} iterations "
          f"({res.evaluations} evaluations){'' if res.converged else ', the limit'}")
    print(f"  residual F = {res.F:.4g} {unit_F}; reprojection rms {res.rms_px:.3f} px, "
          f"worst {err[worst]:.3f} px (marker {cm.names[worst]}, line {cm.lines[worst]}); "
          f"condition {res.condition:.3g}")
    print(f"  {'parameter':<10}{'value':>14}{'uncertainty':>14}")
    for name in res.free:
        value, sigma, unit = getattr(res.params, name), res.uncertainty[name], UNITS[name]
        if unit == "rad":
            print(f"  {name:<10}{math.degrees(value):>14.4f}{math.degrees(sigma):>14.4f}  deg")
        else:
            print(f"  {name:<10}{value:>14.4f}{sigma:>14.4f}  {unit}")
    if not res.converged:
        print(f"  warning: camera {k} did not converge; the values may be inaccurate "
              "(try --solver lm or a larger --max-iter)")


def register(subparsers) -> None:
    p = subparsers.add_parser("calibrate", help="identify the cameras from known markers (teach-in)",
                              description="Identify the cameras from known markers and write "
                              "cameras.toml for `marionette teach` (docs/teach.md).")
    p.add_argument("markers", nargs="?", type=input_file,
                   help="marker file (CSV: camera,marker,x,y,z,R,T)")
    p.add_argument("-o", "--output", required=True, type=output_file,
                   help="cameras file to write (TOML)")
    p.add_argument("--sample", action="store_true", help="use the bundled sample's markers")
    p.add_argument("--solver", choices=sorted(SOLVERS), default="lm",
                   help="lm: Levenberg-Marquardt (default, fast); steepest-descent: the paper's "
                        "method (thousands of iterations)")
    p.add_argument("--model", choices=sorted(MODELS), default="ideal",
                   help="ideal: position, angles, L (7 parameters); improved: also the tilt of "
                        "the pixel plane and the radial rectification (11; needs about 20 markers)")
    p.add_argument("--residual", choices=("algebraic", "pixel"), default="algebraic",
                   help="minimise the paper's eq. 4.8 error [m] or the reprojection error [pixel]")
    p.add_argument("--image-size", default="512x512",
                   help="sensor COLUMNSxROWS [pixel]; the optical axis is its centre (default 512x512)")
    p.add_argument("--guess", type=input_file,
                   help="starting cameras (cameras.toml format; angles or target = "
                        "[x, y, z]); default: found linearly from the markers")
    p.add_argument("--max-iter", type=Number(int, 1),
                   help="iteration limit (default 200 for lm, 20000 for "
                        "steepest-descent)")
    p.set_defaults(run=run)
