"""Reading an .npz file that may be damaged or not an .npz at all.

numpy raises many kinds of error for a damaged file (BadZipFile, EOFError,
zlib.error, ...) and, for one that is not a zip file, advises allow_pickle,
which would run code from an untrusted file. Here pickles stay refused and
every such failure is one error that names the file.
"""
from __future__ import annotations

import struct
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from marionette.errors import MarionetteError

# what numpy and zipfile raise on damaged files (found by tests/test_show.py's random damage);
# MemoryError: an array header that declares a huge shape
_DAMAGED = (OSError, EOFError, ValueError, KeyError, NotImplementedError, SyntaxError,
            MemoryError, struct.error, tokenize.TokenError, zipfile.BadZipFile, zlib.error)


def read_npz(path, error: type[MarionetteError] = MarionetteError) -> dict[str, np.ndarray]:
    """Every array of the .npz file at path, read now; error(message naming
    the file) when it is missing, empty, damaged or not an .npz."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise error(f"{path}: empty file, not an .npz")
    try:
        with open(path, "rb") as f:          # ours to close, whatever numpy does on a failure
            z = np.load(f, allow_pickle=False)
            if not isinstance(z, np.lib.npyio.NpzFile):
                raise error(f"{path}: a single .npy array, not an .npz of named arrays")
            return {name: np.asarray(z[name]) for name in z.files}
    except _DAMAGED as exc:
        if isinstance(exc, MarionetteError):
            raise
        if isinstance(exc, ValueError) and "pickle" in str(exc):
            reason = "not an .npz file (nor an .npy array)"
        else:
            reason = f"damaged ({type(exc).__name__}: {exc})"
        raise error(f"{path}: {reason}; cannot read it as an .npz") from None
