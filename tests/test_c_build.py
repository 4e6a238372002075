"""The C in ext/ and firmware_protocol/ is plain C11: no Python headers,
warning-free under -Wall -Wextra, and its standalone test passes under
AddressSanitizer and UBSan (with allocation counting around the ticks)."""
import os
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from conftest import FOLLOW_CFLAGS, PROTO_CFLAGS

ROOT = Path(__file__).resolve().parents[1]
C_DIRS = [ROOT / "ext", ROOT / "firmware_protocol"]
SOURCES = sorted(str(p) for d in C_DIRS for p in d.glob("*.c"))
BASE = ["-std=c11", "-D_POSIX_C_SOURCE=200809L", "-Wall", "-Wextra", "-Werror",
        "-I", str(ROOT / "ext"), "-I", str(ROOT / "firmware_protocol")]

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")


def test_no_python_headers_in_plain_c():
    for d in C_DIRS:
        for path in list(d.rglob("*.c")) + list(d.rglob("*.h")):
            assert "Python.h" not in path.read_text(), f"{path} includes Python.h"


@pytest.mark.parametrize("opt", ["-O0", "-O2"])
def test_builds_warning_free(tmp_path, opt):
    def compile_one(i):             # several at once (one per CPU), each to its own object
        return subprocess.run(["gcc", *BASE, "-Wpedantic", opt, "-c", SOURCES[i], "-o",
                               str(tmp_path / f"{i}.o")], capture_output=True, text=True)
    with ThreadPoolExecutor(max(1, len(os.sched_getaffinity(0)))) as pool:
        results = list(pool.map(compile_one, range(len(SOURCES))))
    for src, result in zip(SOURCES, results):
        assert result.returncode == 0 and not result.stderr, f"{src}:\n{result.stderr}"


def test_engine_under_asan_ubsan_without_tick_allocations(tmp_path, sanitized_build):
    exe = tmp_path / "test_engine"
    wrap = "-Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc,--wrap=free"
    # the follower's and the codec's files with their own builds' flags
    # (tests/test_follow.py, tests/test_protocol_c.py: the same objects)
    follow = [s for s in SOURCES if Path(s).name.startswith("mar_follow")]
    proto = [s for s in SOURCES if Path(s).parent.name == "firmware_protocol"]
    rest = [s for s in SOURCES if s not in follow + proto] + [str(ROOT / "ext" / "tests" / "test_engine.c")]
    build = sanitized_build.link(exe, [(follow, FOLLOW_CFLAGS), (proto, PROTO_CFLAGS), (rest, BASE)],
                                 ["-lm", "-lpthread", wrap])
    assert build.returncode == 0, build.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120,
                         env={"ASAN_OPTIONS": "detect_leaks=1", "UBSAN_OPTIONS": "print_stacktrace=1"})
    assert run.returncode == 0, run.stdout + run.stderr
    assert "C engine tests passed" in run.stdout
