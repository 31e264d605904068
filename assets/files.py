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


def _refused(folder: Path, exc: OSError) -> str:
    """Why ``folder`` (which exists) took no new file: "no permission", "read-only", or the system's word. Made in
    /proc, a file is refused with ENOENT, which read "No such file or directory" of a folder that is there."""
    import errno

    why = {
        errno.ENOENT: "its file system takes no new files",
        errno.EACCES: "no permission",
        errno.EPERM: "no permission",
        errno.EROFS: "a read-only file system",
    }.get(exc.errno or 0, exc.strerror or str(exc))
    return f"folder {folder} is not writable ({why}); give a path in another folder"


def _make_folder(folder: Path, named: Path) -> None:
    """Create ``folder`` (and its parents); CannotWriteError naming ``named`` (the output it is for) with the
    problem when the file system refuses: a file in a folder's place, a missing folder that cannot be made where."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        blocker = next((q for q in (folder, *folder.parents) if q.exists() and not q.is_dir()), None)
        if blocker is not None:
            raise CannotWriteError(named, f"cannot write here: {blocker} is a file, not a folder") from None
        there = next(q for q in folder.parents if q.is_dir())  # "/" at the latest
        missing = next(q for q in (folder, *folder.parents) if q.parent == there)
        raise CannotWriteError(
            named, f"cannot write here: folder {missing} is missing and cannot be made: {_refused(there, exc)}"
        ) from None


def _probe(folder: Path, named: Path) -> None:
    """A file made in ``folder`` and removed (permissions, read-only and special file systems such as /proc refuse
    only when a file is made); CannotWriteError naming ``named`` otherwise."""
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{named.name}.", suffix=".probe", dir=folder)
    except OSError as exc:
        raise CannotWriteError(named, f"cannot write here: {_refused(folder, exc)}") from None
    os.close(fd)
    os.unlink(probe)


def make_parent(path: str | os.PathLike) -> Path:
    """Create ``path``'s folder (and its parents); CannotWriteError naming ``path`` when the file system
    refuses (a parent is a file, no permission), so the command line prints one line, not a traceback."""
    path = Path(path)
    _make_folder(path.parent, path)
    return path


def check_writable(path: str | os.PathLike) -> Path:
    """Before any work: ``path``'s folder made (:func:`make_parent`), ``path`` not a folder, and a file can be created
    beside it (a probe file made and removed). CannotWriteError naming ``path`` and its folder's problem otherwise
    (`say -o /proc/x.mp4` read "No such file or directory" of a folder that is there), so a command refuses at once
    instead of failing after its work with a traceback, and leaves none of its other outputs behind."""
    path = make_parent(path)
    if path.is_dir():
        raise CannotWriteError(path, "is a folder: give a file name")
    _probe(path.parent, path)
    return path


def check_writable_folder(folder: str | os.PathLike) -> Path:
    """:func:`check_writable` for an output folder (``corpus DIR``, ``mu -o DIR``, ``perceptual build -o DIR``,
    ``extract -o DIR``): made with its parents and a file can be created in it; CannotWriteError naming it otherwise.
    ``mu -o /proc/d`` failed with a FileNotFoundError traceback."""
    folder = Path(folder)
    _make_folder(folder, folder)
    _probe(folder, folder / ".facecast")
    return folder


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path``: a temporary file in the same folder, then ``os.replace``.

    The file gets mode 0644 (mkstemp's 0600 would hide shared caches and models from others).
    Raises CannotWriteError naming ``path`` when the file system refuses.
    """
    path = make_parent(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise CannotWriteError(path, f"cannot write here: {_refused(path.parent, exc)}") from None
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
