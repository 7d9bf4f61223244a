"""Published results: marked sections of markdown pages and the JSON records beside them.

A benchmark or a report command publishes a table by replacing the text between
``<!-- name:start -->`` and ``<!-- name:end -->`` of a page, and its numbers as a JSON record, so
that what draws a figure from them reads the record, never the page.
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


def write_record(path: Path, record: dict) -> None:
    """Write a published result's numbers (``record``: JSON-serialisable, with the command that made
    them) to ``path``, whole or not at all."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_atomically(path, json.dumps(record, indent=1, allow_nan=True) + "\n")


def read_record(path: Path, what: str) -> dict:
    """A result record written by :func:`write_record`; one line naming ``path`` and ``what`` makes it
    where it is missing or not JSON."""
    record = read_json(Path(path), what, ": rerun the command that publishes it")
    if not isinstance(record, dict):
        raise InputError(f"{path}: not a {what} (a JSON object); rerun the command that publishes it")
    return record


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
