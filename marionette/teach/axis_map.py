"""Map generalized coordinates to the marionette's figure axes.

Input: poses (K, 6) = ``(x0, y0, z0 [m], phi, theta, psi [rad])`` per sample, with
``x0, y0`` already compressed into the marionette's stage coordinates
(:class:`marionette.teach.filters.SoftLimit`).  Output: ``{axis name: (K,) array}``
in SI units.  Axis names are configuration, never hard-coded in the computation.

* Horizontal axes: ``x = x0``, ``y = y0`` [m].
* Rotation axis: ``rot = unwrap(psi) + rotation_offset`` [rad] (continuous through
  full turns).  A dancer who turns freely leaves a rotation axis of limited range;
  :func:`fold_turns` brings it back by whole turns, as few times as possible.
* String winches: each winch ``j`` holds the puppet at a point ``p_j`` of the body frame
  (the rucksack frame: origin at the LED square centre, x forward, y left, z up) [m].
  Its value is ``gain_j * dz_j`` with the vertical displacement of that point
  ``dz_j = z_gain (z0 - z_ref) + (R' p_j)_z - p_jz`` [m], where
  ``(R' p)_z = -sin(theta') p_x + cos(theta') sin(phi') p_y + cos(theta') cos(phi') p_z``
  with ``phi' = tilt_gain phi`` and ``theta' = tilt_gain theta`` (yaw does not change
  heights).  Positive = the point rises (string shortens) for ``gain = 1``.  The axis
  value is ``offset_j + gain_j * dz_j``: ``offset_j`` [m] is the winch position of the
  reference pose (e.g. the middle of its travel).
* Floodlights: pan/tilt [rad] aimed from the light position at the puppet point
  ``(x, y, target_height + z_gain (z0 - z_ref))`` [m]: ``pan = atan2(dy, dx) - pan_offset``
  (unwrapped), ``tilt = atan2(dz, hypot(dx, dy))`` (negative = below the light).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Mapping

import numpy as np

from marionette.errors import ArgumentError

TURN = 2.0 * np.pi       # one full turn [rad]


@dataclass
class Winch:
    """One string winch."""

    name: str                                 # axis name
    attach: tuple[float, float, float]        # attachment point, body frame [m]
    gain: float = 1.0                         # axis value per vertical displacement [m/m]
    offset: float = 0.0                       # axis value at zero displacement [m]


@dataclass
class Floodlight:
    """One tracking floodlight (two axes)."""

    pan_name: str                             # pan axis name
    tilt_name: str                            # tilt axis name
    position: tuple[float, float, float]      # light position, stage frame [m]
    target_height: float = 1.0                # aim point height at z0 = z_ref [m]
    pan_offset: float = 0.0                   # direction of pan = 0, from +x to +y [rad]


def default_winches() -> list[Winch]:
    """Nine winches on a plausible figure (body frame: x forward, y left, z up) [m]."""
    return [
        Winch("head", (0.0, 0.0, 0.35)),
        Winch("shoulder_l", (0.0, 0.20, 0.10)),
        Winch("shoulder_r", (0.0, -0.20, 0.10)),
        Winch("hand_l", (0.10, 0.45, -0.30)),
        Winch("hand_r", (0.10, -0.45, -0.30)),
        Winch("knee_l", (0.10, 0.12, -0.90)),
        Winch("knee_r", (0.10, -0.12, -0.90)),
        Winch("foot_l", (0.0, 0.12, -1.35)),
        Winch("foot_r", (0.0, -0.12, -1.35)),
    ]


def default_lights() -> list[Floodlight]:
    """Two floodlights in front of the 1.5 m x 1.5 m stage [m]."""
    return [
        Floodlight("light1_pan", "light1_tilt", (-2.0, -3.0, 4.0)),
        Floodlight("light2_pan", "light2_tilt", (2.0, -3.0, 4.0)),
    ]


@dataclass
class AxisMap:
    """Configuration of the map from generalized coordinates to axes."""

    x_name: str = "x"
    y_name: str = "y"
    rotation_name: str = "rot"
    rotation_offset: float = 0.0              # added to the unwrapped yaw [rad]
    z_gain: float = 1.0                       # vertical scale dancer -> puppet [m/m]
    tilt_gain: float = 1.0                    # scale of roll and pitch [rad/rad]
    z_ref: float | None = None                # z0 of zero winch displacement [m]; None = mean
    winches: list[Winch] = field(default_factory=default_winches)
    lights: list[Floodlight] = field(default_factory=default_lights)

    def __post_init__(self) -> None:
        names = self.axis_names()
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ArgumentError(f"axis names must be unique; duplicated: {dup}")

    def axis_names(self) -> list[str]:
        """All output axis names, in output order."""
        names = [self.x_name, self.y_name, self.rotation_name]
        names += [w.name for w in self.winches]
        for light in self.lights:
            names += [light.pan_name, light.tilt_name]
        return names

    def to_dict(self) -> dict:
        """Plain dict (lists/floats/strings; TOML friendly except a ``None`` z_ref is dropped)."""
        d = asdict(self)
        if d["z_ref"] is None:
            del d["z_ref"]
        for w in d["winches"]:
            w["attach"] = list(w["attach"])
        for light in d["lights"]:
            light["position"] = list(light["position"])
        return d

    @classmethod
    def from_dict(cls, data: Mapping) -> "AxisMap":
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        data = dict(data)
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ArgumentError(f"unknown axis map key(s) {unknown}; known: {sorted(known)}")
        if "winches" in data:
            data["winches"] = [_build(Winch, w, "attach") for w in data["winches"]]
        if "lights" in data:
            data["lights"] = [_build(Floodlight, w, "position") for w in data["lights"]]
        return cls(**data)


def _build(kind, item: Mapping, vector_key: str):
    unknown = sorted(set(item) - set(kind.__dataclass_fields__))
    if unknown:
        raise ArgumentError(f"unknown {kind.__name__} key(s) {unknown}")
    item = dict(item)
    vec = tuple(float(v) for v in item[vector_key])
    if len(vec) != 3:
        raise ArgumentError(f"{kind.__name__} {vector_key} must have 3 entries [m], got {vec}")
    item[vector_key] = vec
    return kind(**item)


def map_axes(pose, config: AxisMap | None = None) -> dict[str, np.ndarray]:
    """Axis trajectories ``{name: (K,)}`` for poses (K, 6) (see module docstring)."""
    config = AxisMap() if config is None else config
    q = np.asarray(pose, float)
    if q.ndim != 2 or q.shape[1] != 6:
        raise ArgumentError(f"pose must have shape (K, 6), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ArgumentError("pose contains NaN/inf; bridge gaps before mapping to axes")
    x0, y0, z0, phi, theta, psi = q.T
    z_ref = float(np.mean(z0)) if config.z_ref is None else float(config.z_ref)
    lift = config.z_gain * (z0 - z_ref)                  # vertical displacement [m]
    out: dict[str, np.ndarray] = {
        config.x_name: x0.copy(),
        config.y_name: y0.copy(),
        config.rotation_name: np.unwrap(psi) + config.rotation_offset,
    }
    f = config.tilt_gain * phi
    t = config.tilt_gain * theta
    for w in config.winches:
        px, py, pz = w.attach
        height = -np.sin(t) * px + np.cos(t) * np.sin(f) * py + np.cos(t) * np.cos(f) * pz
        out[w.name] = w.offset + w.gain * (lift + height - pz)
    for light in config.lights:
        lx, ly, lz = light.position
        dx, dy = x0 - lx, y0 - ly
        dz = light.target_height + lift - lz
        out[light.pan_name] = np.unwrap(np.arctan2(dy, dx) - light.pan_offset)
        out[light.tilt_name] = np.arctan2(dz, np.hypot(dx, dy))
    return out


@dataclass
class Fold:
    """A rotation folded into an axis's range by whole turns (:func:`fold_turns`)."""

    values: np.ndarray       # (K,) folded rotation [rad]
    turns: np.ndarray        # (K,) whole turns added at each sample [1]
    wraps: np.ndarray        # sample indices where ``turns`` changes (the figure turns back)


