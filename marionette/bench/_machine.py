"""What the benchmarks ran on: CPU model, cores, kernel, clock source, idle states."""
from __future__ import annotations

import os
import platform
from pathlib import Path


def _read(path: str) -> str | None:
    try:
        return Path(path).read_text().strip()
    except OSError:
        return None


def cpu_model() -> str:
    """The CPU's 'model name' from /proc/cpuinfo (or the platform's guess)."""
    text = _read("/proc/cpuinfo") or ""
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key.strip() in ("model name", "Model", "cpu model"):
            return value.strip()
    return platform.processor() or "unknown"


def _virtualized() -> bool:
    """True under a hypervisor (the 'hypervisor' CPU flag): idle vCPUs wake slowly."""
    for line in (_read("/proc/cpuinfo") or "").splitlines():
        if line.startswith("flags"):
            return "hypervisor" in line.split(":", 1)[1].split()
    return False


def machine_info() -> dict:
    """CPU model, logical cores, kernel, clock source, idle driver, hypervisor, Python, numpy."""
    import numpy

    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = os.cpu_count()
    return {
        "cpu": cpu_model(),
        "cores": os.cpu_count(),                 # logical CPUs online
        "usable_cores": usable,                  # in this process's affinity mask
        "kernel": platform.release(),
        "kernel_version": platform.version(),    # shows PREEMPT / PREEMPT_RT
        "realtime_kernel": _read("/sys/kernel/realtime") == "1",
        "clocksource": _read("/sys/devices/system/clocksource/clocksource0/current_clocksource"),
        "cpuidle_driver": _read("/sys/devices/system/cpu/cpuidle/current_driver"),  # "none": plain halt
        "virtualized": _virtualized(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
    }


def describe(info: dict) -> str:
    """One line for the human-readable output."""
    rt = ", PREEMPT_RT" if info.get("realtime_kernel") else ""
    return (f"machine: {info['cpu']}, {info['cores']} cores ({info['usable_cores']} usable), "
            f"Linux {info['kernel']} {info['kernel_version']}{rt}, "
            f"clocksource {info['clocksource']}, cpuidle {info['cpuidle_driver']}, "
            f"{'virtual machine' if info['virtualized'] else 'bare metal'}, "
            f"Python {info['python']}, numpy {info['numpy']}")
