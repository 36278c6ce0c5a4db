"""The files of ``featurewarp edit`` (:mod:`featurewarp_cli.app.editor_session`): what Save and
Export write and how (one handle per line, put back when an Export fails or is abandoned, errors
naming the file rather than its temporary), and the texture and painted mask the page exchanges.
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import json
import os
from pathlib import Path

import numpy as np

from ..io import write
from .pipeline import WarpError

#: Longest side of the image the browser gets as its texture (and paints the mask on).
TEXTURE_SIDE = 4096


class Unconfirmed(ValueError):
    """A write that would drop what the user wrote (answered 409: the page asks first).

    Parameters
    ----------
    message : str
        What would be lost, naming the file.
    notes : list of str
        The load-time notes naming what the editor ignored.
    """

    def __init__(self, message: str, notes: list):
        super().__init__(message)
        self.notes = list(notes)


class Snapshot:
    """Files as they are now, put back by :meth:`restore` (or removed, where there was none):
    an Export that fails or is abandoned leaves every existing file as it was, the output and
    the handles and mask it writes included.

    Parameters
    ----------
    paths : list of str
        The files to keep (a link's target is what gets written).
    """

    def __init__(self, paths: list):
        self.before = {}
        for path in dict.fromkeys(os.path.realpath(path) for path in paths):
            self.before[path] = (Path(path).read_bytes() if os.path.isfile(path)
                                 else "absent" if not os.path.lexists(path) else None)

    def restore(self) -> None:
        """Put every file back (a FIFO, a device or a dangling link stays as it is)."""
        for path, data in self.before.items():
            if data == "absent":
                write.remove_quietly(path)
            elif data is not None:
                write.write_atomic(path, data)


def handles_json(data: dict) -> str:
    """The handles file's text: one handle (and one border side) per line, as
    ``samples/astronaut_handles.json`` is written, so that a change reads as a line in a diff."""
    lines = []
    for key, value in _whole(data).items():
        if isinstance(value, list) and value:
            inner = ",\n".join("    " + json.dumps(item) for item in value)
            text = "[\n" + inner + "\n  ]"
        elif isinstance(value, dict) and value:
            inner = ",\n".join(f"    {json.dumps(k)}: {json.dumps(v)}" for k, v in value.items())
            text = "{\n" + inner + "\n  }"
        else:
            text = json.dumps(value)
        lines.append(f"  {json.dumps(key)}: {text}")
    return "{\n" + ",\n".join(lines) + "\n}\n"


def _whole(value):
    """``value`` with every whole float written as an int (``60`` as the samples, not ``60.0``)."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 2**53:
        return int(value)
    if isinstance(value, dict):
        return {k: _whole(v) for k, v in value.items()}
    return [_whole(v) for v in value] if isinstance(value, list) else value


def write_named(path: str, data: bytes) -> None:
    """:func:`write.write_atomic`, an OSError naming ``path`` (not its temporary file)."""
    with naming(path):
        write.write_atomic(path, data)


@contextlib.contextmanager
def naming(path: str):
    """An OSError of the block about a temporary file beside ``path`` names ``path`` instead,
    and says when its folder is gone."""
    try:
        yield
    except OSError as err:
        name = os.path.basename(str(err.filename or ""))
        if not (name.startswith(".featurewarp-") or name.startswith(".") and name.endswith(".tmp")):
            raise
        folder = os.path.dirname(path) or "."
        reason = (f"the folder {folder}/ no longer exists" if not os.path.isdir(folder)
                  else err.strerror or str(err))
        raise OSError(err.errno, f"cannot write {path}: {reason}") from None


def decode_mask(data, size: tuple[int, int]) -> np.ndarray:
    """The 8-bit mask of a ``data:image/png;base64,...`` URL whose PNG is ``size`` (w, h)."""
    import cv2

    prefix = "data:image/png;base64,"
    if not isinstance(data, str) or not data.startswith(prefix):
        raise ValueError("png: expected a data URL of a PNG (data:image/png;base64,...)")
    try:
        raw = base64.b64decode(data[len(prefix):], validate=True)
    except (binascii.Error, ValueError):
        raise ValueError("png: not valid base64") from None
    from ..io.decode import png_size

    found = png_size(raw)                                      # before decoding: no bomb gets decoded
    if found is None:
        raise ValueError("png: not a PNG")
    width, height = found
    if (width, height) != tuple(size):
        raise ValueError(f"png: the mask is {width}x{height}; the page's texture is {size[0]}x{size[1]}")
    from ..io.capture import captured_stderr

    with captured_stderr():                   # libpng's complaints: the 400 says it, not the terminal
        image = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_GRAYSCALE)
    if image is None or image.shape != (height, width):
        raise ValueError("png: cannot decode the mask")
    return image


def texture(image: np.ndarray) -> np.ndarray:
    """``image`` scaled down to :data:`TEXTURE_SIDE` at most (8 bits), each side 1 px at least
    (a 10000 x 1 strip scaled by 4096 / 10000 would have no row: OpenCV asserts)."""
    import cv2

    if image.dtype != np.uint8:
        image = (image / (257.0 if image.dtype == np.uint16 else 1.0 / 255.0)).clip(0, 255).astype(np.uint8)
    height, width = image.shape[:2]
    if max(height, width) > TEXTURE_SIDE:
        scale = TEXTURE_SIDE / max(height, width)
        size = (max(1, int(round(width * scale))), max(1, int(round(height * scale))))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    return image


def png(image: np.ndarray) -> bytes:
    import cv2

    ok, data = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise WarpError("cannot encode the editor's texture")
    return data.tobytes()
