"""Offline pragmatic filtering (Hoffmann 1996, section 6): the points of rest
at musical climaxes -- the extrema of each axis's taught trajectory -- are
joined by timed parabolic moves (parabolic ends, a constant slope no steeper
than the servo's top speed in the middle), so that the figure reaches every
climax exactly at its taught tick, at rest, within the servo's speed and
acceleration limits.

The algorithm is C (ext/mar_shape.c, through marionette._shape); this module
picks the defaults, runs it per axis and reports. Method, profile choice,
feasibility and policies: docs/shaping.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from marionette import _shape
from marionette.config import FigureConfig
from marionette.errors import ArgumentError, ShowError
from marionette.show import Show, fit_to_figure

POLICIES = ("reduce", "borrow", "reject")
DEFAULT_PROMINENCE = 0.02       # of the axis's position range [1]
DEFAULT_REST_TOLERANCE = 0.005  # of the axis's position range [1]


@dataclass(frozen=True)
class InfeasibleSegment:
    """A move that could not reach its climax's taught value in its time."""

    axis: str
    unit: str
    time_s: float        # the climax the move arrives at [s] (its taught time, kept)
    depart_s: float      # when the move leaves its previous point of rest [s]
    shortfall: float     # |D| - reachable |D| over the nominal window [unit]
    action: str          # "reduced", "borrowed", "borrowed+reduced" or "rejected"
    reduced_by: float    # how far the climax's value was moved toward the start [unit]
    borrowed_ticks: int  # how many ticks earlier than nominal the move left [tick]

    def describe(self) -> str:
        u = self.unit
        what = {"reduced": f"reduced by {self.reduced_by:.6g} {u}",
                "borrowed": f"left {self.borrowed_ticks} ticks early",
                "borrowed+reduced": f"left {self.borrowed_ticks} ticks early, "
                                    f"then reduced by {self.reduced_by:.6g} {u}",
                "rejected": "rejected"}[self.action]
        return (f"axis {self.axis!r} at {self.time_s:.3f} s: short by "
                f"{self.shortfall:.6g} {u}; {what}")


@dataclass
class AxisShape:
    """What shaping did to one axis."""

    axis: str
    unit: str
    prominence: float        # [unit]
    rest_tolerance: float    # [unit]
    extrema: int             # points of rest, the two ends included
    segments: int            # moves between them
    infeasible: list[InfeasibleSegment]
    peak_speed: float        # fastest move's cruise speed [unit/s]
    peak_accel: float        # largest ramp acceleration [unit/s^2]
    max_speed: float         # the servo's top speed [unit/s]
    max_accel: float         # the servo's top acceleration [unit/s^2]
    plan_speed: float = 0.0  # speed the moves were planned to [unit/s]
    plan_accel: float = 0.0  # acceleration the moves were planned to [unit/s^2]
    points: np.ndarray = field(repr=False, default=None)     # _shape.EXTREMUM_DTYPE
    moves: np.ndarray = field(repr=False, default=None)      # _shape.SEGMENT_DTYPE


@dataclass
class ShapeReport:
    """Per axis: points of rest, moves, and every infeasible move."""

    policy: str
    show: str
    figure: str
    axes: list[AxisShape]
    accel_fraction: float = 1.0   # planned to this fraction of each top acceleration [1]
    lag_headroom: bool = False    # speed planned to leave room for the lag feed-forward

    @property
    def infeasible(self) -> list[InfeasibleSegment]:
        return [seg for a in self.axes for seg in a.infeasible]

    @property
    def segments(self) -> int:
        return sum(a.segments for a in self.axes)

    def axis(self, name: str) -> AxisShape:
        for a in self.axes:
            if a.axis == name:
                return a
        raise KeyError(name)

    def __str__(self) -> str:
        lines = [f"shaped {self.show} for {self.figure}, policy {self.policy}; "
                 "speed and accel: the fastest move's, over the servo's limits",
                 f"  {'axis':<18}{'unit':>5}{'prominence':>12}{'extrema':>9}{'moves':>7}"
                 f"{'infeasible':>12}{'speed/max':>11}{'accel/max':>11}"]
        for a in self.axes:
            lines.append(f"  {a.axis:<18}{a.unit:>5}{a.prominence:>12.4g}{a.extrema:>9d}"
                         f"{a.segments:>7d}{len(a.infeasible):>12d}"
                         f"{a.peak_speed / a.max_speed:>11.2f}{a.peak_accel / a.max_accel:>11.2f}")
        if self.accel_fraction != 1.0 or self.lag_headroom:
            lines.append(f"  planned to {self.accel_fraction:g} of each top acceleration"
                         + (", top speed less tau * that acceleration (lag headroom)"
                            if self.lag_headroom else ""))
        bad = self.infeasible
        lines.append(f"  {len(bad)} of {self.segments} moves infeasible")
        lines.extend(f"    {seg.describe()}" for seg in bad)
        return "\n".join(lines)


def _per_axis(value, config: FigureConfig, default_fraction: float, what: str,
              positive: bool) -> list[float]:
    """One value per axis [unit]: None -> fraction of the range; a number; a mapping."""
    out = []
    for a in config.axes:
        if value is None:
            v = default_fraction * (a.max - a.min)
        elif isinstance(value, Mapping):
            v = value.get(a.name, default_fraction * (a.max - a.min))
        else:
            v = value
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
            raise ArgumentError(f"{what} for axis {a.name!r} is {v!r}, not a number")
        v = float(v)
        if not math.isfinite(v) or v < 0 or (positive and v == 0):
            raise ArgumentError(f"{what} for axis {a.name!r} must be a finite number "
                                f"{'> 0' if positive else '>= 0'}, not {v!r}")
        out.append(v)
    if isinstance(value, Mapping):
        unknown = set(value) - set(config.axis_names)
        if unknown:
            raise ArgumentError(f"{what}: unknown axis {sorted(unknown)[0]!r}")
    return out


