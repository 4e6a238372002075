"""Reading a text file that may be damaged or binary: its UTF-8 text, or an
error that names the file and the line of the first byte that is not."""
from __future__ import annotations

from pathlib import Path

from marionette.errors import MarionetteError


def read_text(path, error: type[MarionetteError] = MarionetteError) -> str:
    path = Path(path)
    data = path.read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise error(f"{path}, line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x}): "
                    "a damaged or binary file?") from None
