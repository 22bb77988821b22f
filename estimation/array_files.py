"""The files of fitted estimation models: named NumPy arrays and JSON metadata in one ``.npz``.

One home for how fitted models such as
:class:`~estimation.anticipation.linear_predictors.LinearTiltPredictor` are written and read:
compressed, no pickles (``allow_pickle=False``: a model file cannot run code), the metadata as a
JSON string, and a malformed file reported as a ``ValueError`` that names it and what it should have
been.  Files are written whole or not at all (:func:`write_atomic`): a reader in another process
never sees one half-written.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")


def write_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that a concurrent reader never sees it half-written (a
    temporary file beside it, then renamed); its folder is made when missing.  Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=path.parent, delete=False, suffix=".tmp") as handle:
        handle.write(data)
        temp = Path(handle.name)
    os.replace(temp, path)
    return path


def save_arrays(path: str | Path, arrays: Mapping[str, Any], metadata: Mapping[str, Any]) -> Path:
    """Write ``arrays`` and ``metadata`` (as JSON, under ``metadata``) to ``path``
    (:func:`write_atomic`); its folder is made when missing.  Returns the path."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays, metadata=json.dumps(dict(metadata)))
    return write_atomic(path, buffer.getvalue())


def load_arrays(
    path: str | Path, kind: str, build: Callable[[Mapping[str, np.ndarray], dict[str, Any]], T]
) -> T:
    """Read ``path`` and ``build`` the model from its arrays and metadata; a missing, unreadable
    or malformed file (a missing key, a bad value) is a ``ValueError`` naming it as not a
    ``kind`` file."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            return build(data, json.loads(str(data["metadata"])))
    except (OSError, KeyError, ValueError) as error:
        raise ValueError(f"{path} is not a {kind} file: {error}") from error