_ACTIONS = {_shape.ACT_REDUCED: "reduced", _shape.ACT_BORROWED: "borrowed",
            _shape.ACT_BORROWED | _shape.ACT_REDUCED: "borrowed+reduced"}


def planning_limits(axis, accel_fraction: float = 1.0, lag_headroom: bool = False
                    ) -> tuple[float, float]:
    """(speed [unit/s], acceleration [unit/s^2]) the moves of an axis are planned to.

    accel_fraction of the servo's top acceleration; with lag_headroom, the
    speed leaves room for the engine's lag feed-forward (lead
    "dead_time_lag": command = x + tau*x'): speed + tau*accel <= top speed,
    with tau*accel at most half the top speed."""
    accel = accel_fraction * axis.max_accel
    speed = axis.max_speed
    if lag_headroom and axis.time_constant > 0:
        accel = min(accel, 0.5 * axis.max_speed / axis.time_constant)
        speed = axis.max_speed - axis.time_constant * accel
    return speed, accel


def shape_show(show: Show, config: FigureConfig, policy: str = "reduce",
               prominence=None, rest_tolerance=None, *, accel_fraction: float = 1.0,
               lag_headroom: bool = False) -> tuple[Show, ShapeReport]:
    """Join the points of rest of every axis by timed parabolic moves.

    prominence [unit]: the smallest excursion that counts as a point of rest
    (default 2 % of each axis's position range); rest_tolerance [unit]: the
    band around an extremum in which the taught trajectory is at rest
    (default 0.5 % of the range). Either may be a number (the same for every
    axis, in that axis's unit) or a mapping axis name -> number.
    policy: what to do with a move that the servo cannot make in its time:
    "reduce" its amplitude, "borrow" time from the preceding rest (then
    reduce), or "reject" (raise ShowError naming every such move).
    accel_fraction (0 < f <= 1) and lag_headroom plan the moves below the
    servo's limits (planning_limits), leaving room for the engine's lag
    feed-forward: a show to be played with lead "dead_time_lag" keeps its
    climaxes on time only if the compensated command stays inside the limits
    (docs/shaping.md; marionette.bench.climax measures it).

    Returns the shaped show (axes in the figure's order) and the report.
    """
    if policy not in POLICIES:
        raise ArgumentError(f"policy must be one of {POLICIES}, not {policy!r}")
    if not (isinstance(accel_fraction, (int, float)) and 0 < accel_fraction <= 1):
        raise ArgumentError(f"accel_fraction must be in (0, 1], not {accel_fraction!r}")
    show = fit_to_figure(show, config)
    proms = _per_axis(prominence, config, DEFAULT_PROMINENCE, "prominence", positive=True)
    tols = _per_axis(rest_tolerance, config, DEFAULT_REST_TOLERANCE, "rest_tolerance",
                     positive=False)
    T = config.tick_period
    shaped = np.empty_like(show.positions)
    axes = []
    for j, a in enumerate(config.axes):
        vmax, amax = planning_limits(a, accel_fraction, lag_headroom)
        status, out, points, moves = _shape.shape_axis(
            np.ascontiguousarray(show.positions[j]), T, vmax, amax,
            a.min, a.max, proms[j], tols[j], policy)
        if status < 0:
            raise ShowError(f"{show.path}: axis {a.name!r}: shaping failed "
                            f"(status {status}: {_status_text(status)})")
        shaped[j] = out
        infeasible = []
        for m in moves[moves["shortfall"] > 0]:
            action = "rejected" if policy == "reject" else _ACTIONS[int(m["action"]) & 3]
            nominal = int(points["rest_end"][np.searchsorted(points["tick"], m["from_tick"])])
            infeasible.append(InfeasibleSegment(
                axis=a.name, unit=a.unit, time_s=float(m["arrive_tick"]) * T,
                depart_s=float(m["depart_tick"]) * T, shortfall=float(m["shortfall"]),
                action=action, reduced_by=float(m["reduced_by"]),
                borrowed_ticks=nominal - int(m["depart_tick"])))
        axes.append(AxisShape(
            axis=a.name, unit=a.unit, prominence=proms[j], rest_tolerance=tols[j],
            extrema=len(points), segments=len(moves), infeasible=infeasible,
            peak_speed=float(moves["peak_speed"].max()) if len(moves) else 0.0,
            peak_accel=float(moves["accel"].max()) if len(moves) else 0.0,
            max_speed=a.max_speed, max_accel=a.max_accel, plan_speed=vmax, plan_accel=amax,
            points=points, moves=moves))
    report = ShapeReport(policy=policy, show=show.path, figure=config.name, axes=axes,
                            accel_fraction=accel_fraction, lag_headroom=lag_headroom)
    bad = report.infeasible
    if policy == "reject" and bad:
        raise ShowError(f"{show.path}: {len(bad)} move(s) exceed the servo limits of "
                        f"{config.source} (policy 'reject'):\n"
                        + "\n".join(f"  {seg.describe()}" for seg in bad))
    changes = list(show.changes)
    changes.append(f"shaped (policy {policy}): {report.segments} moves between points of rest, "
                   f"{len(bad)} infeasible")
    source = f"{show.source}; shaped, policy {policy}" if show.source else f"shaped, policy {policy}"
    return replace(show, positions=shaped, source=source, changes=changes), report


def _status_text(status: int) -> str:
    import errno
    import os
    name = errno.errorcode.get(-status, "?")
    hint = {"ERANGE": "a point of rest lies outside the axis's position limits",
            "EINVAL": "invalid argument or non-finite position"}.get(name, os.strerror(-status))
    return f"{name}, {hint}"
