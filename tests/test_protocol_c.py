"""The protocol codec in C: its standalone test under AddressSanitizer and
UBSan (round trips, refusals, deframer resync, CAN joins, a short fuzz),
and the golden vectors, which must be what tools/make_vectors.c writes now."""
import shutil
import subprocess
from pathlib import Path

import pytest

from conftest import PROTO_CFLAGS

ROOT = Path(__file__).resolve().parents[1]
PROTO = ROOT / "firmware_protocol"
SOURCES = sorted(str(p) for p in PROTO.glob("*.c"))

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")


def build(tmp_path, sanitized_build, main, name):
    """main and the codec under ASan and UBSan (the codec's objects made
    once per session)."""
    exe = tmp_path / name
    result = sanitized_build.link(exe, [([*SOURCES, str(main)], PROTO_CFLAGS)], ["-lm"])
    assert result.returncode == 0, result.stderr
    return exe


def test_codec_needs_nothing_from_ext_or_python():
    for path in PROTO.glob("*.[ch]"):
        text = path.read_text()
        assert "Python.h" not in text and "malloc" not in text and "mar_engine" not in text, path


def test_codec_under_asan_ubsan(tmp_path, sanitized_build):
    exe = build(tmp_path, sanitized_build, PROTO / "tests" / "test_proto.c", "test_proto")
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=300,
                         env={"ASAN_OPTIONS": "detect_leaks=1", "UBSAN_OPTIONS": "print_stacktrace=1"})
    assert run.returncode == 0, run.stdout + run.stderr
    assert "protocol tests passed" in run.stdout


def test_committed_vectors_are_what_the_program_writes(tmp_path, sanitized_build):
    exe = build(tmp_path, sanitized_build, PROTO / "tools" / "make_vectors.c", "make_vectors")
    out = tmp_path / "vectors"
    out.mkdir()
    run = subprocess.run([str(exe), str(out)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    for name in ("serial.json", "can.json", "refused.json"):
        assert (out / name).read_text() == (PROTO / "vectors" / name).read_text(), name