def fold_turns(angle, lo: float, hi: float) -> Fold:
    """Add whole turns to an unwrapped rotation ``angle`` (K,) [rad] so that every value
    lies in ``[lo, hi]`` [rad], changing the number of turns at the fewest samples.

    The turns are chosen greedily: a run of samples keeps one number of turns while some
    number fits all of them, which gives the fewest changes (each run is as long as it
    can be).  Within a run, the number nearest to the previous run's is taken (0 for the
    first): a rotation that fits is left as it is, and on a range of less than two turns
    a wrap turns the figure back one turn.  Needs ``hi - lo >= TURN`` (every orientation
    reachable).
    """
    a = np.asarray(angle, float)
    if hi - lo < TURN:
        raise ArgumentError(f"range [{lo!r}, {hi!r}] rad is less than a full turn: cannot fold")
    fewest = np.ceil((lo - a) / TURN)       # turns that lift each sample to at least lo [1]
    most = np.floor((hi - a) / TURN)        # turns that keep it at most hi [1]
    turns = np.zeros(a.size, int)
    wraps = []
    prev, start = 0, 0
    run_lo, run_hi = (fewest[0], most[0]) if a.size else (0.0, 0.0)
    for k in range(1, a.size + 1):
        if k < a.size and max(run_lo, fewest[k]) <= min(run_hi, most[k]):
            run_lo, run_hi = max(run_lo, fewest[k]), min(run_hi, most[k])
            continue
        n = int(min(max(prev, run_lo), run_hi))
        turns[start:k] = n
        if start > 0:
            wraps.append(start)
        if k < a.size:
            prev, start, run_lo, run_hi = n, k, fewest[k], most[k]
    values = np.clip(a + TURN * turns, lo, hi)       # the clip only removes rounding [rad]
    return Fold(values, turns, np.array(wraps, int))


