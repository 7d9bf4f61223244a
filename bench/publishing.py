"""How a benchmark publishes: its table into a marked section of a docs page, its numbers into a JSON
record under docs/results/bench/ (what figures and other benchmarks read), and the command that
reproduces both."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from rheograph.io.pages import read_record, replace_section, write_record

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "docs" / "results" / "bench"


def command_line(script: str, argv=None) -> str:
    """``python -m bench.<script> ARGS`` as the user typed it (``argv``, or the process's), less
    ``--no-write``: the command that reproduces a published section (``script`` with or without
    its ``.py``)."""
    args = argv if argv is not None else sys.argv[1:]
    module = script.removesuffix(".py")
    return f"python -m bench.{module} {shlex.join([a for a in args if a != '--no-write'])}".rstrip()


def publish(
    section: str, text: str, write: bool, page: str = "benchmarks.md", record: dict | None = None
) -> None:
    """Print a result section and (unless the script's --no-write) replace it in docs/<page>, and
    write ``record`` (its numbers) to docs/results/bench/<section>.json."""
    print(text)
    if write:
        replace_section(ROOT / "docs" / page, section, text)
        if record is not None:
            write_record(record_path(section), record)


def record_path(name: str, records: Path = RECORDS) -> Path:
    """Where the numbers published as ``name`` (a section, or a run a benchmark scored) are kept."""
    return Path(records) / f"{name}.json"


def write_result_record(name: str, record: dict, records: Path = RECORDS) -> None:
    """Keep the numbers published as ``name`` (with the command that made them in ``record``)."""
    write_record(record_path(name, records), record)


def read_result_record(name: str, records: Path = RECORDS) -> dict:
    """The numbers published as ``name`` (one line naming the file where it is absent or damaged)."""
    return read_record(record_path(name, records), f"result record of {name}")
