"""Offline pragmatic filtering (Hoffmann 1996, section 6): the points of rest
at musical climaxes -- the extrema of each axis's taught trajectory -- are
joined by timed parabolic moves (parabolic ends, a constant slope no steeper
than the servo's top speed in the middle), so that the figure reaches every
climax exactly at its taught tick, at rest, within the servo's speed and
acceleration limits.

The moves are planned for the command the engine will send: with the lead
"dead_time_lag" it commands x + tau*x' ahead by the dead time, so each move
is smoothed (finite jerk) and planned to limits that leave room for the
feed-forward; the shaped show is then played through the engine in step
mode to check that its limiter stays idle, and an axis where it would act
is planned again with more headroom.

The algorithm is C (ext/mar_shape.c, through marionette._shape); this module
picks the defaults, runs it per axis, checks and reports. Method, profile
choice, feasibility and policies: docs/shaping.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from marionette import _shape
from marionette.config import FigureConfig
from marionette.engine import DEFAULT_LEAD, LEAD_MODES, Engine
from marionette.errors import ArgumentError, ShowError
from marionette.limiter_report import limited_axes
from marionette.show import Show, fit_to_figure

POLICIES = ("reduce", "borrow", "reject")
DEFAULT_PROMINENCE = 0.02       # of the axis's position range [1]
DEFAULT_REST_TOLERANCE = 0.005  # of the axis's position range [1]
HEADROOM = 0.95                 # first plan to this fraction of the limits where the engine
                                # samples between ticks: its cubic interpolation adds a little [1]
HEADROOM_EXACT = 1 - 1e-6       # ... and where it commands the samples themselves: rounding [1]
HEADROOM_STEP = 0.8             # an axis the engine still limits is planned again to this
                                # fraction of its previous headroom ... [1]
HEADROOM_TRIES = 4              # ... at most this many times [1]


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
    lag: float = 0.0         # the lag feed-forward planned for [s]
    headroom: float = 1.0    # fraction of the limits planned to after the engine check [1]
    retried: bool = False    # planned again with less headroom: the engine limited it
    limited: object = None   # limiter_report.AxisLimited: where the engine still limits, or None
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
    lead: str = DEFAULT_LEAD      # the engine's lead mode the show was planned for
    rate_max: float = 1.0         # ... and the fastest playback rate [1] (figure's follow.rate_max)

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
        lines.append(f"  planned for the engine's command with lead {self.lead} at rates up to "
                     f"{self.rate_max:g}"
                     + (f", to {self.accel_fraction:g} of each top acceleration"
                        if self.accel_fraction != 1.0 else ""))
        again = [f"{a.axis} {a.headroom:.2f}" for a in self.axes if a.retried]
        if again:
            lines.append("  planned again with more headroom, as played through the engine: "
                         + ", ".join(again))
        bad = self.infeasible
        lines.append(f"  {len(bad)} of {self.segments} moves infeasible")
        lines.extend(f"    {seg.describe()}" for seg in bad)
        limited = self.limited
        lines.append(f"  the engine's limits act on {sum(a.ticks for a in limited)} axis-ticks "
                     "of the shaped show" + (":" if limited else ""))
        lines.extend(f"    {a.describe()}" for a in limited)
        return "\n".join(lines)

    @property
    def limited(self) -> list:
        """limiter_report.AxisLimited of the axes the engine still limits."""
        return [a.limited for a in self.axes if a.limited is not None]


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


def command_model(axis, lead: str, period: float, rate: float = 1.0) -> tuple[float, float, int]:
    """How the engine turns the show into axis's command (ext/mar_engine.c,
    mar_engine_create) when it plays at rate [1]: (lag feed-forward [s of
    show], how far ahead it samples [s of show], the first tick a move may
    leave so that the first command is at rest [tick]: the cubic
    interpolation at ahead/period reads two samples on; 0 when the engine
    commands the samples themselves). At rate r the command is that of the
    show played at rate 1 with r times the lag and the lead, r times the
    speed and r^2 times the acceleration."""
    if lead not in LEAD_MODES:
        raise ArgumentError(f"lead must be one of {sorted(LEAD_MODES)}, not {lead!r}")
    lag = axis.time_constant if lead == "dead_time_lag" else 0.0
    ahead = {"none": 0.0, "mean_delay": axis.dead_time + axis.time_constant,
             "dead_time_lag": axis.dead_time}[lead]
    return rate * lag, rate * ahead, int(math.floor(rate * ahead / period)) + 2 if ahead > 0 else 0


def position_margin(axis, lag: float, accel: float, period: float) -> float:
    """How far inside its position limits a move must end [unit]: the command
    x + lag*x' overshoots the end by up to lag^2 * accel / 2 (accel: the
    planned acceleration [unit/s^2]), and the limiter's braking bound wants
    about one tick at top acceleration more (max_accel * period^2)."""
    return 0.5 * lag * lag * accel + axis.max_accel * period * period


def plan_limits(axis, headroom: float, accel_fraction: float, rate: float) -> tuple[float, float]:
    """(speed [unit/s], acceleration [unit/s^2]) an axis's moves are planned to,
    before the lag's share (mar_shape_lag_limits), for playback at up to rate."""
    return headroom * axis.max_speed / rate, headroom * accel_fraction * axis.max_accel / rate**2


