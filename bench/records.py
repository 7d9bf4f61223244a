"""The JSON records behind the validation pages, and how a record draws its marked section.

A record (``docs/results/bench/<section>.json``) holds one published section: ``section`` (the marker
name), ``page`` (under docs/), ``command`` (what produced its numbers, or null where the section quotes
several) and ``blocks``, the section in order: ``{"text": ...}`` for prose and ``{"table": {"header":
[...], "align": [...], "rows": [[...], ...]}}`` for a table, whose cells are the published numbers as
printed (with ``"indent"``, the spaces of a table inside a list item).  A benchmark may add its raw
numbers under other keys (read by figures and other benchmarks).
"""

from __future__ import annotations

from pathlib import Path

from rheograph.errors import InputError
from rheograph.io.pages import read_record, render_blocks, table_block

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
RECORDS = DOCS / "results" / "bench"
REQUIRED = ("section", "page", "command", "blocks")


def table(header, rows, align=None) -> dict:
    """A table block: ``header`` (column names), ``rows`` (cells, formatted as they are to be published)
    and ``align`` (each column's separator cell, ``---`` by default)."""
    return table_block(header, rows, align)


def text(*lines: str) -> dict:
    """A block of prose (``lines`` joined by newlines)."""
    return {"text": "\n".join(lines)}


class Section:
    """A section built in order: lines of prose (``add``) and tables (``table``), as blocks that render
    exactly as the lines would have been joined."""

    def __init__(self, *lines: str) -> None:
        self._blocks: list[dict] = []
        self._lines: list[str] = list(lines)

    def add(self, *lines: str) -> None:
        self._lines.extend(lines)

    def table(self, header, rows, align=None) -> None:
        self._flush()
        self._blocks.append(table(header, rows, align))

    def blocks(self) -> list[dict]:
        self._flush()
        return list(self._blocks)

    def _flush(self) -> None:
        if self._lines:
            self._blocks.append(text(*self._lines))
            self._lines = []


def as_blocks(content) -> list[dict]:
    """``content`` (a string, one block, or a list of strings and blocks) as a list of blocks."""
    if isinstance(content, Section):
        return content.blocks()
    if isinstance(content, (str, dict)):
        content = [content]
    return [text(b) if isinstance(b, str) else b for b in content]


def check_record(record: dict, where: str = "record") -> None:
    """Raise InputError naming ``where`` unless ``record`` has the schema above."""
    missing = [k for k in REQUIRED if k not in record]
    if missing:
        raise InputError(f"{where}: missing {', '.join(missing)}")
    if not isinstance(record["blocks"], list) or not record["blocks"]:
        raise InputError(f"{where}: blocks must be a non-empty list")
    for k, block in enumerate(record["blocks"]):
        if "text" in block:
            if not isinstance(block["text"], str):
                raise InputError(f"{where}: block {k}: text must be a string")
        elif "table" in block:
            t = block["table"]
            width = len(t.get("header", []))
            if not width or len(t.get("align", [])) != width:
                raise InputError(f"{where}: block {k}: a table needs a header and one align cell per column")
            if t.get("indent", "").strip():
                raise InputError(f"{where}: block {k}: a table's indent must be spaces")
            bad = [i for i, row in enumerate(t.get("rows", [])) if len(row) != width]
            if bad:
                raise InputError(f"{where}: block {k}: rows {bad} do not have {width} cells")
        else:
            raise InputError(f"{where}: block {k} is neither text nor a table")


def render_section(record: dict) -> str:
    """The markdown of a record's section (between its markers)."""
    return render_blocks(record["blocks"])


def load_records(records: Path = RECORDS) -> list[dict]:
    """Every section record under ``records`` (its top level; sub-folders hold per-run inputs)."""
    out = []
    for path in sorted(Path(records).glob("*.json")):
        record = read_record(path, f"section record {path.stem}")
        check_record(record, str(path))
        out.append(record)
    return out
