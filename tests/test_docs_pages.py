"""The pages a newcomer reads first stay short: the README's tables keep cells of at most 120 characters,
and the results page, one table per question, stays within 1,000 words (markers not counted)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def table_cells(text: str) -> list[str]:
    return [
        cell.strip()
        for line in text.splitlines()
        if line.startswith("|")
        for cell in line.strip("|").split("|")
    ]


def test_readme_table_cells_are_short():
    cells = table_cells((ROOT / "README.md").read_text())
    assert cells and max(len(cell) for cell in cells) <= 120


def test_the_results_page_reads_in_minutes():
    text = re.sub(r"<!--.*?-->", "", (ROOT / "docs" / "results.md").read_text(), flags=re.S)
    assert len(text.split()) <= 1000
