"""The files of fitted estimation models: named NumPy arrays and JSON metadata in one ``.npz``.

One home for how fitted models such as
:class:`~estimation.anticipation.linear_predictors.LinearTiltPredictor` are written and read:
compressed, no pickles (``allow_pickle=False``: a model file cannot run code), the metadata as a
JSON string, and a malformed file reported as a ``ValueError`` that names it and what it should have
been.  Files are written whole or not at all (:func:`write_atomic`): a reader in another process
never sees one half-written; processes that would make the same file take turns (:func:`locked`).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import uuid
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")


def write_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that a concurrent reader never sees it half-written (a
    temporary file beside it, then renamed); its folder is made when missing.  Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex}.tmp")
    try:
        # made as open() makes a file (the umask's permissions)
        with os.fdopen(os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), "wb") as out:
            out.write(data)
        os.replace(temp, path)
    except BaseException:
        temp.unlink(missing_ok=True)
        raise
    return path


@contextlib.contextmanager
def locked(path: str | Path) -> Iterator[None]:
    """Hold an exclusive lock on ``path``'s lock file (``path`` with the suffix ``.lock``, made
    with its folder when missing) while the block runs: a process that would make the same file
    waits for the one making it, then finds it made.  Where the OS has no ``fcntl``
    (Windows) it locks nothing, and processes that make a file at once each write it whole."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_suffix(".lock"), "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


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
