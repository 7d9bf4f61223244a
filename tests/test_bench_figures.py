"""The published figures against the JSON records of their numbers: every PNG a docs page links has an
entry in ``bench.figures.FIGURES``, a record, redraws from it and carries the hash of its numbers
(``python -m bench.render --check``); a changed number in a figure record is caught, naming the figure."""

import json
import shutil
from pathlib import Path

import matplotlib.pyplot as plt
import pytest

from bench import figures
from bench.records import DOCS, RECORDS
from rheograph.io.figures import data_hash, drawn_from_hash

SMALL = "figures/surrogate_r2_vs_phi.png"  # the quickest to draw, from a section record


def test_every_published_figure_has_a_record_redraws_and_shows_its_numbers():
    """What ``--check`` checks of every figure, less its drawing at full size into PNGs (about 20 s in
    all): here each figure is built from its record alone, its layout included."""
    assert figures.published_figures() == set(figures.FIGURES)
    for name, spec in figures.FIGURES.items():
        data = figures.figure_data(name)
        assert drawn_from_hash(DOCS / name) == data_hash(data), name
        plt.close(spec.draw(data))


@pytest.fixture
def records(tmp_path):
    folder = tmp_path / "records"
    shutil.copytree(RECORDS, folder)
    return folder


def test_a_changed_number_in_a_figure_record_fails_the_check_naming_the_figure(records, tmp_path):
    assert figures.figure_problems(SMALL, DOCS, records, tmp_path) == []
    path = records / figures.FIGURES[SMALL].record
    record = json.loads(path.read_text())
    record["figure"]["series"][0]["mean"]["r2_log_eta"][0] += 0.01
    path.write_text(json.dumps(record))
    problems = figures.figure_problems(SMALL, DOCS, records, tmp_path)
    assert problems == [
        f"{SMALL}: figure differs from its record surrogate_per_phi.json (python -m bench.render)"
    ]
    # redrawn from the changed record, the figure carries its numbers and the check passes again
    docs = tmp_path / "docs"
    drawn = figures.draw(SMALL, docs, records)
    assert drawn_from_hash(drawn) == data_hash(record["figure"])
    assert figures.figure_problems(SMALL, docs, records, tmp_path / "scratch") == []


def test_a_missing_record_or_key_and_an_unlisted_figure_are_named(records, tmp_path):
    (records / "figures" / "flow_curves.json").unlink()
    assert figures.figure_problems("figures/flow_curves.png", DOCS, records, tmp_path) == [
        "figures/flow_curves.png: its record figures/flow_curves.json is missing"
    ]
    path = records / figures.FIGURES[SMALL].record
    record = json.loads(path.read_text())
    del record["figure"]
    path.write_text(json.dumps(record))
    assert figures.figure_problems(SMALL, DOCS, records, tmp_path) == [
        f"{SMALL}: its record surrogate_per_phi.json holds no 'figure'"
    ]
    docs = tmp_path / "docs"
    (docs / "results" / "run").mkdir(parents=True)
    (docs / "page.md").write_text("![a](figures/new.png) and [b](figures/flow_curves.png)\n")
    (docs / "results" / "run" / "report.md").write_text("![parity](parity.png)\n")  # a training report's
    assert figures.published_figures(docs) == {"figures/new.png", "figures/flow_curves.png"}


def test_the_dataset_card_command_writes_the_record_its_published_figures_draw_from(tmp_path):
    from rheograph.analysis import dataset_card

    # the runs the committed index lists (a campaign may be writing new ones beside them); the card writes
    # an index of its own beside the runs
    data = tmp_path / "data"
    committed = DOCS.parent / "data" / "flow_curves_3d"
    for run in json.loads((committed / "index.json").read_text())["runs"]:
        run_dir = Path(run["path"]).parent
        shutil.copytree(committed / run_dir, data / run_dir)
    record = tmp_path / "record.json"
    dataset_card.main([str(data), "--out", str(tmp_path / "card"), "--record", str(record)])
    written = json.loads(record.read_text())
    assert written["command"].startswith("python -m rheograph.analysis.dataset_card ")
    for key in ("fig2", "fig3"):
        png = tmp_path / "card" / "figures" / f"dataset_{key}.png"
        assert drawn_from_hash(png) == data_hash(written[key])
    # the committed set's record holds the same numbers
    name = "datasets/flow_curves_3d/figures/dataset_fig2.png"
    assert figures.figure_data(name) == written["fig2"]
