"""The file-system edge shared by every package: atomic writes.

Everything facecast writes (corpora, models, rigs, caches, exports) goes through
:func:`atomic_write_bytes`, so a reader sees the old file or the new one, never half of one,
and an interrupted run leaves no partial file under the final name.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from assets.errors import CannotWriteError


def not_a_file(path: str | os.PathLike) -> str:
    """Why ``path`` (not a file) cannot be read, for a message that names it: "is a folder, not a file" or
    "not found" (a folder given where a file belongs used to read "not found", though it was there)."""
    return "is a folder, not a file" if Path(path).is_dir() else "not found"


def make_parent(path: str | os.PathLike) -> Path:
    """Create ``path``'s folder (and its parents); CannotWriteError naming ``path`` when the file system
    refuses (a parent is a file, no permission), so the command line prints one line, not a traceback."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        blocker = next((q for q in path.parents if q.exists() and not q.is_dir()), None)
        why = f"{blocker} is a file, not a folder" if blocker else f"{exc.strerror or exc} ({exc.filename})"
        raise CannotWriteError(path, f"cannot write here: {why}") from None
    return path


def check_writable(path: str | os.PathLike) -> Path:
    """Before any work: ``path``'s folder made (:func:`make_parent`), ``path`` not a folder, and a file can be created
    beside it (a probe file made and removed: permissions, read-only and special file systems such as /proc refuse
    only when a file is made). CannotWriteError naming ``path`` otherwise, so a command refuses at once instead of
    failing after its work with a traceback, and leaves none of its other outputs behind."""
    path = make_parent(path)
    if path.is_dir():
        raise CannotWriteError(path, "is a folder: give a file name")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=path.parent)
    except OSError as exc:
        raise CannotWriteError(path, f"cannot write here: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path``: a temporary file in the same folder, then ``os.replace``.

    The file gets mode 0644 (mkstemp's 0600 would hide shared caches and models from others).
    Raises CannotWriteError naming ``path`` when the file system refuses.
    """
    path = make_parent(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise CannotWriteError(path, f"cannot write here: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except OSError as exc:  # disk full, the name is a folder ...: nothing is left behind
        Path(tmp).unlink(missing_ok=True)
        raise CannotWriteError(path, f"cannot write here: {exc.strerror or exc}") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