def first_headroom(axis, lead: str, period: float) -> float:
    """The headroom [1] of an axis's first plan: exact where the engine commands the
    samples themselves, else room for its cubic interpolation."""
    return HEADROOM_EXACT if command_model(axis, lead, period)[1] == 0 else HEADROOM


def move_reach(axis, durations, period: float, lead: str, accel_fraction: float,
               rate: float) -> np.ndarray:
    """How far [unit] a shaped move of each duration [s] reaches on axis, as
    shape_show first plans it for lead and playback at up to rate (the
    figure's follow.rate_max): a move to a point that far, or nearer, in that
    time is not cut (the teach-in sizes the turn back of a folded rotation
    with it)."""
    lag = command_model(axis, lead, period, rate)[0]
    vmax, amax = plan_limits(axis, first_headroom(axis, lead, period), accel_fraction, rate)
    return np.array([_shape.reach_lag(float(d), vmax, amax, lag)[0]
                     for d in np.atleast_1d(durations)])


def last_departure(x, axis, period: float, lead: str, rate: float) -> int:
    """The sample at which shape_show's move up to the last sample of x [unit]
    leaves (the end of the previous point of rest's rest, default prominence and
    rest tolerance), when x is the start of a show played at up to rate."""
    span = axis.max - axis.min
    status, points = _shape.extrema(np.ascontiguousarray(x, dtype=float),
                                    DEFAULT_PROMINENCE * span, DEFAULT_REST_TOLERANCE * span)
    if status < 0 or len(points) < 2:
        return 0
    depart = int(points["rest_end"][-2])
    if len(points) == 2:                        # the first move waits for the lead
        depart = max(depart, min(command_model(axis, lead, period, rate)[2], len(x) - 2))
    return depart


def shape_show(show: Show, config: FigureConfig, policy: str = "reduce",
               prominence=None, rest_tolerance=None, *, accel_fraction: float = 1.0,
               lead: str = DEFAULT_LEAD) -> tuple[Show, ShapeReport]:
    """Join the points of rest of every axis by timed moves that the engine
    can command within every limit.

    prominence [unit]: the smallest excursion that counts as a point of rest
    (default 2 % of each axis's position range); rest_tolerance [unit]: the
    band around an extremum in which the taught trajectory is at rest
    (default 0.5 % of the range). Either may be a number (the same for every
    axis, in that axis's unit) or a mapping axis name -> number.
    policy: what to do with a move that the servo cannot make in its time:
    "reduce" its amplitude, "borrow" time from the preceding rest (then
    reduce), or "reject" (raise ShowError naming every such move).
    accel_fraction (0 < f <= 1): plan to that fraction of each top
    acceleration. lead: the engine's lead mode the show will be played with
    (Engine(lead=...)); the moves are planned for the command it makes
    (command_model) at any rate up to the figure's follow.rate_max (a live
    show follows the music's rate), and the shaped show is played through the
    engine in step mode at rate 1 and at that rate: an axis the limits would
    still cut is planned again
    with more headroom (HEADROOM_STEP, HEADROOM_TRIES), and what remains is
    reported (ShapeReport.limited).

    Returns the shaped show (axes in the figure's order) and the report.
    """
    if policy not in POLICIES:
        raise ArgumentError(f"policy must be one of {POLICIES}, not {policy!r}")
    if not (isinstance(accel_fraction, (int, float)) and 0 < accel_fraction <= 1):
        raise ArgumentError(f"accel_fraction must be in (0, 1], not {accel_fraction!r}")
    if lead not in LEAD_MODES:
        raise ArgumentError(f"lead must be one of {sorted(LEAD_MODES)}, not {lead!r}")
    show = fit_to_figure(show, config)
    proms = _per_axis(prominence, config, DEFAULT_PROMINENCE, "prominence", positive=True)
    tols = _per_axis(rest_tolerance, config, DEFAULT_REST_TOLERANCE, "rest_tolerance",
                     positive=False)
    shaped = np.empty_like(show.positions)
    axes = []
    for j in range(len(config.axes)):
        shaped[j], ax = _shape_one(show, config, j, policy, proms[j], tols[j], accel_fraction,
                                   lead, first_headroom(config.axes[j], lead, config.tick_period))
        axes.append(ax)
    for attempt in range(HEADROOM_TRIES + 1):
        found = {a.axis: a for a in _engine_limits(replace(show, positions=shaped), config, lead)}
        for ax in axes:
            ax.limited = found.get(ax.axis)
        if not found or attempt == HEADROOM_TRIES:
            break
        for j, ax in enumerate(axes):
            if ax.limited is not None:
                shaped[j], axes[j] = _shape_one(show, config, j, policy, proms[j], tols[j],
                                                accel_fraction, lead, ax.headroom * HEADROOM_STEP)
                axes[j].retried = True
    report = ShapeReport(policy=policy, show=show.path, figure=config.name, axes=axes,
                         accel_fraction=accel_fraction, lead=lead,
                         rate_max=config.follow.rate_max)
    bad = report.infeasible
    if policy == "reject" and bad:
        raise ShowError(f"{show.path}: {len(bad)} move(s) exceed the servo limits of "
                        f"{config.source} (policy 'reject'):\n"
                        + "\n".join(f"  {seg.describe()}" for seg in bad))
    changes = list(show.changes)
    changes.append(f"shaped (policy {policy}, lead {lead}): {report.segments} moves between "
                   f"points of rest, {len(bad)} infeasible")
    source = f"{show.source}; shaped, policy {policy}" if show.source else f"shaped, policy {policy}"
    return replace(show, positions=shaped, source=source, changes=changes), report


