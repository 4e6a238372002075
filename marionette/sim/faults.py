"""Faults the simulator injects, to show the control PC survives them.

Every random choice comes from one seeded generator, so a run is
repeatable for the same input."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from marionette.errors import ArgumentError


@dataclass
class Faults:
    drop_rate: float = 0.0          # probability each received byte is lost
    corrupt_rate: float = 0.0       # probability each received byte gets one bit flipped
    delay: float = 0.0              # extra time before a node acts on what it received [s]
    position_noise: float = 0.0     # std dev of the reported position [counts]
    silent: set[int] = field(default_factory=set)   # nodes that neither listen nor answer
    seed: int = 0
    nodes: frozenset[int] = frozenset()             # the figure's nodes, for 'silence N' (empty: any)
    rng: np.random.Generator = field(init=False, repr=False)
    bytes_dropped: int = 0
    bytes_corrupted: int = 0

    def __post_init__(self):
        self.rng = np.random.default_rng(self.seed)

    def mangle(self, data: bytes) -> bytes:
        """The bytes as a noisy line delivers them."""
        if not data or (self.drop_rate <= 0 and self.corrupt_rate <= 0):
            return data
        x = np.frombuffer(data, np.uint8).copy()
        flip = self.rng.random(len(x)) < self.corrupt_rate
        x[flip] ^= (1 << self.rng.integers(0, 8, int(flip.sum()))).astype(np.uint8)
        keep = self.rng.random(len(x)) >= self.drop_rate
        self.bytes_corrupted += int(flip.sum())
        self.bytes_dropped += int((~keep).sum())
        return x[keep].tobytes()

    def noise(self, n: int) -> np.ndarray:
        """Noise to add to n reported positions [counts]."""
        if self.position_noise <= 0:
            return np.zeros(n)
        return self.rng.normal(0.0, self.position_noise, n)

    def apply(self, command: str) -> str:
        """A control line from the simulator's stdin, e.g. 'silence 3',
        'resume 3', 'drop 0.01', 'corrupt 0.001', 'delay 0.005', 'noise 2'.
        Returns what changed, or raises ArgumentError naming the line and value."""
        words = command.split()
        if len(words) != 2:
            raise ArgumentError(f"fault command {command!r}: expected '<name> <value>'")
        name, value = words
        if name in ("silence", "resume"):
            try:
                node = int(value)
            except ValueError:
                raise ArgumentError(f"fault command {command!r}: node {value!r} is not a whole "
                                    "number") from None
            if self.nodes and node not in self.nodes:
                raise ArgumentError(f"fault command {command!r}: there is no node {node} "
                                    f"(nodes: {', '.join(map(str, sorted(self.nodes)))})")
            (self.silent.add if name == "silence" else self.silent.discard)(node)
            return f"node {node} {'silenced' if name == 'silence' else 'resumed'}"
        try:
            number = float(value)
        except ValueError:
            raise ArgumentError(f"fault command {command!r}: {value!r} is not a number") from None
        if not np.isfinite(number) or number < 0:
            raise ArgumentError(f"fault command {command!r}: value must be finite and >= 0")
        attr = {"drop": "drop_rate", "corrupt": "corrupt_rate", "delay": "delay",
                "noise": "position_noise"}.get(name)
        if attr is None:
            raise ArgumentError(f"fault command {command!r}: unknown fault {name!r}")
        if attr.endswith("rate") and number > 1:
            raise ArgumentError(f"fault command {command!r}: a rate is at most 1")
        setattr(self, attr, number)
        return f"{attr} = {number:g}"
