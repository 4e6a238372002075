"""A CPU kept for one process during a benchmark: every other task moved off it (a cpuset shield).

On a shared machine the tick's wake latency moves by hundreds of
microseconds between 10 s segments whatever the process under test does,
because other tasks run on the tick's CPU. A shield takes them off it for
the length of a run, as the kernel's `isolcpus` does at boot, but at run
time and undone afterwards:

- a cpuset `marionette-rest` (cgroup v1, the `cpuset` hierarchy) holds every
  CPU but the shielded one;
- every task of the root cpuset that may move goes there, except this
  process's own threads (per-CPU kernel threads cannot move, and stay);
- on leaving, every task in it goes back to the root cpuset, which is then
  as before, and the cpuset is removed.

It needs root and a mounted cgroup-v1 cpuset hierarchy (which a Debian
container with the hybrid layout has). Interrupts and the hypervisor's own
work still reach the CPU: what is left is the machine's floor.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path

from marionette.errors import ArgumentError

CPUSET_ROOT = Path("/sys/fs/cgroup/cpuset")      # cgroup v1 cpuset hierarchy
REST = "marionette-rest"                          # the cpuset of every other task


def _tasks(cpuset: Path) -> list[int]:
    return [int(t) for t in (cpuset / "tasks").read_text().split()]


def _move(tids, cpuset: Path) -> int:
    """Move the tasks into cpuset; the count that moved (one that has ended or may not move stays)."""
    moved = 0
    for tid in tids:
        try:
            (cpuset / "tasks").write_text(str(tid))
            moved += 1
        except OSError:
            pass
    return moved


def _check(cpu: int, root: Path) -> None:
    if not (root / "cpuset.cpus").exists():
        raise ArgumentError(f"--shield: no cgroup-v1 cpuset hierarchy at {root} (mount one, or run without --shield)")
    if not os.access(root / "tasks", os.W_OK):
        raise ArgumentError(f"--shield: {root}/tasks is not writable (it needs root)")
    if os.cpu_count() is None or os.cpu_count() < 2:
        raise ArgumentError("--shield: it needs at least 2 CPUs (one to shield, one for the rest)")
    if not 0 <= cpu < os.cpu_count():
        raise ArgumentError(f"--shield: CPU {cpu} is not one of 0..{os.cpu_count() - 1}")


@contextlib.contextmanager
def shield(cpu: int, root: Path = CPUSET_ROOT):
    """Every other task off CPU cpu while inside; yields {"cpu", "moved", "stayed"} (task counts)."""
    _check(cpu, root)
    rest = root / REST
    others = ",".join(str(c) for c in range(os.cpu_count()) if c != cpu)
    rest.mkdir(exist_ok=True)
    try:
        (rest / "cpuset.mems").write_text((root / "cpuset.mems").read_text())
        (rest / "cpuset.cpus").write_text(others)
        own = {int(t) for t in os.listdir(f"/proc/{os.getpid()}/task")}
        tids = [t for t in _tasks(root) if t not in own]
        moved = _move(tids, rest)
        yield {"cpu": cpu, "moved": moved, "stayed": len(tids) - moved}
    finally:
        # twice: a task that forked while the first pass ran is in rest too
        for _ in range(2):
            _move(_tasks(rest), root)
        with contextlib.suppress(OSError):
            rest.rmdir()


def pin_off(cpu: int) -> None:
    """This process's threads from now on run off CPU cpu (the tick thread is pinned onto it by start())."""
    allowed = {c for c in os.sched_getaffinity(0) if c != cpu} or {cpu}
    for tid in os.listdir(f"/proc/{os.getpid()}/task"):   # threads made later inherit it
        os.sched_setaffinity(int(tid), allowed)
