"""Published results: marked sections of markdown pages and the JSON records beside them.

A benchmark or a report command keeps a published section as a JSON record (its prose and its tables as
rows of cells, :func:`render_blocks`) and draws it between ``<!-- name:start -->`` and
``<!-- name:end -->`` of a page, so that what draws a figure or a page from them reads the record, never
the page.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from rheograph.errors import InputError
from rheograph.io.json_files import read_json


def replace_section(path: Path, name: str, body: str, insert_before: str | None = None) -> None:
    """Put ``body`` between ``<!-- name:start -->`` and ``<!-- name:end -->`` of the page ``path``; where
    the markers are absent, insert the block just before the line starting with ``insert_before`` (a
    heading) or append it.  The page is replaced whole (through a temporary file)."""
    path = Path(path)
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    text = path.read_text() if path.exists() else ""
    block = f"{start}\n{body}\n{end}"
    if start in text and end in text:
        text = text[: text.index(start)] + block + text[text.index(end) + len(end) :]
    elif insert_before and f"\n{insert_before}" in text:
        at = text.index(f"\n{insert_before}") + 1
        text = text[:at] + block + "\n\n" + text[at:]
    else:
        text = text.rstrip() + ("\n\n" if text else "") + block + "\n"
    _write_atomically(path, text)


def table_block(header, rows, align=None, indent: str = "") -> dict:
    """A table of a section record: ``header`` (column names), ``rows`` (cells, formatted as they are to
    be published), ``align`` (each column's separator cell, ``---`` by default) and ``indent`` (spaces
    before every line: a table inside a list item; kept in the record only where set)."""
    header = [str(h) for h in header]
    table = {
        "header": header,
        "align": list(align) if align is not None else ["---"] * len(header),
        "rows": [[str(c) for c in row] for row in rows],
    }
    if indent:
        table["indent"] = indent
    return {"table": table}


def render_blocks(blocks: list[dict]) -> str:
    """The markdown of a section's blocks (``{"text": ...}`` verbatim, tables as pipe tables), joined by
    newlines."""
    return "\n".join(_render_block(b) for b in blocks)


def _render_block(block: dict) -> str:
    if "text" in block:
        return block["text"]
    t = block["table"]
    lines = [_row(t["header"]), "|" + "|".join(t["align"]) + "|"] + [_row(row) for row in t["rows"]]
    return "\n".join(t.get("indent", "") + line for line in lines)


def _row(cells) -> str:
    return "|" + "|".join(f" {c} " if c else " " for c in cells) + "|"


def write_record(path: Path, record: dict) -> None:
    """Write a published result's numbers (``record``: JSON-serialisable, with the command that made
    them) to ``path``, whole or not at all."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_atomically(path, json.dumps(record, indent=1, allow_nan=True, ensure_ascii=False) + "\n")


def read_record(path: Path, what: str) -> dict:
    """A result record written by :func:`write_record`; one line naming ``path`` and ``what`` makes it
    where it is missing or not JSON."""
    record = read_json(Path(path), what, ": rerun the command that publishes it")
    if not isinstance(record, dict):
        raise InputError(f"{path}: not a {what} (a JSON object); rerun the command that publishes it")
    return record


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
