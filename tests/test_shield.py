"""The benchmarks' CPU shield (marionette/bench/shield.py): every other task off one CPU, then back;
and `bench console-cost` run with it in a real terminal (tmux)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import run_cli
from marionette.bench.shield import CPUSET_ROOT, REST, shield
from marionette.errors import ArgumentError

from test_console import tmux  # noqa: F401  (the fixture)

needs_cpuset = pytest.mark.skipif(
    os.geteuid() != 0 or not (CPUSET_ROOT / "tasks").exists() or (os.cpu_count() or 1) < 2,
    reason="the shield needs root, a cgroup-v1 cpuset hierarchy and 2 CPUs")


def allowed(pid: int) -> str:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("Cpus_allowed_list:"):
            return line.split(":", 1)[1].strip()
    raise AssertionError(f"no Cpus_allowed_list for {pid}")


@needs_cpuset
@pytest.mark.parametrize("cpu", [0, 1])
def test_other_tasks_leave_the_shielded_cpu_and_come_back(cpu):
    sleepers = [subprocess.Popen(["sleep", "60"])]
    try:
        before = allowed(sleepers[0].pid)
        with shield(cpu) as shielded:
            rest = {c for c in range(os.cpu_count()) if c != cpu}
            assert {int(c) for c in allowed(sleepers[0].pid).replace("-", ",").split(",")} <= rest
            assert cpu in os.sched_getaffinity(0)              # this process keeps it
            assert shielded["moved"] >= 1 and shielded["cpu"] == cpu
        for p in sleepers:
            assert allowed(p.pid) == before
        assert not (CPUSET_ROOT / REST).exists()
    finally:
        for p in sleepers:
            p.kill()
            p.wait()


def test_a_missing_cpuset_hierarchy_is_a_clear_error(tmp_path):
    with pytest.raises(ArgumentError, match=str(tmp_path)):
        with shield(0, root=tmp_path):
            pass


@needs_cpuset
def test_console_cost_in_a_terminal_on_a_shielded_cpu(tmux, tmp_path):  # noqa: F811
    out = tmp_path / "cost.json"
    t = tmux([sys.executable, "-m", "marionette.cli", "bench", "console-cost", "--segment", "1",
              "--pairs", "1", "--cpu", "1", "--shield", "--json", out])
    assert t.exit_status(timeout=30) == 0, t.screen()
    screen = t.screen()
    assert "p99 change" in screen and "shielded" in screen
    result = json.loads(out.read_text())
    for kind in ("without", "with"):                  # 1 s each at 20 ms: 50 ticks, give or take the edges
        assert 45 <= result[kind]["ticks"] <= 55
        assert 0 < result[kind]["p50_us"] <= result[kind]["p99_us"] <= result[kind]["max_us"]
    assert result["shield"]["moved"] >= 1 and result["cpu"] == 1 and not result["share"]
    assert not (CPUSET_ROOT / REST).exists()


@pytest.mark.parametrize("bench", ["console-cost", "jitter"])
def test_shield_without_cpu_is_refused(bench):
    r = run_cli("bench", bench, "--shield")
    assert r.returncode == 2, r.stderr
    assert "need" in r.stderr and "--cpu N" in r.stderr and "Traceback" not in r.stderr
