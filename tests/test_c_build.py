"""The C in ext/ and firmware_protocol/ is plain C11: no Python headers,
warning-free under -Wall -Wextra, and its standalone test passes under
AddressSanitizer and UBSan (with allocation counting around the ticks)."""
import shutil
import subprocess
from pathlib import Path

import pytest

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
    for src in SOURCES:
        result = subprocess.run(["gcc", *BASE, "-Wpedantic", opt, "-c", src, "-o",
                                 str(tmp_path / "x.o")], capture_output=True, text=True)
        assert result.returncode == 0 and not result.stderr, f"{src}:\n{result.stderr}"


def test_engine_under_asan_ubsan_without_tick_allocations(tmp_path):
    exe = tmp_path / "test_engine"
    wrap = "-Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc,--wrap=free"
    build = subprocess.run(
        ["gcc", *BASE, "-g", "-O1", "-fsanitize=address,undefined", "-fno-omit-frame-pointer",
         "-fno-sanitize-recover=all", *SOURCES, str(ROOT / "ext" / "tests" / "test_engine.c"),
         "-o", str(exe), "-lm", "-lpthread", wrap], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120,
                         env={"ASAN_OPTIONS": "detect_leaks=1", "UBSAN_OPTIONS": "print_stacktrace=1"})
    assert run.returncode == 0, run.stdout + run.stderr
    assert "C engine tests passed" in run.stdout
