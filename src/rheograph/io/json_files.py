"""JSON files rheograph reads beside its data (indexes, model cards, error models): read whole, or
refused in one line that names the file and what it should have been."""

from __future__ import annotations

import json
from pathlib import Path

from rheograph.errors import InputError


def read_json(path: str | Path, what: str, advice: str = "") -> object:
    """The JSON value in ``path``; a file that cannot be read or is not JSON (a cut copy, a bit flip, an
    encoding other than UTF-8) raises ``InputError`` naming it as ``what`` (e.g. "a model card"), with
    ``advice`` appended."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a readable {what} ({exc}){advice}") from exc