def unwind(values, wraps, reach, dt: float, departs=None) -> np.ndarray:
    """Replace the jump of a whole turn at each wrap of a folded rotation ``values`` (K,)
    [rad] by a turn back: a straight run back from the turn's top that ends where it
    first meets the folded rotation again within ``reach``.  ``reach(durations)`` [rad]
    is how far a run may go in each duration [s] (samples ``dt`` [s] apart), e.g.
    ``lambda d: speed * d``, or the pragmatic filter's (marionette.shape.move_reach),
    so that the filter plans each run as one move that fits its time.  A run that
    cannot meet the rotation before the next wrap or the last sample goes as far as
    ``reach`` allows towards it until then.

    ``departs(x)``, if given, is the sample at which the filter's move up to the last
    sample of ``x`` leaves (marionette.shape.last_departure): where the rise into a
    wrap from there is farther than ``reach`` in its time (the dancer turns faster
    than the figure can), the top is reached later, on a straight run, and the turn
    back starts there; the top is the figure's own, no climax of the dance, so it is
    moved in time rather than cut.  Every run lies between two values inside the
    range, so it stays inside; the figure shows the turn back instead of a jump that
    no servo can follow."""
    out = np.array(values, float)
    ends = list(wraps[1:]) + [out.size - 1]
    begin = 0                                   # where the rise into the next wrap may start
    for k, end in zip(wraps, ends):
        top, apex = out[k - 1], k - 1           # [rad], [sample]
        if departs is not None:
            d = begin + int(departs(out[begin:k]))
            fits = np.flatnonzero(reach(dt * np.arange(1, end - d + 1)) >= abs(top - out[d]))
            late = min(d + 1 + int(fits[0]) if fits.size else end, end - 1)
            if late > apex:                     # a straight rise to the top, reached late
                apex = late
                out[d + 1:apex + 1] = out[d] + (top - out[d]) * np.arange(1, apex - d + 1) / (apex - d)
        far = np.asarray(reach(dt * np.arange(1, end - apex + 1)), float)   # at apex+1..end [rad]
        met = np.flatnonzero(np.abs(out[apex + 1:end + 1] - top) <= far)
        if met.size:
            steps = met[0] + 1
            out[apex + 1:apex + steps] = top + (out[apex + steps] - top) * np.arange(1, steps) / steps
            begin = apex + steps
        else:
            goal = out[end]
            out[apex + 1:end + 1] = top + np.sign(goal - top) * np.minimum(far, abs(goal - top))
            begin = end
    return out