def _shape_one(show: Show, config: FigureConfig, j: int, policy: str, prominence: float,
               rest_tolerance: float, accel_fraction: float, lead: str, headroom: float
               ) -> tuple[np.ndarray, AxisShape]:
    """Axis j shaped for the engine's command with lead, to headroom [1] of its
    top speed and of accel_fraction times its top acceleration."""
    a = config.axes[j]
    T = config.tick_period
    rate = config.follow.rate_max
    lag, _, first_depart = command_model(a, lead, T, rate)
    vmax, amax = plan_limits(a, headroom, accel_fraction, rate)
    status, out, points, moves = _shape.shape_axis(
        np.ascontiguousarray(show.positions[j]), T, vmax, amax, a.min, a.max, prominence,
        rest_tolerance, policy, lag, position_margin(a, lag, amax, T), first_depart)
    if status < 0:
        raise ShowError(f"{show.path}: axis {a.name!r}: shaping failed "
                        f"(status {status}: {_status_text(status)})")
    infeasible = []
    for m in moves[moves["shortfall"] > 0]:
        action = "rejected" if policy == "reject" else _ACTIONS[int(m["action"]) & 3]
        nominal = int(points["rest_end"][np.searchsorted(points["tick"], m["from_tick"])])
        if m["from_tick"] == points["tick"][0]:     # the first move waits for the lead
            nominal = max(nominal, min(first_depart, int(m["arrive_tick"]) - 1))
        infeasible.append(InfeasibleSegment(
            axis=a.name, unit=a.unit, time_s=float(m["arrive_tick"]) * T,
            depart_s=float(m["depart_tick"]) * T, shortfall=float(m["shortfall"]),
            action=action, reduced_by=float(m["reduced_by"]),
            borrowed_ticks=nominal - int(m["depart_tick"])))
    return out, AxisShape(
        axis=a.name, unit=a.unit, prominence=prominence, rest_tolerance=rest_tolerance,
        extrema=len(points), segments=len(moves), infeasible=infeasible,
        peak_speed=float(moves["peak_speed"].max()) if len(moves) else 0.0,
        peak_accel=float(moves["accel"].max()) if len(moves) else 0.0,
        max_speed=a.max_speed, max_accel=a.max_accel, plan_speed=vmax, plan_accel=amax,
        lag=lag, headroom=headroom, points=points, moves=moves)


def _engine_limits(show: Show, config: FigureConfig, lead: str) -> list:
    """Where the engine's limits cut the commands of show played at rate 1 or at
    the figure's follow.rate_max (the axes limited at either, the larger count)."""
    found = {}
    for rate in (1.0, config.follow.rate_max):
        with Engine(config, show, lead=lead, record=True) as engine:
            engine.set_rate(rate)
            engine.step(math.ceil(show.n_ticks / rate))
            records = engine.records()
        for a in limited_axes(records, config.axis_names, [a.unit for a in config.axes],
                              config.tick_period):
            if a.axis not in found or a.ticks > found[a.axis].ticks:
                found[a.axis] = a
    return [found[name] for name in config.axis_names if name in found]


def _status_text(status: int) -> str:
    import errno
    import os
    name = errno.errorcode.get(-status, "?")
    hint = {"ERANGE": "a point of rest lies outside the axis's position limits",
            "EINVAL": "invalid argument or non-finite position"}.get(name, os.strerror(-status))
    return f"{name}, {hint}"
