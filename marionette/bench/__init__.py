"""Benchmarks of the C tick engine, and the pure-numpy reference tick they compare against.

- ``marionette.bench.tick``: compute time per tick in step mode [us] for 16, 256
  and 4096 axes, against the numpy reference tick on the same figure and show.
- ``marionette.bench.jitter``: wake latency of the real-time loop at the 20 ms
  period [us], beside ``cyclictest`` (rt-tests) at the same period and
  priority, and again under Python threads churning the GIL.
- ``marionette.bench.reference``: the numpy reference tick (benchmarks and
  tests only; the engine itself never runs it).

Each benchmark module has ``collect(...)`` (returns plain data), and for
``marionette bench NAME`` (marionette/cli/bench.py) ``register(subparsers)``
and ``run(args)`` (prints a table, or JSON with ``--json``); ``main(argv)``
runs it as ``python -m marionette.bench.NAME``.
"""

# Every bench with targets reports each as PASS, FAIL, or SKIPPED (None: it
# could not be measured here, e.g. without Ruckig or cyclictest), and exits
# 0 after its report; with --strict, 1 when a measured target failed.
STRICT_HELP = "exit with status 1 when a target that was measured fails (a skipped one does not)"


def verdict(ok: bool | None) -> str:
    return "SKIPPED" if ok is None else "PASS" if ok else "FAIL"


def exit_status(oks, strict: bool) -> int:
    """The bench's exit status from its targets' verdicts (True, False, None)."""
    return 1 if strict and any(ok is False for ok in oks) else 0
