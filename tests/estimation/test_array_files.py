"""The files of fitted models: written whole or not at all, and read back as written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimation.array_files import load_arrays, save_arrays, write_atomic


def test_a_written_file_replaces_the_old_one_whole_and_leaves_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "new" / "folder" / "file.bin"
    assert write_atomic(path, b"first") == path
    write_atomic(path, b"second, longer")
    assert path.read_bytes() == b"second, longer"
    assert [p.name for p in path.parent.iterdir()] == ["file.bin"]


def test_saved_arrays_and_metadata_load_back_and_a_damaged_file_is_named(tmp_path: Path) -> None:
    path = save_arrays(tmp_path / "m.npz", {"a": np.arange(3.0)}, {"fit": [1, 2.5]})
    a, metadata = load_arrays(path, "test", lambda data, meta: (np.array(data["a"]), meta))
    assert np.array_equal(a, [0.0, 1.0, 2.0]) and metadata == {"fit": [1, 2.5]}
    path.write_bytes(b"damaged")
    with pytest.raises(ValueError, match=r"m\.npz is not a test file"):
        load_arrays(path, "test", lambda data, meta: data["a"])
