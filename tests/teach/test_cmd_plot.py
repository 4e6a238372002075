"""`marionette plot`: the filter stages of one axis as a PNG (needs matplotlib: the
`plot` and `test` extras)."""
import struct

import numpy as np
import pytest

import taught_show
from marionette.show import Show

from conftest import run_cli


@pytest.fixture(scope="session")
def taught(tmp_path_factory):
    return taught_show.make(tmp_path_factory)


def _png_size(path):
    """(width, height) [pixel] from the IHDR chunk; fails on anything but a PNG."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR", head
    return struct.unpack(">II", head[16:24])


def test_plot_writes_a_png_of_all_stages(taught, tmp_path):
    out = tmp_path / "stages.png"
    result = run_cli("plot", taught.show, "--axis", "winch_hand_l", "-o", out)
    assert result.returncode == 0, result.stderr
    assert "7 stages of axis 'winch_hand_l' [m]" in result.stdout
    width, height = _png_size(out)
    assert (width, height) == (900, 1115)            # 9 x 11.15 in at 100 dpi
    assert 40_000 < out.stat().st_size < 1_000_000   # seven panels of lines, not blank


def test_plot_errors(taught, tmp_path):
    out = tmp_path / "x.png"
    result = run_cli("plot", taught.show, "--axis", "nose", "-o", out)
    assert result.returncode == 2
    assert f"{taught.show}: no axis 'nose'" in result.stderr and "winch_head" in result.stderr
    plain = tmp_path / "plain.npz"                   # a show not made by teach
    Show(axis_names=["x"], units=["m"], positions=np.zeros((1, 10)), loudness=np.zeros(10)).save(plain)
    result = run_cli("plot", plain, "--axis", "x", "-o", out)
    assert result.returncode == 2 and f"{plain}: no filter stages" in result.stderr
    assert not out.exists()
