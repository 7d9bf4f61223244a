"""Figures as files: PNGs with a 256-colour palette.

Line plots and scatter plots use a handful of colours plus their anti-aliased edges; a palette of 256
colours renders them indistinguishably from 24-bit RGBA at about a third of the bytes, which keeps the
reports that are committed beside each training run, and the site built from them, light.
"""

from __future__ import annotations

import io
from pathlib import Path

from PIL import Image


def save_png(fig, path: str | Path, dpi: int) -> Path:
    """Write matplotlib figure ``fig`` to ``path`` at ``dpi`` (dots per inch) as a palette PNG.

    The figure is drawn once as RGB (on its own white face colour) and reduced to 256 colours
    without dithering (dithering would speckle the flat backgrounds)."""
    path = Path(path)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    buffer.seek(0)
    with Image.open(buffer) as image:
        palette = image.convert("RGB").quantize(
            colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE
        )
        palette.save(path, format="PNG", optimize=True)
    return path
