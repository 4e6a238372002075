"""``marionette plot SHOW.npz --axis NAME -o stages.png``: the filter stages of one
axis of a taught show, one above the other (like Fig. 6 of Hoffmann 1996).

The stages are the extra arrays ``marionette teach`` stores in the .npz (docs/teach.md).
Each panel draws its stage in colour over the previous stage in grey, so that what
the step changed stands out. Needs matplotlib (the ``plot`` extra); draws with the
Agg backend (no display).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from marionette.cli.options import Number, image_file, input_file
from marionette.errors import ShowError, TeachError
from marionette.npzfile import read_npz
from marionette.show import load_show

DPI = Number(int, 10, 1200)        # [dots per inch]
COLOURS = ("tab:red", "tab:orange", "tab:olive", "tab:green", "tab:cyan", "tab:blue", "tab:purple")


def read_stages(path: Path) -> dict:
    """Stage arrays of a taught .npz: names, labels, times and (axes, samples) values."""
    z = read_npz(path, TeachError)
    if "stage_names" not in z:
        raise TeachError(f"{path}: no filter stages in this show (only shows written by "
                         "`marionette teach` have them)")
    names = [str(n) for n in z["stage_names"]]
    wanted = ["stage_labels", "stage_bases", "stage_set_times", "stage_tick_times"]
    missing = [k for k in wanted + [f"stage_{n}" for n in names] if k not in z]
    if missing:
        raise TeachError(f"{path}: stage array {missing[0]!r} is missing")
    return {"names": names, "labels": [str(s) for s in z["stage_labels"]],
            "bases": [str(s) for s in z["stage_bases"]],
            "set": z["stage_set_times"], "tick": z["stage_tick_times"],
            "values": {n: z[f"stage_{n}"] for n in names}}


def run(args) -> int:
    path = Path(args.show)
    if path.suffix != ".npz":
        raise TeachError(f"{path}: plot reads the .npz shows that `marionette teach` writes")
    show = load_show(path)                       # checks that it is a valid show at all
    if args.axis not in show.axis_names:
        raise ShowError(f"{path}: no axis {args.axis!r} (axes: {', '.join(show.axis_names)})")
    stages = read_stages(path)
    try:
        import matplotlib
    except ImportError:
        raise TeachError("plot needs matplotlib: pip install 'marionette[plot]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    j = show.axis_names.index(args.axis)
    unit = show.units[j]
    n = len(stages["names"])
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.45 * n + 1.0), sharex=True)
    previous = None
    for k, (name, label, base) in enumerate(zip(stages["names"], stages["labels"], stages["bases"])):
        ax = axes[k]
        t = stages[base]
        y = stages["values"][name][j]
        if previous is not None:
            ax.plot(previous[0], previous[1], color="0.7", lw=1.0)     # the stage before
        style = dict(marker=".", ms=3, lw=0.8) if base == "set" else dict(lw=1.2)
        ax.plot(t, y, color=COLOURS[k % len(COLOURS)], **style)
        title = f"({chr(ord('A') + k)}) {label}"
        if name == "raw":
            gaps = t[~np.isfinite(y)]
            if gaps.size and np.isfinite(y).any():
                ax.plot(gaps, np.full(gaps.size, np.nanmin(y)), "|", color="k", ms=8)
                title += f"; | = {gaps.size} sets with a missing LED"
        ax.set_title(title, fontsize=9, loc="left")
        ax.set_ylabel(unit)
        ax.grid(True, lw=0.3, alpha=0.6)
        ax.tick_params(labelsize=8)
        previous = (t, y)
    axes[-1].set_xlabel("time [s] (0 = start of the music)")
    fig.suptitle(f"{args.axis}: filter stages of {path.name}", fontsize=11)
    fig.tight_layout()
    fig.savefig(args.output, dpi=args.dpi)
    plt.close(fig)
    print(f"wrote {args.output}: {n} stages of axis {args.axis!r} [{unit}], "
          f"{stages['set'].size} sets, {stages['tick'].size} ticks")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("plot", help="plot the filter stages of one axis of a taught show",
                              description="Plot the filter stages of one axis of a show written by "
                              "`marionette teach`, one above the other (docs/teach.md).")
    p.add_argument("show", type=input_file, help="show written by `marionette teach` (.npz)")
    p.add_argument("--axis", required=True, help="axis name, as in the figure")
    p.add_argument("-o", "--output", required=True, type=image_file,
                   help="image to write (.png, .pdf, .svg, ...)")
    p.add_argument("--dpi", type=DPI, default=100,
                   help=f"resolution of raster images, {DPI.range} (default 100)")
    p.set_defaults(run=run)
