"""Where the engine's hard limits acted, per axis, from flight-recorder records.

Each record carries, per axis, the excess: the target the limits did not let
the command reach minus the command [unit], 0 where they did not act
(ext/mar_engine.h). From it: which axes were limited, when (runs of
consecutive limited ticks, in show time), and the largest excess. `play`
prints these lines and warns on stderr when the limits acted on more than
WARN_AXIS_TICKS axis-ticks; `shape` uses the same figures to check a shaped
show against the engine's command.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass

import numpy as np

WARN_AXIS_TICKS = 5     # more limited axis-ticks than this: play warns [axis-ticks]
MAX_SPANS = 3           # time ranges named per axis, the longest first [1]


@dataclass(frozen=True)
class AxisLimited:
    """The ticks on which the limits acted on one axis."""

    axis: str
    unit: str
    ticks: int                           # limited ticks [tick]
    spans: list[tuple[float, float]]     # runs of limited ticks, show time [s], longest first
    runs: int                            # how many runs in all [1]
    max_excess: float                    # largest |target - command| [unit]
    max_excess_s: float                  # where, show time [s]

    def describe(self) -> str:
        shown = ", ".join(f"{a:.2f}-{b:.2f} s" if b > a else f"{a:.2f} s" for a, b in self.spans)
        more = f" and {self.runs - len(self.spans)} more" if self.runs > len(self.spans) else ""
        return (f"{self.axis}: {self.ticks} ticks in {self.runs} run(s) ({shown}{more}); "
                f"largest excess {self.max_excess:.4g} {self.unit} at {self.max_excess_s:.2f} s")


def limited_axes(records: np.ndarray, names, units, period: float) -> list[AxisLimited]:
    """Per axis on which the limits acted, most limited ticks first.

    records: flight-recorder records (marionette._core.record_dtype); names,
    units: the axes'; period: the tick [s]. Times are show positions
    (records["position"] * period)."""
    excess = records["excess"]
    hit = excess != 0                                      # NaN too: a non-finite target
    show_s = records["position"] * period                  # [s]
    out = []
    for j in np.flatnonzero(hit.any(axis=0)):
        h = hit[:, j]
        edges = np.diff(np.concatenate([[0], h.astype(np.int8), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        order = np.argsort(-(ends - starts), kind="stable")[:MAX_SPANS]
        size = np.where(np.isnan(excess[:, j]), np.inf, np.abs(excess[:, j]))
        k = int(np.argmax(size))
        out.append(AxisLimited(
            axis=names[j], unit=units[j], ticks=int(h.sum()),
            spans=[(float(show_s[starts[i]]), float(show_s[ends[i]])) for i in order],
            runs=len(starts), max_excess=float(size[k]), max_excess_s=float(show_s[k])))
    out.sort(key=lambda a: -a.ticks)
    return out


def summary(records: np.ndarray, config, period: float) -> tuple[list[str], str | None]:
    """(lines for play's summary, a warning for stderr or None)."""
    found = limited_axes(records, config.axis_names, [a.unit for a in config.axes], period)
    total = sum(a.ticks for a in found)
    lines = [f"  limits acted on {total} axis-ticks" + (f", on {len(found)} axes:" if found else "")]
    lines.extend(f"    {a.describe()}" for a in found)
    warning = None
    if total > WARN_AXIS_TICKS:
        worst = found[0]
        warning = (f"warning: the limits cut the commands on {total} axis-ticks (most on "
                   f"{worst.axis}: {worst.ticks} ticks, by up to {worst.max_excess:.4g} {worst.unit}); "
                   "there the figure is not where the show wants it. `marionette shape` plans "
                   "a show that the engine can command within the limits")
    return lines, warning


def print_summary(records: np.ndarray, config, period: float, json_lines: bool = False) -> None:
    """The summary lines on stdout, the warning (if any) on stderr: as a
    JSON object {"warning": ...} where stderr carries JSON lines (play --json)."""
    lines, warning = summary(records, config, period)
    print("\n".join(lines))
    if warning:
        print(json.dumps({"warning": warning}) if json_lines else warning, file=sys.stderr)
