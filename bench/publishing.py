"""How a benchmark publishes: a JSON record of its section under docs/results/bench/ (its tables as
rows of cells, its prose, its raw numbers and the command that reproduces them), from which
``bench.render`` draws the marked section of the docs page (and the figures whose numbers it holds);
never the other way round."""

from __future__ import annotations

import os
import shlex
import sys
from pathlib import Path

from bench.figures import draw, figures_of
from bench.records import DOCS, RECORDS, Section, as_blocks, check_record, render_section, table, text
from rheograph.io.pages import read_record, replace_section, write_record

__all__ = [
    "Section", "command_line", "publish", "read_result_record", "record_path", "records_folder", "table",
    "text",
]  # fmt: skip

ROOT = Path(__file__).resolve().parents[1]
# where records go instead (and no page is touched): bench.quick's temporary folder
OUT_ENV = "RHEOGRAPH_BENCH_OUT"


def command_line(script: str, argv=None) -> str:
    """``python -m bench.<script> ARGS`` as the user typed it (``argv``, or the process's), less
    ``--no-write``: the command that reproduces a published section (``script`` with or without
    its ``.py``)."""
    args = argv if argv is not None else sys.argv[1:]
    module = script.removesuffix(".py")
    return f"python -m bench.{module} {shlex.join([a for a in args if a != '--no-write'])}".rstrip()


def publish(
    section: str,
    content,
    write: bool,
    page: str | None = None,
    record: dict | None = None,
    command: str | None = None,
) -> dict:
    """Print a result section and (unless the benchmark's --no-write) keep it as the record
    docs/results/bench/<section>.json and draw it into its page.

    ``content``: the section's blocks (a :class:`Section`, or a list of :func:`table`, :func:`text` and
    strings of prose); ``record``:
    raw numbers kept beside them; ``page`` (under docs/): by default the page the section's record already
    names.  Figures drawn from the record (:data:`bench.figures.FIGURES`) are redrawn from it.  Where
    ``$RHEOGRAPH_BENCH_OUT`` is set the record goes to that folder and no page or figure is touched.
    Returns the record."""
    out = os.environ.get(OUT_ENV)
    path = record_path(section, records_folder())
    if page is None:
        known = record_path(section)
        page = read_record(known, f"record of {section}")["page"] if known.exists() else None
        if page is None and write:
            raise SystemExit(f"{section}: no record names its page yet; pass page=")
    full = dict(record or {})
    blocks = as_blocks(content)
    if command is None:
        command = full.get("command")
    full.update({"section": section, "page": page, "command": command, "blocks": blocks})
    check_record(full, section)
    print(render_section(full))
    if write:
        write_record(path, full)
        if not out:
            replace_section(DOCS / page, section, render_section(full))
            for figure in figures_of(path.name):  # the figures this record holds the numbers of
                draw(figure)
    return full


def records_folder() -> Path:
    """Where :func:`publish` keeps records: docs/results/bench/, or ``$RHEOGRAPH_BENCH_OUT`` where set."""
    out = os.environ.get(OUT_ENV)
    return Path(out) if out else RECORDS


def record_path(name: str, records: Path = RECORDS) -> Path:
    """Where the numbers published as ``name`` (a section, or a run a benchmark scored) are kept."""
    return Path(records) / f"{name}.json"


def write_result_record(name: str, record: dict, records: Path = RECORDS) -> None:
    """Keep the numbers published as ``name`` (with the command that made them in ``record``)."""
    write_record(record_path(name, records), record)


def read_result_record(name: str, records: Path = RECORDS) -> dict:
    """The numbers published as ``name`` (one line naming the file where it is absent or damaged)."""
    return read_record(record_path(name, records), f"result record of {name}")
