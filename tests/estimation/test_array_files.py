"""The files of fitted models: written whole or not at all, and read back as written."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from estimation.array_files import load_arrays, locked, save_arrays, write_atomic
from tests.paths import ROOT


def test_a_written_file_replaces_the_old_one_whole_and_leaves_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "new" / "folder" / "file.bin"
    assert write_atomic(path, b"first") == path
    write_atomic(path, b"second, longer")
    assert path.read_bytes() == b"second, longer"
    assert [p.name for p in path.parent.iterdir()] == ["file.bin"]
    umask = os.umask(0o022)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # as open() would have made it


def test_a_write_that_fails_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    path = write_atomic(tmp_path / "file.bin", b"kept")
    with pytest.raises(TypeError):
        write_atomic(path, "not bytes")  # type: ignore[arg-type]
    assert path.read_bytes() == b"kept"
    assert [p.name for p in tmp_path.iterdir()] == ["file.bin"]


def test_a_write_whose_temporary_cannot_be_made_raises_the_systems_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def refuse(*args: object) -> int:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "open", refuse)
    with pytest.raises(OSError, match="No space left on device") as raised:
        write_atomic(tmp_path / "file.bin", b"data")
    assert raised.type is OSError  # not the FileNotFoundError of removing a file never made
    assert list(tmp_path.iterdir()) == []


def test_a_second_process_waits_for_the_lock_and_then_holds_it(tmp_path: Path) -> None:
    path = tmp_path / "made.npz"
    script = (
        "import sys, time\n"
        "from estimation.array_files import locked\n"
        "print('asking', flush=True)\n"
        "with locked(sys.argv[1]):\n"
        "    print(time.monotonic(), flush=True)\n"
    )
    with locked(path):
        other = subprocess.Popen(
            [sys.executable, "-c", script, str(path)],
            stdout=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        assert other.stdout is not None and other.stdout.readline().strip() == "asking"
        time.sleep(0.5)
        released = time.monotonic()
    entered = float(other.communicate(timeout=60)[0])
    assert entered >= released
    assert (tmp_path / "made.lock").is_file()


def test_saved_arrays_and_metadata_load_back_and_a_damaged_file_is_named(tmp_path: Path) -> None:
    path = save_arrays(tmp_path / "m.npz", {"a": np.arange(3.0)}, {"fit": [1, 2.5]})
    a, metadata = load_arrays(path, "test", lambda data, meta: (np.array(data["a"]), meta))
    assert np.array_equal(a, [0.0, 1.0, 2.0]) and metadata == {"fit": [1, 2.5]}
    path.write_bytes(b"damaged")
    with pytest.raises(ValueError, match=r"m\.npz is not a test file"):
        load_arrays(path, "test", lambda data, meta: data["a"])
