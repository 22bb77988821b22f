"""The envelope of the calibration files: a JSON document naming its ``format`` and the
``format_version`` it was written in (``version`` in the first files)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def read_document(
    path: str | Path, format_name: str, readable: tuple[int, ...], what: str
) -> dict[str, Any]:
    """The JSON document at ``path``, refused (ValueError naming the file) unless it is a
    ``format_name`` file of a version in ``readable``; ``what`` names the kind of file."""
    doc = json.loads(Path(path).read_text())
    if doc.get("format") != format_name:
        raise ValueError(f"{path}: not a {what}")
    version = doc.get("format_version", doc.get("version"))
    if version not in readable:
        raise ValueError(f"{path}: unsupported format_version {version!r}; readable: {readable}")
    return doc
