"""Tables of one row per snapshot (predictions): CSV with ``#`` comment lines, or HDF5 with one dataset
per column and the header as attributes."""

from __future__ import annotations

import csv
from pathlib import Path

import h5py
import numpy as np


def write_table(table: dict, out: Path, header: dict) -> None:
    """CSV (``#``-comment lines with ``header`` first) or HDF5 (``header`` as attributes), through a
    temporary file: ``out`` appears whole or not at all."""
    tmp = out.with_name(out.name + ".tmp")
    try:
        _write_table(table, tmp, out.suffix, header)
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)


def _write_table(table: dict, out: Path, suffix: str, header: dict) -> None:
    if suffix == ".h5":
        with h5py.File(out, "w") as h5:
            for key, value in table.items():
                if value.dtype.kind == "U":  # variable-length UTF-8 (paths and notes may be non-ASCII)
                    h5.create_dataset(key, data=value.astype(object), dtype=h5py.string_dtype())
                else:
                    h5[key] = value
            for key, value in header.items():
                h5.attrs[key] = value
        return
    with open(out, "w", newline="") as fh:
        for key, value in header.items():
            fh.write(f"# {key}: {value}\n")
        writer = csv.writer(fh)
        columns = list(table)
        writer.writerow(columns)
        for row in zip(*(table[c] for c in columns)):
            writer.writerow([f"{v:.9g}" if isinstance(v, float | np.floating) else v for v in row])
