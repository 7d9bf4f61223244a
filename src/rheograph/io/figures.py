"""Figures as files: PNGs with a 256-colour palette, stamped with the data they were drawn from.

Line plots and scatter plots use a handful of colours plus their anti-aliased edges; a palette of 256
colours renders them indistinguishably from 24-bit RGBA at about a third of the bytes, which keeps the
reports that are committed beside each training run, and the site built from them, light.

A figure drawn from a JSON-serialisable record of its numbers can carry that record's SHA-256
(:func:`data_hash`) in a text chunk of the PNG (:func:`drawn_from_hash` reads it back): whether a
published PNG shows the numbers of its record is then a comparison of two hashes, the same whatever the
matplotlib version that drew the pixels.
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import numpy as np
from PIL import Image
from PIL.PngImagePlugin import PngInfo

DRAWN_FROM = "drawn-from-sha256"  # the PNG text chunk holding the hash of the plotted numbers


def data_hash(data) -> str:
    """SHA-256 (hex) of ``data`` as canonical JSON (keys sorted, no spaces, NaN allowed): equal for the
    numbers in memory and for the same numbers read back from a JSON record."""
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def significant(values, digits: int = 4) -> list[float]:
    """``values`` (any shape, flattened) rounded to ``digits`` significant digits as plain floats, for a
    figure's record: at 4 digits a point moves by < 1e-4 of itself, far below a pixel."""
    return [float(f"{v:.{digits}g}") for v in np.asarray(values, dtype=np.float64).ravel()]


def save_png(fig, path: str | Path, dpi: int, drawn_from=None) -> Path:
    """Write matplotlib figure ``fig`` to ``path`` at ``dpi`` (dots per inch) as a palette PNG.

    The figure is drawn once as RGB (on its own white face colour) and reduced to 256 colours
    without dithering (dithering would speckle the flat backgrounds).  ``drawn_from``: the numbers the
    figure plots (JSON-serialisable), whose :func:`data_hash` the PNG then carries."""
    path = Path(path)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    buffer.seek(0)
    info = PngInfo()
    if drawn_from is not None:
        info.add_text(DRAWN_FROM, data_hash(drawn_from))
    with Image.open(buffer) as image:
        palette = image.convert("RGB").quantize(
            colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE
        )
        palette.save(path, format="PNG", optimize=True, pnginfo=info)
    return path


def drawn_from_hash(path: str | Path) -> str | None:
    """The hash of the numbers a PNG written by :func:`save_png` was drawn from (None where it carries
    none)."""
    with Image.open(path) as image:
        return image.text.get(DRAWN_FROM)


def png_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of an image file in pixels."""
    with Image.open(path) as image:
        return image.size
