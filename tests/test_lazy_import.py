"""import marionette is lazy (PEP 562): the simulator process and
firmware_protocol/tools/bus_budget.py import marionette.protocol only, and do
not load the C engine."""
import subprocess
import sys
import tempfile

import marionette


def _modules_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys\n"
                          "print(' '.join(m for m in sys.modules if m.startswith('marionette')))"],
                         capture_output=True, text=True, timeout=60, check=True,
                         cwd=tempfile.gettempdir()).stdout     # the installed package, not the source tree
    return set(out.split())


def test_protocol_alone_does_not_load_the_engine():
    loaded = _modules_after("import marionette.protocol")
    assert "marionette.protocol" in loaded
    assert "marionette._core" not in loaded and "marionette.engine" not in loaded


def test_the_public_names_load_when_used():
    loaded = _modules_after("import marionette")
    assert "marionette._core" not in loaded
    loaded = _modules_after("import marionette\nassert marionette.Engine.__name__ == 'Engine'")
    assert "marionette._core" in loaded
    for name in marionette.__all__:
        assert getattr(marionette, name) is not None
    assert marionette.transport.open_link.__name__ == "open_link"     # a subpackage, by attribute


def test_the_simulator_process_does_not_load_the_engine(tmp_path):
    """`marionette sim` builds the parser of its own command only: the running
    simulator process has neither the engine's extension mapped nor the
    other commands imported."""
    import json
    proc = subprocess.Popen([sys.executable, "-m", "marionette.cli", "sim", "--serial"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tmp_path)
    try:
        assert json.loads(proc.stdout.readline()).get("ready")
        with open(f"/proc/{proc.pid}/maps") as f:
            maps = f.read()
        # the follower's option tables, not the engine
        assert "marionette/_core" not in maps and "marionette/_follow" in maps
        loaded = _modules_after("from marionette.cli import build_parser\nbuild_parser(['sim'])")
        assert "marionette._core" not in loaded and "marionette.cli.play" not in loaded
        loaded = _modules_after("from marionette.cli import build_parser\nbuild_parser()")
        assert "marionette.cli.play" in loaded                      # --help: every command
    finally:
        proc.kill()
        proc.communicate()
