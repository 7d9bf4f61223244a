"""Figures written as palette PNGs look like the figure: a line plot, reduced to 256 colours, differs
from its full-colour rendering by less than one grey level on average and nowhere by much, and the
file is a palette image (what keeps the committed reports light); it carries the hash of the numbers
it was drawn from."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402

from rheograph.io.figures import save_png  # noqa: E402


def test_palette_png_matches_the_full_colour_rendering(tmp_path):
    fig, axes = plt.subplots(1, 3, figsize=(9, 3))
    x = np.logspace(-1, 2, 30)
    for k, ax in enumerate(axes):
        for c in range(4):  # four series in the default colour cycle, lines and hollow markers
            ax.plot(x, (c + 1) * x ** (0.5 + 0.2 * k), "-o", mfc="none", label=f"series {c}")
        ax.set_xscale("log")
        ax.legend(fontsize=7)
    fig.canvas.draw()
    full = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(float) / 255
    path = save_png(fig, tmp_path / "f.png", dpi=fig.dpi)
    plt.close(fig)
    with Image.open(path) as image:
        assert image.mode == "P"
    written = mpimg.imread(path)[..., :3]  # also what the training report hands to TensorBoard
    assert written.shape == full.shape
    difference = np.abs(written - full)
    assert difference.mean() < 1 / 255
    assert np.quantile(difference, 0.999) < 0.1


def test_a_png_carries_the_hash_of_the_numbers_it_was_drawn_from(tmp_path):
    import json

    from rheograph.io.figures import data_hash, drawn_from_hash

    data = {"x": [0.5, 1.0, float("nan")], "label": "φ = 0.76", "n": (400, 2000)}
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot(data["x"])
    path = save_png(fig, tmp_path / "f.png", dpi=50, drawn_from=data)
    plt.close(fig)
    # the numbers read back from a JSON record hash alike; one changed number does not
    again = json.loads(json.dumps(data, allow_nan=True))
    assert drawn_from_hash(path) == data_hash(again)
    again["x"][0] = 0.51
    assert drawn_from_hash(path) != data_hash(again)
    assert drawn_from_hash(save_png(plt.figure(), tmp_path / "g.png", dpi=20)) is None
