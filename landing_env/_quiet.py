"""PyBullet's glue: silence what its C code prints on import and connect (its build time on
stderr, ``argv[0]=`` on stdout), and a physics client's id.

PyBullet writes with C ``printf``/``fprintf``, past ``sys.stdout``; only pointing file
descriptors 1 and 2 at the null device around the import and the connection hides it.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # importing it here would import PyBullet before it is quietened
    from pybullet_utils.bullet_client import BulletClient


def _flush_all() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    try:  # C's stdio buffer (stdout is fully buffered on a pipe)
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):
        pass


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Point file descriptors 1 and 2 at the null device for the duration (a no-op where
    they cannot be duplicated, e.g. under some notebook kernels).  The descriptors belong to
    the process: what another thread writes meanwhile (a few milliseconds) is lost too."""
    try:
        saved = [(fd, os.dup(fd)) for fd in (1, 2)]
    except OSError:
        yield
        return
    _flush_all()
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd, _ in saved:
            os.dup2(null, fd)
        yield
    finally:
        _flush_all()
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)
        os.close(null)


def client_id(client: int | BulletClient) -> int:
    """The physics-client id of an id or a ``pybullet_utils`` BulletClient (which keeps it in
    ``_client``; it has no public accessor)."""
    return int(getattr(client, "_client", client))
